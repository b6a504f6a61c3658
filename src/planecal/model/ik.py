"""Inverse kinematics of the robot's nominal chain, with joint offsets: every solution
within the joint limits, and the one nearest a given configuration.

One entry, ``ik_all`` (and ``ik_nearest`` on it); the solver is robot.json's
``inverse_kinematics``, or, where it says null, chosen from the geometry (``solver_name``):

* ``spherical_wrist``: the closed form of the MC70 family (a standard DH table with
  a6 = a5 = a4 = 0, d2 = d3 = 0, alpha = (+90, 0, +90, -90, +90, 0) deg): up to 8 branches.
* ``analytic``: closed form by subproblem decomposition (EAIK, Ostermeier et al. 2024:
  a published library): any 6R arm whose axes it can decompose, e.g. a spherical wrist
  with any other geometry (KUKA, ABB, FANUC arms) or three parallel axes (the UR family).
  Built from the chain's joint axes at q = 0 (``ik_problem``); up to 8 (rarely 16)
  branches, each checked by the forward kinematics.
* ``numeric``: for any other 6R arm, damped Newton steps on the analytic Jacobian from
  ``NUMERIC_STARTS`` fixed starts at once, the converged, distinct ends kept. It finds
  the branches its starts lead to, usually all of them, with no guarantee.

Joint offsets delta shift every joint's zero (theta = theta0 + delta + q), so the chain
with offsets reaches T at q when the nominal one reaches it at q + delta: every solver
solves the nominal chain and subtracts delta. Each solution, wrapped to [-pi, pi), is
then listed with every 2*pi-equivalent inside the joint limits (J4 +-360 deg on the MC70
has two, a UR's +-360 deg joints two each).
"""
from __future__ import annotations

import weakref

import numpy as np

from planecal.base.errors import InputError
from planecal.model.kinematics import Kinematics, fk, fk_jacobian, frames
from planecal.model.robot import Robot

SOLVERS = ("spherical_wrist", "analytic", "numeric")
NUMERIC_STARTS = 48  # fixed starts of the numeric solver (a Halton set over the joints)
CHECK_M = 1e-7  # a solution must reach the pose this closely (m; rotation entries alike)


def _wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def _rot_z_x(theta: float, alpha: float) -> np.ndarray:
    """Rotation part of one DH link, Rz(theta) Rx(alpha)."""
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array([[ct, -st * ca, st * sa], [st, ct * ca, -ct * sa], [0.0, sa, ca]])


def _expand_turns(robot: Robot, Q: np.ndarray) -> np.ndarray:
    """Every 2*pi-equivalent of each joint of each row of Q (wrapped to [-pi, pi)) that
    lies within the joint limits (joints such as J4 +-360 deg have several)."""
    turns = 2 * np.pi * np.arange(-3, 4)
    for j in range(Q.shape[1]):
        vals = Q[:, j, None] + turns  # (m, 7)
        lo, hi = robot.limits[j]
        ok = (vals >= lo - 1e-12) & (vals <= hi + 1e-12)
        rows, k = np.nonzero(ok)
        Q = Q[rows].copy()
        Q[:, j] = vals[rows, k]
    return Q


# ----- which solver ---------------------------------------------------------------------------

_SOLVERS: "weakref.WeakKeyDictionary[Kinematics, tuple]" = weakref.WeakKeyDictionary()


def _is_mc70_wrist(robot: Robot) -> bool:
    if robot.theta0 is None:
        return False
    al = np.rad2deg(robot.alpha)
    return (np.allclose(al, [90, 0, 90, -90, 90, 0], atol=1e-9)
            and np.allclose([robot.a[3], robot.a[4], robot.a[5], robot.d[1], robot.d[2]], 0.0))


def _solver(robot: Robot) -> tuple:
    """(name, state) of the robot's solver, made once per chain."""
    kin = robot.kinematics
    hit = _SOLVERS.get(kin)
    if hit is None:
        hit = _SOLVERS[kin] = _make_solver(robot)
    return hit


def _make_solver(robot: Robot) -> tuple:
    kind = robot.ik_kind
    if kind == "spherical_wrist" or (kind is None and _is_mc70_wrist(robot)):
        if not _is_mc70_wrist(robot):
            raise InputError(f"{robot.name}: inverse_kinematics 'spherical_wrist' is the MC70 "
                             "family's closed form; this chain is not of it (say 'analytic', "
                             "'numeric' or null)")
        return "spherical_wrist", None
    if kind in (None, "analytic"):
        problem = ik_problem(robot.kinematics)
        from eaik.IK_HP import HPRobot
        solver = HPRobot(problem[0], problem[1])
        if solver.hasKnownDecomposition():
            return "analytic", (solver, problem[2])
        if kind == "analytic":
            raise InputError(f"{robot.name}: inverse_kinematics 'analytic': no subproblem "
                             "decomposition of this arm is known (say 'numeric' or null)")
    return "numeric", None


def solver_name(robot: Robot) -> str:
    """The solver ``ik_all`` uses for this robot (module docstring)."""
    return _solver(robot)[0]


def kinematic_family(robot: Robot) -> str:
    """What the solver found the arm to be (EAIK's family name for ``analytic``)."""
    name, state = _solver(robot)
    if name == "analytic":
        return state[0].getKinematicFamily()
    return {"spherical_wrist": "MC70 spherical wrist", "numeric": "no known decomposition"}[name]


def numeric_reason(robot: Robot) -> str:
    """Why no closed form applies, in the two families most arms are of: how far the last
    three axes miss a common point (a spherical wrist) and how far from parallel the most
    nearly parallel three consecutive axes are (the UR family)."""
    F = frames(robot.kinematics, np.zeros(robot.kinematics.n_joints))
    H, pts = F[1:, :3, 2], F[1:, :3, 3]

    def miss(idx) -> float:  # the point nearest the lines; its largest distance from them
        A = sum(np.eye(3) - np.outer(H[i], H[i]) for i in idx)
        b = sum((np.eye(3) - np.outer(H[i], H[i])) @ pts[i] for i in idx)
        x = np.linalg.lstsq(A, b, rcond=None)[0]
        return max(float(np.linalg.norm((np.eye(3) - np.outer(H[i], H[i])) @ (x - pts[i])))
                   for i in idx)

    def spread(i) -> float:  # largest angle between axes i, i+1, i+2 (as lines)
        return max(float(np.arccos(np.clip(abs(H[a] @ H[b]), -1.0, 1.0)))
                   for a in range(i, i + 3) for b in range(a + 1, i + 3))

    best = min(range(len(H) - 2), key=spread)
    return (f"axes 4-6 miss a common point by {miss((3, 4, 5)) * 1e3:.3g} mm (a spherical "
            f"wrist), and the most nearly parallel three axes, {best + 1}-{best + 3}, are "
            f"{np.rad2deg(spread(best)):.3g} deg apart")


def ik_problem(kin: Kinematics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chain as joint axes and offsets at q = 0 (product of exponentials): H (6, 3)
    the axes, P (7, 3) base origin -> axis 1 point -> ... -> axis 6 point -> flange
    origin, and R0 the flange's rotation at q = 0. Then T(q) = [Rot(H, q) R0, p(q)]."""
    F = frames(kin, np.zeros(kin.n_joints))
    H = F[1:, :3, 2]
    pts = F[1:, :3, 3]
    T0 = fk(kin, np.zeros(kin.n_joints))
    P = np.vstack([pts[0], np.diff(pts, axis=0), T0[:3, 3] - pts[-1]])
    return H, P, T0[:3, :3].copy()


# ----- the solvers ----------------------------------------------------------------------------

def _spherical_wrist(robot: Robot, T: np.ndarray, delta) -> np.ndarray:
    """The MC70 family's closed form with joint offsets delta: (k, 6) wrapped."""
    d1, d4, d6 = robot.d[0], robot.d[3], robot.d[5]
    a1, a2, a3 = robot.a[0], robot.a[1], robot.a[2]
    al = robot.alpha
    R, p = T[:3, :3], T[:3, 3]
    w = p - d6 * R[:, 2]
    L = np.hypot(a3, d4)
    beta = np.arctan2(d4, a3)
    sols = []
    rho = np.hypot(w[0], w[1])
    for front in (True, False):
        th1 = np.arctan2(w[1], w[0]) if front else np.arctan2(-w[1], -w[0])
        r = (rho if front else -rho) - a1
        s = w[2] - d1
        c = (r * r + s * s - a2 * a2 - L * L) / (2 * a2 * L)
        if abs(c) > 1 + 1e-12:
            continue
        c = min(max(c, -1.0), 1.0)
        R01 = _rot_z_x(th1, al[0])
        for phi in {np.arccos(c), -np.arccos(c)}:
            th3 = phi + beta
            th2 = np.arctan2(s, r) - np.arctan2(L * np.sin(phi), a2 + L * np.cos(phi))
            R03 = R01 @ _rot_z_x(th2, al[1]) @ _rot_z_x(th3, al[2])
            R36 = R03.T @ R
            s5 = np.hypot(R36[0, 2], R36[1, 2])
            for sign in (1.0, -1.0):
                th5 = np.arctan2(sign * s5, R36[2, 2])
                if s5 < 1e-12:  # wrist singularity: only th4 + th6 is defined; keep th4 = 0
                    th4 = 0.0
                    th6 = np.arctan2(R36[1, 0], R36[0, 0])
                else:
                    th4 = np.arctan2(sign * R36[1, 2], sign * R36[0, 2])
                    th6 = np.arctan2(sign * R36[2, 1], -sign * R36[2, 0])
                sols.append([th1, th2, th3, th4, th5, th6])
    if not sols:
        return np.zeros((0, 6))
    return _wrap(np.array(sols) - (robot.theta0 + (0.0 if delta is None else delta)))


def _analytic(state, T: np.ndarray) -> np.ndarray:
    solver, R0 = state
    pose = T.copy()
    pose[:3, :3] = T[:3, :3] @ R0.T
    # every solution, least-squares ones too: at a singularity (a UR at q5 = 0) the exact
    # ones are flagged so; ik_all keeps those the forward kinematics confirms
    return np.asarray(solver.IK(pose).Q, float).reshape(-1, 6)


def _halton(n: int, dim: int) -> np.ndarray:
    """The first n points of the Halton sequence in [0, 1)^dim (bases 2, 3, 5, ...)."""
    primes = [2, 3, 5, 7, 11, 13, 17, 19][:dim]
    out = np.zeros((n, dim))
    for k, b in enumerate(primes):
        for i in range(n):
            f, x, m = 1.0, 0.0, i + 1
            while m:
                f /= b
                x += f * (m % b)
                m //= b
            out[i, k] = x
    return out


def _numeric(kin: Kinematics, T: np.ndarray, iterations: int = 60) -> np.ndarray:
    """Damped Newton from NUMERIC_STARTS starts at once (module docstring): (k, 6)."""
    n = kin.n_joints
    Q = -np.pi + 2 * np.pi * _halton(NUMERIC_STARTS, n)
    lam2 = 1e-6
    for _ in range(iterations):
        X, J = fk_jacobian(kin, Q)
        e = _pose_error(X, T)
        if np.all(np.abs(e).max(axis=1) < 1e-13):
            break
        A = np.einsum("nki,nkj->nij", J, J) + lam2 * np.eye(n)
        step = np.linalg.solve(A, np.einsum("nki,nk->ni", J, e)[..., None])[..., 0]
        scale = np.minimum(1.0, 0.5 / np.maximum(np.abs(step).max(axis=1), 1e-300))
        Q = _wrap(Q + step * scale[:, None])
    X = fk(kin, Q)
    ok = np.abs(_pose_error(X, T)).max(axis=1) < 1e-10
    return Q[ok]


def _pose_error(X: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(N, 6): the target's position minus X's, and the rotation vector taking X's
    rotation to the target's (small-angle: half the sum of axis cross products)."""
    dp = T[:3, 3] - X[:, :3, 3]
    dr = 0.5 * sum(np.cross(X[:, :3, k], T[:3, k]) for k in range(3))
    return np.concatenate([dp, dr], axis=1)


def _distinct(Q: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Rows of Q (wrapped) that differ from every earlier row by more than tol."""
    out = []
    for q in Q:
        if all(np.abs(_wrap(q - r)).max() > tol for r in out):
            out.append(q)
    return np.array(out).reshape(-1, Q.shape[1] if Q.ndim == 2 else 6)


# ----- the entry ------------------------------------------------------------------------------

def ik_all(robot: Robot, T: np.ndarray, delta: np.ndarray | None = None,
           within: bool = True) -> np.ndarray:
    """Every IK solution (k, 6) for one flange pose T (4x4) of the nominal chain with joint
    offsets ``delta``. With ``within`` (default) every 2*pi-equivalent solution inside the
    joint limits is listed; without it, the solutions wrapped to [-pi, pi)."""
    T = np.asarray(T, float)
    name, state = _solver(robot)
    kin = robot.kinematics
    delta = None if delta is None else np.asarray(delta, float)
    if name == "spherical_wrist":
        Q = _spherical_wrist(robot, T, delta)
    else:
        Q = _analytic(state, T) if name == "analytic" else _numeric(kin, T)
        if len(Q):  # the MC70's closed form is exact; these are checked
            Q = _wrap(Q - (0.0 if delta is None else delta))
            X = fk(kin.with_offsets(delta), Q)
            Q = _distinct(Q[np.abs(X - T).max(axis=(1, 2)) < CHECK_M])
    if not len(Q):
        return np.zeros((0, 6))
    return _expand_turns(robot, Q) if within else Q


def turns(robot: Robot, q: np.ndarray) -> np.ndarray:
    """The configurations (k, 6) that put the flange where ``q`` does, ``q`` itself
    excluded: each joint turned by whole turns within its limits (J4, J6 of +-360 deg)."""
    q = np.asarray(q, float)
    Q = _expand_turns(robot, _wrap(q)[None])
    return Q[np.abs(Q - q).max(axis=1) > 1e-9]


def ik_nearest(robot: Robot, T: np.ndarray, q_near: np.ndarray,
               delta: np.ndarray | None = None, weights: np.ndarray | None = None):
    """The IK solution within limits nearest to q_near (weighted max-norm), or None."""
    Q = ik_all(robot, T, delta)
    if len(Q) == 0:
        return None
    w = np.ones(6) if weights is None else weights
    cost = np.max(np.abs(Q - q_near) * w, axis=1)
    return Q[np.argmin(cost)]
