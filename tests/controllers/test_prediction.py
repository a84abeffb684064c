"""The prediction both MPC QPs are written on: against a step-by-step simulation of the model."""

from __future__ import annotations

import numpy as np
import pytest

from peg_ctrl.controllers.contact_mpc import ContactQP
from peg_ctrl.controllers.mpc import condense as mpc_condense
from peg_ctrl.controllers.prediction import INTEGRATOR, condense, increments, prediction

from .test_contact_mpc import FORCE_Z, _settings, _wrench


def _model(nx: int, nu: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return 0.4 * rng.normal(size=(nx, nx)), rng.normal(size=(nx, nu))


def _simulate(a: np.ndarray, b: np.ndarray, z0: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(h, nx): z_1 .. z_h of ``z+ = A z + B u`` from ``z0`` under ``u`` (h, nu)."""
    z, out = z0, []
    for u_k in u:
        z = a @ z + b @ u_k
        out.append(z)
    return np.array(out)


@pytest.mark.parametrize(("nx", "nu", "h"), [(2, 1, 6), (4, 2, 5), (12, 6, 3)])
def test_the_prediction_is_the_model_run_forward(nx: int, nu: int, h: int) -> None:
    a, b = _model(nx, nu)
    phi, gamma = prediction(a, b, h)
    assert phi.shape == (h * nx, nx) and gamma.shape == (h * nx, h * nu)
    rng = np.random.default_rng(1)
    z0, u = rng.normal(size=nx), rng.normal(size=(h, nu))
    np.testing.assert_allclose(phi @ z0 + gamma @ u.ravel(), _simulate(a, b, z0, u).ravel(), atol=1e-12)


def test_increments_invert_the_prediction() -> None:
    a, b = _model(3, 3, seed=2)
    _, gamma = prediction(a, b, 4)
    np.testing.assert_allclose(increments(a, b, 4) @ gamma, np.eye(12), atol=1e-12)
    with pytest.raises(ValueError, match=r"square B, got \(3, 2\)"):
        increments(*_model(3, 2), 4)


def test_the_integrators_increments_are_exact_differences() -> None:
    """The contact QP's rows: y_{k+1} - y_k with no rounding, and k steps reach k times a step."""
    n = 10
    np.testing.assert_array_equal(increments(*INTEGRATOR, n), np.eye(n) - np.eye(n, k=-1))
    _, gamma = prediction(*INTEGRATOR, n)
    np.testing.assert_array_equal(gamma @ np.ones(n), np.arange(1.0, n + 1.0))


def test_the_condensed_cost_is_the_cost_along_the_prediction() -> None:
    """1/2 U'HU + (lin z0)'U + const equals sum z'Qz + z_N'P z_N + u'Ru along the simulation."""
    nx, nu, h = 4, 2, 5
    a, b = _model(nx, nu, seed=3)
    q, p, r = np.diag([1.0, 2.0, 3.0, 4.0]), 5.0 * np.eye(nx), np.diag([0.1, 0.2])
    phi, gamma, hess, lin = condense(a, b, q, p, r, h)
    rng = np.random.default_rng(4)
    z0 = rng.normal(size=nx)

    def cost(u: np.ndarray) -> float:
        z = _simulate(a, b, z0, u.reshape(h, nu))
        return float(
            sum(z_k @ q @ z_k for z_k in z[:-1])
            + z[-1] @ p @ z[-1]
            + sum(u_k @ r @ u_k for u_k in u.reshape(h, nu))
        )

    const = cost(np.zeros(h * nu))
    for _ in range(3):
        u = rng.normal(size=h * nu)
        assert 0.5 * u @ hess @ u + (lin @ z0) @ u + const == pytest.approx(cost(u), rel=1e-10)
    np.testing.assert_array_equal(hess, hess.T)
    assert mpc_condense is condense  # the effort MPC's condensing is this one


def test_the_contact_qp_plans_along_the_integrators_prediction() -> None:
    """Its plan's increments are bounded by the rate cap: the rows it constrains are the
    prediction's increments."""
    s = _settings(rate_cap=(1.0,) * 3 + (0.05,) * 3, damping=(1.0,) * 3 + (0.5,) * 3)
    plan = ContactQP(s).solve(FORCE_Z, _wrench(fz=2.0), _wrench(fz=15.0))
    y = _wrench(fz=2.0)[2] - plan.predicted[0]  # y_k = w_0 - w_k
    dy = increments(*INTEGRATOR, s.horizon) @ y
    step = s.stiffness[2] * 1.0 * s.dt  # K v_cap h: the error is far beyond D v_cap
    assert np.all(np.abs(dy) <= step + 1e-9)
    assert np.abs(dy).max() == pytest.approx(step, rel=1e-6)  # it moves as fast as allowed
