"""The whole geometric model (modified DH + Hayati beta, base and flange frames): robot.json's
standard DH turned into it gives the same flange everywhere; the vectorized chain equals the
product of 4x4 joint transforms, with every parameter moved."""
import numpy as np
import pytest

from planecal.model.kinematics import (Kinematics, fk, frame_error, frames, from_robot,
                                 parallel_pairs)
from planecal.model.robot import fk as dh_fk
from planecal.model.robot import fk_frames, load_robot

ROBOT = load_robot()


def product(kin, q):
    T = kin.base.copy()
    out = [T.copy()]
    for i in range(kin.n_joints):
        T = T @ kin.joint_transform(i, q[i])
        out.append(T.copy())
    return out, T @ kin.flange


def test_nominal_model_is_robot_json_standard_dh():
    rng = np.random.default_rng(0)
    q = rng.uniform(-2.5, 2.5, (200, 6))
    delta = rng.normal(0, 2e-3, 6)
    kin = from_robot(ROBOT, delta)
    assert np.abs(fk(kin, q) - dh_fk(ROBOT, q, delta)).max() < 1e-14
    # standard DH frame i = frame i x Tx(a_i^std) Rx(alpha_i^std); the axes of joint i
    F, S = frames(kin, q), fk_frames(ROBOT, q, delta)
    for i in range(1, 7):
        X = np.eye(4)
        c, s = np.cos(ROBOT.alpha[i - 1]), np.sin(ROBOT.alpha[i - 1])
        X[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
        X[0, 3] = ROBOT.a[i - 1]
        assert np.abs(F[:, i] @ X - S[:, i]).max() < 1e-14
        # joint i's axis (z of frame i) is z of standard frame i-1
        assert np.abs(F[:, i, :3, 2] - S[:, i - 1, :3, 2]).max() < 1e-14
    # the MC70's J2-J3 axes are parallel: Hayati's beta of joint 3
    assert parallel_pairs(kin) == [2]


def test_chain_equals_the_product_of_joint_transforms_with_every_parameter_moved():
    rng = np.random.default_rng(1)
    nom = from_robot(ROBOT)
    kin = Kinematics(nom.alpha + rng.normal(0, 1e-3, 6), nom.a + rng.normal(0, 1e-3, 6),
                     rng.normal(0, 1e-3, 6), nom.theta + rng.normal(0, 1e-3, 6),
                     nom.d + rng.normal(0, 1e-3, 6),
                     frame_error(rng.normal(0, [1e-3] * 3 + [1e-3] * 3)),
                     nom.flange @ frame_error(rng.normal(0, 1e-3, 6)))
    for q in rng.uniform(-3, 3, (20, 6)):
        want_frames, want = product(kin, q)
        assert np.abs(fk(kin, q) - want).max() < 1e-14
        got = frames(kin, q)
        for i in range(7):
            assert np.abs(got[i] - want_frames[i]).max() < 1e-14
    # vectorized over leading axes
    Q = rng.uniform(-3, 3, (4, 5, 6))
    assert fk(kin, Q).shape == (4, 5, 4, 4)
    assert np.abs(fk(kin, Q)[2, 3] - fk(kin, Q[2, 3])).max() == 0


@pytest.mark.parametrize("axis", range(6))
def test_frame_error_small_rotation_and_translation(axis):
    e = np.zeros(6)
    e[axis] = 1e-6
    T = frame_error(e)
    if axis < 3:
        assert T[axis, 3] == 1e-6 and np.allclose(T[:3, :3], np.eye(3))
    else:
        W = T[:3, :3] - np.eye(3)  # skew of the small rotation
        k = axis - 3
        assert abs(W[(k + 2) % 3, (k + 1) % 3] - 1e-6) < 1e-15
