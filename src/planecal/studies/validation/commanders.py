"""The models that command the ISO 9283 poses (``Commander``): each puts *its own estimate*
of the tool point on the ISO point (the package docstring).

* ``ModelCommander``: a calibrated model of any level (``compensate.CalibratedModel``; the
  nominal model is one with robot.json's geometry, zero offsets and the scene's sensor):
  the closed-form IK with its joint offsets, then Newton on the whole model
  (``compensate.solve_poses``), registered on the robot's frame as ``compensate`` does.
  Its tool point is the beam point of *its* sensor pose at the scene's measuring centre.
* ``OracleCommander``: the twin's own whole true model (``twin.oracle.TrueModel``),
  backlash included by each pose's approach direction: what a model that knew every error
  source of the world would leave (repeatability, whole counts). Each level's own floor is
  a ``ModelCommander`` of the level's best parameters (``floors``).
"""
from __future__ import annotations

from typing import Protocol

import numpy as np

from planecal.model.encoder import joints_to_counts
from planecal.model.ik import ik_nearest
from planecal.model.measurement import beam_point


class Commander(Protocol):
    """A model commanding flange poses: ``name`` (its label in the results),
    ``tool_in_flange`` (3,) [m]: where it believes the tool point is in its flange frame;
    ``command(T, q_ref, direction)``: the counts at which it puts its flange at T (4x4 in
    the robot's frame), on the IK branch nearest ``q_ref``; None where it cannot.
    ``direction`` (6,) int: each joint's approach direction there (``Mover.approach``)."""
    name: str
    tool_in_flange: np.ndarray

    def command(self, T: np.ndarray, q_ref: np.ndarray,
                direction: np.ndarray | None = None) -> np.ndarray | None: ...


class ModelCommander:
    """A ``compensate.CalibratedModel`` commanding (module docstring)."""

    def __init__(self, name: str, model, standoff_m: float):
        p = model.params
        self.name, self.model = name, model
        self.tool_in_flange = beam_point(p.sensor_origin, p.phi_y, p.phi_z, standoff_m)
        self._frame = model.robot_frame()

    def command(self, T, q_ref, direction=None):
        from planecal.estimation.compensate import solve_poses
        robot = self.model.robot
        q0 = ik_nearest(robot, T, q_ref, delta=self.model.params.joint_offsets,
                        weights=np.abs(robot.gains))
        if q0 is None:
            return None
        # T is in the robot's frame (J1's axis and zero): the model's own base frame is
        # registered to it, as compensate does
        q, _, ok, _, _ = solve_poses(self.model, (self._frame @ T)[None], q0[None],
                                     direction=None if direction is None else direction[None])
        return joints_to_counts(robot, q[0]) if ok[0] else None


class OracleCommander:
    """The twin's whole true model commanding: its flange at the target's orientation and
    its true tool point on the target's, in the cell frame ``frame @ T`` (the true robot's
    frame), each joint's backlash on the flank ``direction`` leaves it; started from the
    nominal IK."""

    def __init__(self, true_model, frame: np.ndarray, robot, name: str = "oracle"):
        self.name, self.true_model, self.frame, self.robot = name, true_model, frame, robot
        self.tool_in_flange = true_model.tool_in_flange

    def command(self, T, q_ref, direction=None):
        q0 = ik_nearest(self.robot, T, q_ref, weights=np.abs(self.robot.gains))
        if q0 is None:
            return None
        Tc = self.frame @ T
        c, _ = self.true_model.command(Tc[:3, :3], Tc[:3, :3] @ self.tool_in_flange
                                       + Tc[:3, 3], joints_to_counts(self.robot, q0),
                                       direction)
        return c
