"""Ways around a blocked straight path (``planner``'s module docstring), near and far.

Near: the sensor backed out along its beam at both ends and moved between there (the wrist
turns over far from the plate): a few seconds of robot time. Far: through the scene's
calibration position or home (an arm reaching over one plate to a block behind another),
or back the way the robot came in, then on: up to a minute each on a large robot, so a
pose list serves a pose a near detour reaches before one only a far detour reaches.
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from planecal.model.encoder import counts_in_range, counts_to_joints
from planecal.model.ik import ik_all
from planecal.model.kinematics import fk
from planecal.sampling.poses import PoseGenerator

RETRACT_M = (0.25, 0.45)  # how far a detour backs out along the beam (tried in turn)


class Verdict(Protocol):
    ok: bool
    pair: tuple[str, str] | None


class Checker(Protocol):
    """A collision checker (``planecal.safety.collision.CollisionWorld``): stateless."""

    def check_config(self, q: np.ndarray) -> Verdict: ...

    def check_path(self, q0: np.ndarray, q1: np.ndarray) -> Verdict: ...


class Detour:
    """Via-points around a blocked straight path: the sensor backed out by ``RETRACT_M``
    along its beam at both ends, each by the IK solution nearest to its end (same wrist
    branch), so the legs are: back out, move, approach. Aimed with the pose generator's
    model. Where neither backs out clear (an arm reaching over one plate to another behind
    it), through the scene's calibration position, a clear pose near the plates, or else
    its home position: two legs, there and on."""

    def __init__(self, poses: PoseGenerator, checker: Checker):
        self.robot, self.poses, self.checker = poses.robot, poses, checker
        self.T_sf = poses.T_sf
        self.T_fs = np.linalg.inv(poses.T_sf)
        scene = poses.scene  # the clear poses a detour may pass through, in turn
        self.hubs = [q for q in (scene.calibration_q,
                                 None if scene.home_counts is None
                                 else counts_to_joints(self.robot, scene.home_counts))
                     if q is not None]

    def _retract(self, q: np.ndarray, d: float):
        """(joint angles, counts) of the sensor backed out by d from where q puts it."""
        T = fk(self.robot.kinematics.with_offsets(self.poses.delta), q) @ self.T_fs
        T[:3, 3] -= d * T[:3, 2]
        Q = ik_all(self.robot, T @ self.T_sf, self.poses.delta)
        if len(Q) == 0:
            return None
        v = Q[np.argmin(np.max(np.abs(Q - q) * self.poses.weights, axis=1))]
        c = self.poses.counts_target(v)
        return (v, c) if counts_in_range(self.robot, c) else None

    def find(self, q0: np.ndarray, q1: np.ndarray, back: tuple = (),
             far: bool = True) -> list | None:
        """[(q, counts), ...] of a clear detour from q0 to q1, or None: backed out along
        the beam at both ends; with ``far``, else through a hub, else (``back``: the
        configurations the robot came in by, nearest first) the way it came, then on as
        from there."""
        via = self._backed_out(q0, q1)
        if via is not None or not far:
            return via
        return self.far(q0, q1, back)

    def far(self, q0: np.ndarray, q1: np.ndarray, back: tuple = ()) -> list | None:
        """``find``'s far detours alone (a caller that knows no near one is clear): through
        a hub, else the way the robot came in and on from there."""
        via = self._hub(q0, q1)
        if via is not None or not back:
            return via
        c, at, legs = self.checker, q0, []
        for q in back:  # the legs it came by, each checked again
            q = np.asarray(q, float)
            ch = self.poses.counts_target(q)
            if not (counts_in_range(self.robot, ch) and c.check_config(q).ok
                    and c.check_path(at, q).ok):
                return None
            legs.append((q, ch))
            at = q
        if c.check_path(at, q1).ok:
            return legs
        on = self._backed_out(at, q1) or self._hub(at, q1)
        return None if on is None else legs + on

    def _backed_out(self, q0: np.ndarray, q1: np.ndarray) -> list | None:
        for d in RETRACT_M:
            a, b = self._retract(q0, d), self._retract(q1, d)
            if a is None or b is None:
                continue
            c, qa, qb = self.checker, a[0], b[0]
            if (c.check_config(qa).ok and c.check_config(qb).ok and c.check_path(q0, qa).ok
                    and c.check_path(qa, qb).ok and c.check_path(qb, q1).ok):
                return [a, b]
        return None

    def _hub(self, q0: np.ndarray, q1: np.ndarray) -> list | None:
        c = self.checker
        for hub in self.hubs:
            ch = self.poses.counts_target(hub)
            if (counts_in_range(self.robot, ch) and c.check_config(hub).ok
                    and c.check_path(q0, hub).ok and c.check_path(hub, q1).ok):
                return [(np.array(hub, float), ch)]
        return None
