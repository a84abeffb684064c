"""The prediction of a linear model over a horizon, written once for both of the MPC's QPs.

A discrete model ``z+ = A z + B u`` run for ``h`` steps from ``z_0`` under the inputs
``u_0 .. u_{h-1}`` is, stacked::

    Z = Phi z_0 + Gamma U        Z = (z_1, ..., z_h), U = (u_0, ..., u_{h-1})

(:func:`prediction`). With a square, invertible ``B`` the inputs follow from the trajectory
(:func:`increments`): ``U = Gamma^-1 (Z - Phi z_0)``, ``u_k = B^-1 (z_{k+1} - A z_k)``.

The two QPs use it from either side:

- the effort QP (:mod:`peg_ctrl.controllers.mpc`) plans ``U`` and writes its cost on ``Z`` in
  ``U`` (a *condensed* QP, :func:`condense`);
- the contact QP (:mod:`peg_ctrl.controllers.contact_mpc`) plans the trajectory itself: ``Y``,
  the change of the contact wrench, of an integrator ``y+ = y + dy`` (``A = B = 1``) from
  ``y_0 = 0``; its smoothing and rate bound act on the increments ``dY = Gamma^-1 Y``, and its
  budget on how far ``Y`` can go (``Gamma`` applied to the largest increment per step).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

__all__ = ["INTEGRATOR", "condense", "increments", "prediction"]

_Mat = NDArray[np.float64]

#: (A, B) of the scalar integrator ``y+ = y + dy``.
INTEGRATOR: tuple[_Mat, _Mat] = (np.ones((1, 1)), np.ones((1, 1)))


def prediction(a: _Mat, b: _Mat, h: int) -> tuple[_Mat, _Mat]:
    """``(Phi (h nx, nx), Gamma (h nx, h nu))`` of ``Z = Phi z_0 + Gamma U`` for ``z+ = A z + B u``
    (``a`` (nx, nx), ``b`` (nx, nu)) over ``h`` steps."""
    nx, nu = b.shape
    phi = np.zeros((h * nx, nx))
    gamma = np.zeros((h * nx, h * nu))
    power = np.eye(nx)
    for k in range(h):
        power = a @ power
        phi[k * nx : (k + 1) * nx] = power
        for j in range(k + 1):
            gamma[k * nx : (k + 1) * nx, j * nu : (j + 1) * nu] = np.linalg.matrix_power(a, k - j) @ b
    return phi, gamma


def increments(a: _Mat, b: _Mat, h: int) -> _Mat:
    """``Gamma``'s inverse (h nu, h nx) for a square, invertible ``b``: the inputs ``U`` that
    drive ``z+ = A z + B u`` along the trajectory ``Z`` from ``z_0 = 0`` (block bidiagonal:
    ``B^-1`` on the diagonal, ``-B^-1 A`` below it). For :data:`INTEGRATOR`, ``dy_k = y_{k+1} - y_k``
    exactly."""
    nx, nu = b.shape
    if nx != nu:
        raise ValueError(f"increments needs a square B, got {b.shape}")
    b_inv = np.linalg.inv(b)
    below = -b_inv @ a
    out = np.zeros((h * nu, h * nx))
    for k in range(h):
        out[k * nu : (k + 1) * nu, k * nx : (k + 1) * nx] = b_inv
        if k > 0:
            out[k * nu : (k + 1) * nu, (k - 1) * nx : k * nx] = below
    return out


def condense(a: _Mat, b: _Mat, q: _Mat, p_terminal: _Mat, r: _Mat, h: int) -> tuple[_Mat, _Mat, _Mat, _Mat]:
    """The condensed prediction Z = Phi z0 + Gamma U (Z: stacked z_1..z_N, U: du_0..du_{N-1})
    over ``h`` steps (:func:`prediction`), and the QP's Hessian and linear map (g = lin @ z0) of
    the cost ``sum_{k<N} z_k' Q z_k + z_N' P z_N + sum_k u_k' R u_k``: (Phi, Gamma, Hessian, lin)."""
    phi, gamma = prediction(a, b, h)
    q_bar = scipy.linalg.block_diag(*([q] * (h - 1) + [p_terminal]))
    r_bar = scipy.linalg.block_diag(*([r] * h))
    hess = 2.0 * (gamma.T @ q_bar @ gamma + r_bar)
    hess = 0.5 * (hess + hess.T)
    return phi, gamma, hess, 2.0 * gamma.T @ q_bar @ phi
