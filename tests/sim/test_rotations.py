"""The quaternion and vector helpers."""

from __future__ import annotations

import numpy as np

from peg_ctrl.sim.rotations import cross, cross_floats, quat_mul, rotate, rotate_floats, rotate_inv


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


def test_the_float_rotation_is_mujocos_to_the_bit() -> None:
    """rotate_floats against mju_rotVecQuat (through rotate): random turns and vectors, and the
    special cases MuJoCo treats apart (a zero vector, the identity: signed zeros kept)."""
    rng = np.random.default_rng(2)
    cases = []
    for _ in range(2000):
        q = rng.normal(size=4)
        cases.append((q / np.linalg.norm(q), rng.normal(size=3) * 10.0 ** rng.integers(-6, 4)))
    for q in (np.array([1.0, 0.0, 0.0, 0.0]), np.array([1.0, -0.0, 0.0, -0.0]), cases[0][0]):
        for v in ([0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [1.5, -0.0, 2.0]):
            cases.append((q, np.array(v)))
    for q, v in cases:
        assert np.array(rotate_floats(q.tolist(), v.tolist())).tobytes() == rotate(q, v).tobytes()
        q_inv = [q[0], -q[1], -q[2], -q[3]]
        assert np.array(rotate_floats(q_inv, v.tolist())).tobytes() == rotate_inv(q, v).tobytes()
        assert np.array(cross_floats(q[1:].tolist(), v.tolist())).tobytes() == cross(q[1:], v).tobytes()
