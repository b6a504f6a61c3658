"""ISO 9283 pose accuracy AP and repeatability RP on the twin (seed 3.2-3.3; the
package docstring says where the cube goes, how each model commands it, and where (tool
point, flange, named TCPs) and in which frame AP is measured)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import report
from planecal.model.encoder import counts_to_joints
from planecal.studies.validation.settings import ValidationSettings


def iso_points(center: np.ndarray, edge: float) -> np.ndarray:
    """P1..P5 (5, 3): centre and 0.8 of the way to the four corners of the diagonal plane."""
    h = edge / 2
    corners = np.array([[-h, -h, -h], [h, h, -h], [h, h, h], [-h, -h, h]])
    return np.vstack([center, center + 0.8 * corners])


def ap_rp(attained: np.ndarray, commanded: np.ndarray):
    """ISO 9283 per pose from ``attained`` (cycles, n, 3) positions of ``commanded`` (n, 3):
    AP = |barycentre - commanded| (7.2.1; the figure of a pose set is the worst pose's,
    not the mean), RP = l_bar + 3 S_l with l the distances from the barycentre (7.2.2):
    (AP (n,), its vector (n, 3), RP (n,)), in the positions' unit."""
    bary = attained.mean(0)
    lj = np.linalg.norm(attained - bary[None], axis=2)
    return (np.linalg.norm(bary - commanded, axis=1), bary - commanded,
            lj.mean(0) + 3 * lj.std(0, ddof=1))


class Mover:
    """Moves the twin to counts as the robot moves there: the sampling run's step path
    (``sampling.driver``), each path collision-checked once (``checker``; None: not
    checked) and, where the straight one is blocked, the sampling run's detour
    (``detour``: a ``sampling.detour.Detour``, backing out along the beam), then held
    until the robot is at rest on the counts (it settles: a fresh repeatability draw). A
    joint's backlash follows the direction it came from."""

    def __init__(self, twin, robot, checker=None, detour=None):
        from planecal.links.base import AlwaysEnabled
        from planecal.sampling.driver import Driver
        self.twin, self.robot, self.checker, self.detour = twin, robot, checker, detour
        self.drv = Driver(twin, twin, AlwaysEnabled(), robot)
        self.drv.start()
        self._routes: dict = {}

    def approach(self, c0, c1) -> np.ndarray:
        """Each joint's direction of motion (6,) int -1/0/+1 on the straight path from counts
        c0 to c1 (joint side: the wrist coupling applied), the side its backlash takes."""
        dq = (self.robot.coupling / self.robot.gains[None, :]) @ (
            np.asarray(c1, float) - np.asarray(c0, float))
        return np.sign(dq).astype(np.int64)

    def route(self, c0, c1) -> list | None:
        """The counts to pass from c0 to c1: ``[c1]`` where the straight path is clear, the
        detour's via-points and c1 where only a detour is, None where neither is."""
        c1 = np.asarray(c1, np.int64)
        if self.checker is None:
            return [c1]
        key = (np.asarray(c0, np.int64).tobytes(), c1.tobytes())
        if key not in self._routes:
            q0, q1 = counts_to_joints(self.robot, np.array([c0, c1]))
            way = None
            if self.checker.check_path(q0, q1).ok:
                way = [c1]
            elif self.detour is not None:
                via = self.detour.find(q0, q1)
                way = None if via is None else [np.asarray(c, np.int64) for _, c in via] + [c1]
            self._routes[key] = way
        return self._routes[key]

    def path_ok(self, c0, c1) -> bool:
        return self.route(c0, c1) is not None

    def go(self, counts, what: str = "pose") -> None:
        from planecal.sampling.driver import plan_move
        c = np.asarray(counts, np.int64)
        way = self.route(self.drv.commanded_counts, c)
        if way is None:
            raise InputError(f"{what}: the path there is not collision-free")
        for target in way:
            rows = plan_move(self.drv, target)
            if rows is None:
                raise InputError(f"{what}: counts outside the encoder range")
            self.drv.follow(rows)
            for _ in range(1000):  # the servo's lag: a few tens of ticks at most
                if np.array_equal(self.drv.current, target):
                    break
                self.drv.hold()
            else:
                raise RuntimeError(f"{what}: the twin did not come to rest on its counts")


def robot_frame(robot, world) -> np.ndarray:
    """The frame ISO 9283 measures in, in the cell frame (module docstring): the true
    robot's frame of joint 1 at its zero, mapped onto the nominal one's. Identity in the
    ideal world with delta1 = 0."""
    from planecal.estimation.compensate import registered_frame
    kin = world.kinematics if world.kinematics is not None else robot.kinematics
    return registered_frame(robot, kin.with_offsets(world.params.joint_offsets))




@dataclass(frozen=True, eq=False)
class IsoPlan:
    """The ISO poses and what each model commands there: ``points_m`` P1..P5 (5, 3) (tool
    points, robot frame), the cube, the flange orientation ``R`` and the joints whose IK
    branch each pose takes (``q_ref``), per model (``counts``
    name -> (5, 6) int64) and its tool point in its flange frame (``tool_in_flange``), each
    pose's approach direction per joint (``direction``: name -> (5, 6), as the robot's
    counts showed it in a cycle P1 .. P5, P1 of that model's, ``observe_directions``), and
    how far each pose's commanded joints lie outside the
    calibrated region (the worst model's: ``outside_mm`` beyond the flange hull's margin,
    ``outside_deg`` beyond a joint's sampled range and margin; 0 inside)."""
    points_m: np.ndarray
    center_m: np.ndarray
    edge_m: float
    R: np.ndarray
    q_ref: np.ndarray
    counts: dict
    tool_in_flange: dict
    outside_mm: np.ndarray
    outside_deg: np.ndarray
    direction: dict | None = None


def _pose(R, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def cycle_directions(mover: "Mover", cs: np.ndarray) -> np.ndarray:
    """Each pose's approach direction (5, 6) in the cycle P1 .. P5, P1 (``Mover.approach``
    from the pose before); a joint that does not move into a pose keeps the direction it
    came into the pose before with (the twin's backlash keeps its flank)."""
    n = len(cs)
    d = np.array([mover.approach(cs[i - 1], cs[i]) for i in range(n)])
    for _ in range(n):  # carry each joint's last motion forward round the cycle
        for i in range(n):
            d[i] = np.where(d[i] == 0, d[i - 1], d[i])
    return d


def _outside(robot, region, cs) -> tuple[np.ndarray, np.ndarray]:
    q = counts_to_joints(robot, cs)
    return region.distance_m(q, robot) * 1e3, np.degrees(region.outside(q).max(1))


def plan_iso(scene, commanders: list, center, edge: float, R, q_ref, mover: "Mover",
             region=None, checker=None, inside: bool = True) -> IsoPlan:
    """Each model's counts for P1..P5 of the cube (``commanders``: ``Commander``s, the
    first the nominal model, whose path gives every model the joints' approach
    directions). InputError (what to shrink) where a pose is not reachable by a model, not
    collision-free, a path of the cycles is not, or (``inside``) a pose lies outside the
    calibrated ``region`` (``compensate.Region``)."""
    robot = scene.robot
    P = iso_points(center, edge)
    counts, tools = {}, {}
    direction = None
    out_mm, out_deg = np.zeros(5), np.zeros(5)
    for cmd in commanders:
        t = np.asarray(cmd.tool_in_flange, float)
        cs = []
        for i, p in enumerate(P):
            c = cmd.command(_pose(R, p - R @ t), q_ref,
                            None if direction is None else direction[i])
            if c is None:
                raise InputError(f"ISO pose P{i + 1} is not reachable by the {cmd.name} "
                                 "model; give a smaller --cube-mm")
            if checker is not None and not checker.check_config(
                    counts_to_joints(robot, c)).ok:
                raise InputError(f"ISO pose P{i + 1} is not collision-free; give a smaller "
                                 "--cube-mm")
            cs.append(c)
        cs = np.array(cs, np.int64)
        if direction is None:  # the cycle P1 .. P5, P1: each pose approached from the last
            direction = cycle_directions(mover, cs)
        counts[cmd.name], tools[cmd.name] = cs, t
        if region is not None:  # each model as it comes: a cube outside stops early
            mm, deg = _outside(robot, region, cs)
            out_mm, out_deg = np.maximum(out_mm, mm), np.maximum(out_deg, deg)
            far = int(np.argmax(np.maximum(out_mm, out_deg)))
            if inside and (out_mm[far] > 0 or out_deg[far] > 0):
                raise InputError(f"ISO pose P{far + 1} lies outside the calibrated region "
                                 f"({out_mm[far]:.0f} mm, {out_deg[far]:.1f} deg); give a "
                                 "smaller --cube-mm")
    _check_paths(mover, counts)
    plan = IsoPlan(P, np.asarray(center, float), float(edge), np.asarray(R, float),
                   np.asarray(q_ref, float), counts, tools, out_mm, out_deg)
    return observe_directions(plan, commanders, mover, checker, robot, direction)


def _check_paths(mover: "Mover", counts: dict) -> None:
    """Every path of every model's cycles, from where the robot stands, before any is
    driven: InputError naming the first blocked one."""
    prev = mover.drv.commanded_counts
    for name, cs in counts.items():
        for i, c in enumerate([cs[0]] + list(cs[1:]) + [cs[0]]):
            if not mover.path_ok(prev, c):
                raise InputError(f"ISO pose P{i % 5 + 1} ({name} model): the path there is "
                                 "not collision-free; give a smaller --cube-mm")
            prev = c
        prev = cs[-1]


def cycle_observed(mover: "Mover", cs: np.ndarray) -> np.ndarray:
    """Drive one cycle P1 .. P5, P1 of counts ``cs`` (unmeasured) and return each pose's
    approach direction (5, 6) as the robot's counts show it there (``Driver.direction``:
    the sign of each joint's last joint-side motion, what its backlash follows)."""
    out = np.zeros((len(cs), 6), np.int64)
    mover.go(cs[0], "ISO pose P1")
    for i in [*range(1, len(cs)), 0]:
        mover.go(cs[i], f"ISO pose P{i + 1}")
        out[i] = mover.drv.direction
    return out


ROUNDS = 3  # observe and command again at most this often (the direction settles in 1-2)


def observe_directions(plan: IsoPlan, commanders: list, mover: "Mover", checker,
                       robot, guess: np.ndarray) -> IsoPlan:
    """Each model's counts commanded with the approach directions its own cycle shows
    (``cycle_observed``): the straight paths' signs (``cycle_directions``) are not always
    the last motion of the step path (a wrist joint moved by the coupling while one motor
    still runs; the first visit of P1 comes from elsewhere). A model whose counts change
    commands again (and is checked again: reachable, collision-free) until its directions
    hold, at most ``ROUNDS`` times; ``guess``: the directions every model first commanded
    with. What a real cell knows too: its encoders' counts."""
    counts, direction = dict(plan.counts), {}
    for cmd in commanders:
        cs, d = counts[cmd.name], guess
        for _ in range(ROUNDS):
            seen = cycle_observed(mover, cs)
            if np.array_equal(seen, d):
                break
            d = seen
            t = plan.tool_in_flange[cmd.name]
            new = [cmd.command(_pose(plan.R, p - plan.R @ t), plan.q_ref, d[i])
                   for i, p in enumerate(plan.points_m)]
            if any(c is None for c in new):
                raise InputError(f"ISO poses: the {cmd.name} model cannot command them from "
                                 "the directions its cycle shows; give a smaller --cube-mm")
            new = np.array(new, np.int64)
            if np.array_equal(new, cs):
                break
            if checker is not None and not all(
                    checker.check_config(q).ok for q in counts_to_joints(robot, new)):
                raise InputError("ISO poses: not collision-free once commanded from their "
                                 "approach directions; give a smaller --cube-mm")
            cs = new
        counts[cmd.name], direction[cmd.name] = cs, d
    return dataclasses.replace(plan, counts=counts, direction=direction)


def iso9283(twin, plan: IsoPlan, st: ValidationSettings, mover: "Mover", standoff_m: float,
            tcps: dict | None = None, frame: np.ndarray | None = None) -> dict:
    """Drive each model's plan ``st.cycles`` times and measure, per model, AP and RP (mm)
    at the tool point (``tool``: the true sensor's beam point at ``standoff_m``), at the
    flange (``flange``) and at each named TCP (``tcps``: name -> (3,) in the flange
    frame), against what that model commanded there; in the robot's frame ``frame`` (a
    4x4 in the cell frame, ``robot_frame``; None: the cell's) and in the cell frame; with
    each model's ``counts`` (5, 6) and ``tool_in_flange_m``."""
    tcps = tcps or {}
    F = np.eye(4) if frame is None else np.asarray(frame, float)
    Finv = np.linalg.inv(F)
    P, R = plan.points_m, plan.R
    out = {"points_m": P, "edge_m": plan.edge_m, "center_m": plan.center_m,
           "flange_rotation": R, "robot_frame": F, "models": {}}
    for name, cs in plan.counts.items():
        n = 2 + len(tcps)  # tool point, flange, each named TCP
        att = np.zeros((st.cycles, 5, n, 3))
        mover.go(cs[-1], "ISO pose P5")  # the first P1 approached as every later one
        mover.go(cs[0], "ISO pose P1")
        for j in range(st.cycles):
            report(j + 1, st.cycles, f"ISO 9283: the {name} model's cycle")
            for i in range(5):
                mover.go(cs[i], f"ISO pose P{i + 1}")
                Tf, Ts = twin.flange_pose(), twin.sensor_pose()
                att[j, i, 0] = Ts[:3, 3] + standoff_m * Ts[:3, 2]
                att[j, i, 1] = Tf[:3, 3]
                for k, tcp in enumerate(tcps.values()):
                    att[j, i, 2 + k] = Tf[:3, :3] @ tcp + Tf[:3, 3]
        t = plan.tool_in_flange[name]
        commanded = [P, P - R @ t] + [P + (R @ (tcp - t)) for tcp in tcps.values()]
        at = [_figures(att[:, :, k], commanded[k], Finv) for k in range(n)]
        out["models"][name] = {"tool": at[0], "flange": at[1],
                               "tcps": dict(zip(tcps, at[2:])), "counts": cs,
                               "tool_in_flange_m": t,
                               "direction": None if plan.direction is None
                               else plan.direction[name]}
    return out


def _figures(att: np.ndarray, commanded: np.ndarray, Finv: np.ndarray) -> dict:
    """AP, its vector and RP per pose [mm] in the robot's frame (``Finv``: the cell frame
    into it) and AP in the cell frame, of positions ``att`` (cycles, 5, 3) [m] in the cell
    frame."""
    ap, ap_xyz, rp = ap_rp(att @ Finv[:3, :3].T + Finv[:3, 3], commanded)
    ap_c, ap_xyz_c, _ = ap_rp(att, commanded)
    return {"ap_mm": ap * 1e3, "ap_xyz_mm": ap_xyz * 1e3, "rp_mm": rp * 1e3,
            "ap_cell_mm": ap_c * 1e3, "ap_xyz_cell_mm": ap_xyz_c * 1e3}
