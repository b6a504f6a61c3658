"""IK for any 6-axis arm (issue 23): every branch within the limits, each checked by the
forward kinematics; the MC70's closed form against EAIK's decomposition (two independent
solvers), the UR's three parallel axes, an imported KUKA, and the numeric solver where
no decomposition is known. And the chain from joint axes (``kinematics.from_axes``, how a
URDF becomes the model) against the product of exponentials."""
from pathlib import Path

import numpy as np
import pytest

from planecal.model.ik import _numeric, _wrap, ik_all, ik_nearest, kinematic_family, solver_name
from planecal.model.kinematics import Kinematics, fk, frames, from_axes, rot
from planecal.model.robot import load_robot


def _rows_match(A, B, tol=1e-7) -> bool:
    """Every row of A has a row of B within tol (angles wrapped), and vice versa."""
    def cover(X, Y):
        return all(np.min(np.abs(_wrap(Y - x)).max(axis=1)) < tol for x in X)
    return len(A) == len(B) and cover(A, B) and cover(B, A)


def _check_all(robot, n, seed, delta_std=0.0):
    """Over n random configurations within the limits: ik_all's rows all reach the pose
    (FK, 1e-9), lie within the limits, are distinct, and include the configuration."""
    rng = np.random.default_rng(seed)
    counts = []
    for _ in range(n):
        q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1])
        delta = rng.normal(0.0, delta_std, 6) if delta_std else None
        kin = robot.kinematics.with_offsets(delta)
        T = fk(kin, q)
        Q = ik_all(robot, T, delta)
        assert len(Q), q
        assert np.abs(fk(kin, Q) - T).max() < 1e-9
        assert np.all((Q >= robot.limits[:, 0] - 1e-9) & (Q <= robot.limits[:, 1] + 1e-9))
        assert np.min(np.abs(Q - q).max(axis=1)) < 1e-8  # the configuration itself
        assert len(np.unique(np.round(Q, 9), axis=0)) == len(Q)
        counts.append(len(ik_all(robot, T, delta, within=False)))
    return np.array(counts)


def test_mc70_keeps_its_closed_form_and_eaik_agrees():
    from eaik.IK_HP import HPRobot

    from planecal.model.ik import ik_problem
    mc70 = load_robot("mc70")
    assert solver_name(mc70) == "spherical_wrist"
    H, P, R0 = ik_problem(mc70.kinematics)
    other = HPRobot(H, P)
    assert other.hasKnownDecomposition()
    rng = np.random.default_rng(0)
    for _ in range(100):
        q = rng.uniform(-np.pi, np.pi, 6)
        T = fk(mc70.kinematics, q)
        mine = ik_all(mc70, T, within=False)
        pose = T.copy()
        pose[:3, :3] = T[:3, :3] @ R0.T
        theirs = np.asarray(other.IK(pose).Q).reshape(-1, 6)
        theirs = theirs[np.abs(fk(mc70.kinematics, theirs) - T).max(axis=(1, 2)) < 1e-9]
        assert _rows_match(mine, _wrap(theirs)), q
    counts = _check_all(mc70, 100, 1, delta_std=2e-3)
    assert counts.max() == 8


def test_ur5_three_parallel_axes_in_closed_form():
    ur5 = load_robot("ur5")
    assert solver_name(ur5) == "analytic" and "PARALLEL" in kinematic_family(ur5)
    counts = _check_all(ur5, 150, 2, delta_std=2e-3)
    # up to 8 branches (4 where the wrist point is near the shoulder's reach limits), and
    # every one of them twice per +-360 deg joint within the limits
    assert counts.max() == 8 and np.median(counts) == 8
    # at the UR's wrist singularity (q5 = 0) the exact solutions are still found
    T = fk(ur5.kinematics, np.zeros(6))
    assert np.abs(ik_all(ur5, T)).max(axis=1).min() < 1e-9


def test_imported_kuka_and_the_pose_draws_branch_choice(tmp_path):
    from planecal.cli import main
    urdf = Path(__file__).parent / "data" / "robots" / "kuka_kr16" / "urdf" / "kr16_2.urdf"
    assert main(["robot", "import", str(urdf), "--out", str(tmp_path / "kr16"), "--visual",
                 "collision", "-q"]) == 0
    kr16 = load_robot(tmp_path / "kr16")
    assert solver_name(kr16) == "analytic" and "SPHERICAL" in kinematic_family(kr16)
    counts = _check_all(kr16, 100, 3, delta_std=2e-3)
    assert counts.max() == 8
    # ik_nearest picks the solution of the wrist branch nearest the reference
    q = np.deg2rad([10, -70, 100, 20, 45, -30])
    T = fk(kr16.kinematics, q)
    np.testing.assert_allclose(ik_nearest(kr16, T, q + 0.05), q, atol=1e-9)


def _skew_chain():
    """A 6R chain no decomposition covers: the KR-like chain with its wrist axes offset
    (no spherical wrist) and no three parallel axes."""
    return Kinematics(alpha=[0, np.pi / 2, 0.05, np.pi / 2, -np.pi / 2, np.pi / 2],
                      a=[0, 0.26, 0.68, 0.035, 0.04, 0.03],
                      beta=np.zeros(6), theta=[0, 0.3, 0.2, 0, 0.1, 0],
                      d=[0.675, 0.02, -0.01, 0.67, 0.05, 0.158])


def test_numeric_solver_where_no_decomposition_is_known(tmp_path):
    from eaik.IK_HP import HPRobot

    from planecal.model.ik import ik_problem
    kin = _skew_chain()
    H, P, _ = ik_problem(kin)
    assert not HPRobot(H, P).hasKnownDecomposition()
    rng = np.random.default_rng(4)
    found, branches = 0, []
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, 6)
        T = fk(kin, q)
        Q = _numeric(kin, T)
        assert len(Q) and np.abs(fk(kin, Q) - T).max() < 1e-9
        found += np.min(np.abs(_wrap(Q - q)).max(axis=1)) < 1e-8
        branches.append(len(np.unique(np.round(_wrap(Q), 6), axis=0)))
    assert found >= 18  # the generating configuration is among them (all but rare misses)
    assert max(branches) >= 4


def test_ik_on_the_ur5_chain_agrees_with_numeric():
    """Two solvers on one chain (EAIK, numeric): the numeric ends are among the analytic
    branches, and usually all of them."""
    ur5 = load_robot("ur5")
    rng = np.random.default_rng(5)
    complete = 0
    for _ in range(20):
        T = fk(ur5.kinematics, rng.uniform(-np.pi, np.pi, 6))
        A = ik_all(ur5, T, within=False)
        N = _wrap(_numeric(ur5.kinematics, T))
        assert all(np.min(np.abs(_wrap(A - x)).max(axis=1)) < 1e-7 for x in N)
        complete += len(np.unique(np.round(N, 6), axis=0)) == len(A)
    assert complete >= 15


# ----- the chain from joint axes -------------------------------------------------------------

def _poe(P, U, T0, q):
    """Product of exponentials (Rodrigues), independent of the chain's DH form."""
    T = np.eye(4)
    for p, u, t in zip(P, U, q):
        K = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
        R = np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = R, p - R @ p
        T = T @ M
    return T @ T0


def _random_frame(rng):
    T = np.eye(4)
    T[:3, :3] = rot(0, rng.normal()) @ rot(1, rng.normal()) @ rot(2, rng.normal())
    T[:3, 3] = rng.normal(size=3)
    return T


@pytest.mark.parametrize("case", ["mc70", "ur5", "random", "flipped", "near_parallel"])
def test_from_axes_reproduces_the_chain(case):
    rng = np.random.default_rng(11)
    if case in ("mc70", "ur5"):
        kin = load_robot(case).kinematics
    else:
        kin = Kinematics(*rng.normal(size=(5, 6)), _random_frame(rng), _random_frame(rng))
    F = frames(kin, np.zeros(6))
    P = F[1:, :3, 3] + rng.normal(size=(6, 1)) * F[1:, :3, 2]  # any point on each axis
    U = F[1:, :3, 2] * (-1 if case == "flipped" else 1)
    if case == "near_parallel":  # axis 3 tilted 2e-4 rad off axis 2: Hayati's beta
        U[2] = F[2, :3, 2] + 2e-4 * F[2, :3, 0]
    T0 = fk(kin, np.zeros(6))
    got = from_axes(P, U, T0)
    Q = rng.uniform(-3, 3, (100, 6))
    ref = np.array([_poe(P, U / np.linalg.norm(U, axis=1, keepdims=True), T0, q) for q in Q])
    assert np.abs(fk(got, Q) - ref).max() < 1e-12
    if case == "near_parallel":
        # the tilt is Hayati's (beta, and alpha about the other axis), not a far normal
        assert np.hypot(got.beta[2], np.sin(got.alpha[2])) == pytest.approx(2e-4, rel=1e-6)
        assert got.beta[2] != 0 and abs(got.a[2]) < 5
    if case == "mc70":  # the MC70's frames: base and flange stay the identity
        assert np.abs(got.base - np.eye(4)).max() < 1e-15
