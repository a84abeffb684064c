"""The quaternion and vector helpers."""

from __future__ import annotations

import numpy as np

from peg_ctrl.sim.rotations import cross, quat_mul, rotate, rotate_inv


def test_cross_is_numpys_to_the_bit() -> None:
    rng = np.random.default_rng(0)
    for _ in range(200):
        a, b = rng.normal(size=3) * 10.0 ** rng.integers(-6, 3), rng.normal(size=3)
        assert np.array_equal(cross(a, b), np.cross(a, b))


def test_rotate_and_its_inverse_undo_each_other() -> None:
    rng = np.random.default_rng(1)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    v = rng.normal(size=3)
    np.testing.assert_allclose(rotate_inv(q, rotate(q, v)), v, atol=1e-12)
    q_inv = np.array([q[0], -q[1], -q[2], -q[3]])
    np.testing.assert_allclose(quat_mul(q, q_inv), [1.0, 0.0, 0.0, 0.0], atol=1e-12)
