"""The twin's joint-side error sources, turned into what the tick (``ticks``) reads: the
flags, the per-joint constants in ``F`` and the world ``W`` (gear harmonics and the
gravity model). The tick applies them (``ticks.joint_row``, in the order written there).

* repeatability: a perturbation N(0, s^2) per joint, drawn at each rest;
  ``s = robot.repeatability_sigma`` gives the flange a 3-sigma spread of the robot's
  repeatability (JIS B 8432 +-0.07 mm for the MC70: s ~ 1.1e-5 rad).
* encoder quantisation: the motor sits anywhere within +-1/2 count of what its encoder
  reads, a new position U(-1/2, 1/2) per joint at each rest.
* gear transmission error: per joint, sum_h A_h sin(f_h q + phi_h) (amplitude A [rad],
  f [1/rad]: periods per radian of the joint, phase [rad]).
* backlash: joint j's output trails its motor by b_j / 2 against the direction of its
  last motion; a joint whose gravity torque reaches its preload rests on the flank gravity
  pushes it to, whichever way it came (J2 and J3 carry their links' weight).
* gravity compliance: joint j yields c_j tau_j, c = 1/k the joint's compliance and tau
  the gravity torque of the links' masses (robot.json ``masses``) and the payload, as
  the twin's MuJoCo model holds them (``gravity_model``).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from planecal.model.robot import Robot
from planecal.estimation.noise import repeatability_sigma
from planecal.twin import ticks

GRAVITY = np.array([0.0, 0.0, -9.81])
EPS_BLOCK = 64  # rests drawn at once (perturbations, quantisation)
MAX_HARMONICS = 4


@dataclass(frozen=True)
class JointErrors:
    """The joint-side error sources (all off by default). ``repeatability_m``: the
    flange's 3-sigma repeatability [m]; ``quantization``: sub-count motor positions;
    ``gear``: per joint a list of (amplitude rad, frequency 1/rad, phase rad);
    ``backlash_rad`` (6,) full widths; ``compliance_rad_per_nm`` (6,) c = 1/k."""
    repeatability_m: float = 0.0
    quantization: bool = False
    gear: tuple = ()
    backlash_rad: tuple | None = None
    backlash_preload_nm: tuple | None = None
    compliance_rad_per_nm: tuple | None = None

    def flags(self) -> int:
        f = 0
        if self.repeatability_m > 0:
            f |= ticks.REPEAT
        if self.quantization:
            f |= ticks.QUANT
        if any(len(h) for h in self.gear):
            f |= ticks.GEAR
        if self.backlash_rad is not None and np.any(np.asarray(self.backlash_rad) != 0):
            f |= ticks.BACKLASH
        if (self.compliance_rad_per_nm is not None
                and np.any(np.asarray(self.compliance_rad_per_nm) != 0)):
            f |= ticks.COMPLY
        if (f & ticks.BACKLASH and self.backlash_preload_nm is not None
                and np.any(np.nan_to_num(np.asarray(self.backlash_preload_nm, float)) > 0)):
            f |= ticks.PRELOADED
        return f

    def sigma(self, robot: Robot) -> float:
        r = self.repeatability_m
        return repeatability_sigma(robot, r) if r > 0 else 0.0

    def harmonics(self) -> np.ndarray:
        """(6, MAX_HARMONICS, 3): amplitude, frequency, phase; unused rows zero."""
        G = np.zeros((6, MAX_HARMONICS, 3))
        for j, hs in enumerate(self.gear):
            if len(hs) > MAX_HARMONICS:
                raise ValueError(f"gear error of joint {j + 1}: at most {MAX_HARMONICS} harmonics")
            for h, (a, f, phi) in enumerate(hs):
                G[j, h] = (a, f, phi)
        return G

    def fill(self, F: np.ndarray) -> None:
        """The per-joint constants into the tick's F."""
        if self.backlash_rad is not None:
            F[ticks.BACK:ticks.BACK + 6] = np.asarray(self.backlash_rad, float).reshape(6)
        if self.compliance_rad_per_nm is not None:
            F[ticks.COMP:ticks.COMP + 6] = np.asarray(self.compliance_rad_per_nm,
                                                      float).reshape(6)
        if self.backlash_preload_nm is not None:
            F[ticks.PRELOAD:ticks.PRELOAD + 6] = np.nan_to_num(
                np.asarray(self.backlash_preload_nm, float).reshape(6))


def _body_pose(model: mujoco.MjModel, b: int) -> np.ndarray:
    T = np.eye(4)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.body_quat[b])
    T[:3, :3] = R.reshape(3, 3)
    T[:3, 3] = model.body_pos[b]
    return T


def gravity_model(model: mujoco.MjModel, link_bodies: list[int], tool_body: int):
    """(base pose (4,4), body poses before each hinge (6,4,4), mass bodies (m,), centres
    of mass in their body frames (m,3), masses (m,), gravity (3,)) of the twin's model:
    the chain and the inertials MuJoCo holds (links 1..6, the tool's on link 6)."""
    base = _body_pose(model, int(model.body_parentid[link_bodies[0]]))
    P = np.array([_body_pose(model, b) for b in link_bodies])
    mbody, mcom, mkg = [], [], []
    for k, b in enumerate(link_bodies, 1):
        mbody.append(k)
        mcom.append(model.body_ipos[b].copy())
        mkg.append(float(model.body_mass[b]))
    T = _body_pose(model, tool_body)  # on the last link
    mbody.append(len(link_bodies))
    mcom.append(T[:3, :3] @ model.body_ipos[tool_body] + T[:3, 3])
    mkg.append(float(model.body_mass[tool_body]))
    return (base, P, np.array(mbody, np.int64), np.array(mcom), np.array(mkg),
            GRAVITY.copy())
