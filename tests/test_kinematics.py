"""The whole geometric model (modified DH + Hayati beta, base and flange frames): robot.json's
standard DH turned into it gives the same flange everywhere; the vectorized chain equals the
product of 4x4 joint transforms, with every parameter moved."""
import numpy as np
import pytest

from planecal.model.kinematics import (Kinematics, fk, fk_jacobian, frame_error, frames,
                                       jacobian, link_frames, parallel_pairs)
from planecal.model.robot import load_robot

ROBOT = load_robot()


def dh_frames(robot, q, delta):
    """robot.json's standard DH frames 0..6, an independent 4x4 product:
    T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), theta_i = q_i + delta_i + theta0_i."""
    T = np.eye(4)
    out = [T]
    for i in range(6):
        th = q[i] + delta[i] + robot.theta0[i]
        ct, st = np.cos(th), np.sin(th)
        ca, sa = np.cos(robot.alpha[i]), np.sin(robot.alpha[i])
        T = T @ np.array([[ct, -st * ca, st * sa, robot.a[i] * ct],
                          [st, ct * ca, -ct * sa, robot.a[i] * st],
                          [0.0, sa, ca, robot.d[i]], [0.0, 0.0, 0.0, 1.0]])
        out.append(T)
    return np.array(out)


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
    kin = ROBOT.kinematics.with_offsets(delta)
    S = np.array([dh_frames(ROBOT, qi, delta) for qi in q])
    assert np.abs(fk(kin, q) - S[:, -1]).max() < 1e-14
    # each link's frame is its standard DH frame
    assert np.abs(link_frames(kin, q) - S).max() < 1e-14
    # standard DH frame i = frame i x Tx(a_i^std) Rx(alpha_i^std); the axes of joint i
    F = frames(kin, q)
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
    nom = ROBOT.kinematics
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


def test_frame_error_is_translation_then_rz_ry_rx_at_large_angles():
    """The closed form against the product of elementary rotations, with angles far from
    small (a sign or order slip in one entry shows only there)."""
    from planecal.model.kinematics import rot
    e = np.array([0.1, -0.2, 0.3, 0.7, -1.1, 2.3])
    T = np.eye(4)
    T[:3, :3] = rot(2, e[5]) @ rot(1, e[4]) @ rot(0, e[3])
    T[:3, 3] = e[:3]
    assert np.abs(frame_error(e) - T).max() < 1e-15


def test_joints_take_their_sines_once_and_give_the_same_distances_and_jacobian():
    """The fit hands the kernel precomputed cos/sin of its joints (``Joints``); a subset of
    rows and the plain angles give the same numbers, bit for bit."""
    from planecal.model.layout import level2_layout
    from planecal.model.measurement import Joints, predict_joints_with_jacobian
    from planecal.model.scene import load_scene, nominal_params
    scene = load_scene("three_plates")
    p = nominal_params(scene)
    rng = np.random.default_rng(5)
    q = rng.uniform(-1, 1, (40, 6))
    plate = rng.integers(0, 3, 40)
    layout = level2_layout(3, compliance=True)
    j = Joints.of(q)
    # numba's libm and numpy's (possibly SIMD) cos may differ in the last bit
    assert np.abs(j.cos - np.cos(q)).max() < 4e-16 and np.abs(j.sin - np.sin(q)).max() < 4e-16
    d0, J0 = predict_joints_with_jacobian(ROBOT, q, p, plate, layout)
    d1, J1 = predict_joints_with_jacobian(ROBOT, j, p, plate, layout)
    assert np.array_equal(d0, d1) and np.array_equal(J0, J1)
    rows = np.arange(40) % 3 == 0
    d2, J2 = predict_joints_with_jacobian(ROBOT, j.rows(rows), p, plate[rows], layout)
    assert np.array_equal(d2, d0[rows]) and np.array_equal(J2, J0[rows])
    assert j.rows(np.ones(40, bool)) is j


def test_geometric_jacobian_against_central_differences_with_every_parameter_moved():
    # v: the flange origin's velocity; w: the angular velocity from dR R^T
    rng = np.random.default_rng(4)
    nom = ROBOT.kinematics
    kin = Kinematics(nom.alpha + rng.normal(0, 1e-3, 6), nom.a + rng.normal(0, 1e-3, 6),
                     rng.normal(0, 1e-3, 6), nom.theta, nom.d + rng.normal(0, 1e-3, 6),
                     frame_error(rng.normal(0, 1e-2, 6)), nom.flange)
    h = 1e-6
    for q in rng.uniform(-2.5, 2.5, (10, 6)):
        T, J = fk_jacobian(kin, q)
        assert np.array_equal(T, fk(kin, q)) and np.array_equal(J, jacobian(kin, q))
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = h
            Tp, Tm = fk(kin, q + dq), fk(kin, q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ T[:3, :3].T
            w = np.array([W[2, 1], W[0, 2], W[1, 0]])
            assert np.abs(J[:3, j] - v).max() < 1e-8
            assert np.abs(J[3:, j] - w).max() < 1e-8
    # batch shape and the same numbers as one pose at a time
    Q = rng.uniform(-2, 2, (3, 4, 6))
    Tb, Jb = fk_jacobian(kin, Q)
    assert Tb.shape == (3, 4, 4, 4) and Jb.shape == (3, 4, 6, 6)
    assert np.array_equal(Jb[1, 2], jacobian(kin, Q[1, 2]))
