import json

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.model.kinematics import fk, link_frames, jacobian
from planecal.model.ik import ik_all, ik_nearest
from planecal.model.robot import load_robot, within_limits

HOME = np.array([[0, 0, 1, 1.315], [0, -1, 0, 0], [1, 0, 0, 1.65], [0, 0, 0, 1]])


def test_home_pose_is_model_notes_matrix(robot):
    np.testing.assert_allclose(fk(robot.kinematics, np.zeros(6)), HOME, atol=1e-15)


def test_description_values(robot):
    assert robot.gains[2] == -53651.3 and robot.qe0[0] == 8388608
    assert robot.coupling[4, 3] == -0.01111111 and robot.coupling[5, 3] == 0.017137476
    assert robot.coupling[5, 4] == -0.016949152
    np.testing.assert_allclose(np.rad2deg(robot.limits[2]), [-146, 260])
    assert robot.max_step_counts == 51 and robot.trip_step_counts == 60


def test_fk_vectorized_matches_loop(robot):
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], (50, 6))
    T = fk(robot.kinematics, q)
    for i in (0, 17, 49):
        np.testing.assert_allclose(T[i], fk(robot.kinematics, q[i]), atol=1e-15)
    np.testing.assert_allclose(link_frames(robot.kinematics, q)[:, -1], T, atol=1e-14)


def test_jacobian_against_finite_differences(robot):
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = rng.uniform(-2, 2, 6)
        J = jacobian(robot.kinematics, q)
        h = 1e-6
        for j in range(6):
            dq = np.zeros(6)
            dq[j] = h
            Tp, Tm = fk(robot.kinematics, q + dq), fk(robot.kinematics, q - dq)
            v = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ fk(robot.kinematics, q)[:3, :3].T
            w = np.array([dR[2, 1], dR[0, 2], dR[1, 0]])
            np.testing.assert_allclose(J[:3, j], v, atol=1e-8)
            np.testing.assert_allclose(J[3:, j], w, atol=1e-8)


def test_ik_round_trip_random_reachable_poses(robot):
    rng = np.random.default_rng(2)
    worst_pose, worst_q, n_sol = 0.0, 0.0, []
    for _ in range(300):
        q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1])
        T = fk(robot.kinematics, q)
        Q = ik_all(robot, T)
        n_sol.append(len(Q))
        worst_pose = max(worst_pose, np.abs(fk(robot.kinematics, Q) - T).max())
        worst_q = max(worst_q, np.min(np.max(np.abs(Q - q), axis=1)))
        assert within_limits(robot, Q).all()
    assert worst_pose < 1e-9  # FK(IK(T)) = T
    assert worst_q < 1e-7  # the generating configuration is among the solutions
    assert min(n_sol) >= 1 and max(n_sol) >= 8


def test_ik_nearest_with_offsets(robot):
    rng = np.random.default_rng(3)
    delta = rng.uniform(-3e-3, 3e-3, 6)
    q = np.deg2rad([30, -20, -50, -40, 100, -120])
    T = fk(robot.kinematics.with_offsets(delta), q)
    qn = ik_nearest(robot, T, q + 0.05, delta)
    np.testing.assert_allclose(qn, q, atol=1e-10)


def test_ik_unreachable_is_empty(robot):
    T = np.eye(4)
    T[:3, 3] = [5.0, 0, 0]
    assert len(ik_all(robot, T)) == 0
    assert ik_nearest(robot, T, np.zeros(6)) is None


def test_ur5_is_described_by_data_only():
    ur5 = load_robot("ur5")
    assert np.allclose(ur5.coupling, np.eye(6))
    T = fk(ur5.kinematics, np.zeros(6))
    # UR5 at zero: flange at x = a2 + a3 = -0.81725, y = -(d4 + d6), z = d1 - d5
    np.testing.assert_allclose(T[:3, 3], [-0.81725, -0.19145, -0.005491], atol=1e-12)
    # issue 23: the UR's three parallel axes have a closed form (tests/test_ik.py)
    Q = ik_all(ur5, T)
    assert np.abs(Q).max(axis=1).min() < 1e-9  # q = 0 among them


def test_bad_robot_file(tmp_path):
    p = tmp_path / "robot.json"
    p.write_text('{"name": "x", "dh": []')
    with pytest.raises(InputError, match=r"robot.json:1: invalid JSON"):
        load_robot(p)
    raw = json.loads((load_robot().source).read_text())
    raw["encoder"]["gain_counts_per_rad"] = raw["encoder"]["gain_counts_per_rad"][:5]
    p.write_text(json.dumps(raw))
    with pytest.raises(InputError, match="robot.json: encoder.gain_counts_per_rad: must hold 6 gains, one per joint, got 5$"):
        load_robot(p)
