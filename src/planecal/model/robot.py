"""Robot description, loaded from models/<robot>/robot.json: the nominal kinematic chain,
joint limits, encoder model, controller limits and link masses.

The chain every computation uses is ``Robot.kinematics`` (``planecal.model.kinematics``:
modified DH with Hayati's beta, a base and a flange frame). robot.json gives it one of two
ways: standard DH rows (``dh``; MODEL-NOTES), ``T_i = Rz(theta_i) Tz(d_i) Tx(a_i)
Rx(alpha_i)`` with ``theta_i = q_i + delta_i + theta0_i``, made into the chain exactly
(``from_standard_dh``; the table stays in ``Robot.theta0, d, a, alpha`` for the MC70's
closed-form IK), or the chain itself (``chain``: what ``planecal robot import`` writes
from a URDF; the table fields are then None). ``q`` are joint angles from the encoder
model and ``delta`` the joint offsets that calibration identifies. SI units (m, rad).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.formats.base import read_json, validate
from planecal.formats.robot import RobotFile
from planecal.base.paths import DEFAULT_ROBOT, robot_path  # noqa: F401 (also named here)
from planecal.model.kinematics import Kinematics, from_standard_dh

# the MC70's (seed H.1): the reference a robot without a stated repeatability is scaled from
REFERENCE_REACH_M = 2.8334658438426485  # kinematics.reach_m of models/mc70/robot.json
REFERENCE_REPEATABILITY_MM = 0.07  # its datasheet's, JIS B 8432


def default_repeatability_m(kin: Kinematics) -> float:
    """The repeatability [m] of a robot whose description states none: the MC70's 0.07 mm
    scaled by the arm's reach (``kinematics.reach_m``; a UR5-sized arm 0.021 mm, a KR 16
    0.052 mm). A stand-in for the datasheet's figure, which robot.json should hold."""
    from planecal.model.kinematics import reach_m
    return REFERENCE_REPEATABILITY_MM * 1e-3 * reach_m(kin) / REFERENCE_REACH_M


@dataclass(frozen=True)
class Robot:
    name: str
    theta0: np.ndarray | None  # (6,) rad: the standard DH table, None for a ``chain``
    d: np.ndarray | None  # (6,) m
    a: np.ndarray | None  # (6,) m
    alpha: np.ndarray | None  # (6,) rad
    limits: np.ndarray  # (6, 2) rad, [lower, upper]
    gains: np.ndarray  # (6,) counts/rad
    qe0: np.ndarray  # (6,) counts at the zero reference
    coupling: np.ndarray  # (6, 6) C with q = C x
    encoder_bits: int
    ik_kind: str | None
    repeatability_m: float
    tick_s: float
    max_step_counts: int
    trip_step_counts: int
    home_counts: np.ndarray  # (6,) int64
    source: Path | None = None
    # (link frame, centre of mass in it [m] (3,), mass [kg], inertia about the centre of
    # mass (ixx iyy izz ixy ixz iyz) or None): the arm's masses
    masses: tuple = ()
    kinematics: Kinematics | None = None  # the nominal chain
    digest: str = ""  # SHA-256 of the description's content (``description_digest``)
    joint_names: tuple[str, ...] = ()  # robot.json's (an imported robot's URDF names)
    payload_kg: float | None = None  # rated payload (the generic error profile scales by it)
    controller_kind: str | None = None  # "fd11", "ur" or None: which exports apply
    # level 3 (robot.json's ``transmission``): each joint's gear harmonic orders (cycles
    # per output revolution) and the gravity torque [N m] above which its backlash rests
    # on gravity's flank (inf: never, the flank of its last motion)
    gear_orders: tuple[tuple[int, ...], ...] = ((1, 2),) * 6
    backlash_preload_nm: tuple[float, ...] = (float("inf"),) * 6
    transmission_given: bool = False  # False: the defaults above (the robot gives none)
    # False: robot.json states no repeatability_mm; repeatability_m is then
    # ``default_repeatability_m`` (the MC70's scaled by reach), as every consumer reads it
    repeatability_given: bool = True

    def __post_init__(self):
        if self.kinematics is None:
            object.__setattr__(self, "kinematics",
                               from_standard_dh(self.theta0, self.d, self.a, self.alpha))

    @property
    def n_joints(self) -> int:
        return self.kinematics.n_joints

    @property
    def step_counts(self) -> int:
        """The step generator's step a tick [counts]: one count below the controller's
        limit ``max_step_counts`` (the MC70's FD11: 50 of 51). Every move, and every
        estimate of robot time, is cut at this step (``sampling.steps``)."""
        return max(1, self.max_step_counts - 1)

    @property
    def folder(self) -> Path | None:
        """The description's folder (models/<robot>/, or an imported robot's directory)."""
        return None if self.source is None else self.source.parent


def load_robot(name_or_path: str | Path = DEFAULT_ROBOT, relative_to: Path | None = None) -> Robot:
    """Load a robot description: a name under models/ (``mc70``), a folder holding
    robot.json (an imported robot) or a path to robot.json (``robot_path``). Validated by
    ``planecal.formats.robot.RobotFile``; one-line InputError otherwise."""
    p = robot_path(name_or_path, relative_to)
    raw = read_json(p, "robot description")
    rf = validate(RobotFile, raw, p, "robot description")
    enc, ctrl = rf.encoder, rf.controller
    if rf.dh is not None:
        table = dict(theta0=np.array([j.theta0_rad for j in rf.dh]),
                     d=np.array([j.d_m for j in rf.dh]), a=np.array([j.a_m for j in rf.dh]),
                     alpha=np.array([j.alpha_rad for j in rf.dh]))
        kin = from_standard_dh(table["theta0"], table["d"], table["a"], table["alpha"])
    else:
        c = rf.chain
        kin = Kinematics(*(np.array([getattr(j, k) for j in c.joints]) for k in
                           ("alpha_rad", "a_m", "beta_rad", "theta0_rad", "d_m")),
                         c.base.matrix(), c.flange.matrix())
        table = dict(theta0=None, d=None, a=None, alpha=None)
    return Robot(
        name=rf.name, **table,
        limits=np.deg2rad(np.array(rf.joint_limits_deg, float)),
        gains=np.array(enc.gain_counts_per_rad, float),
        qe0=np.array(enc.offset_counts, float),
        coupling=enc.coupling_matrix(),
        encoder_bits=enc.bits,
        ik_kind=rf.inverse_kinematics,
        repeatability_m=(default_repeatability_m(kin) if rf.repeatability_mm is None
                         else rf.repeatability_mm * 1e-3),
        repeatability_given=rf.repeatability_mm is not None,
        tick_s=ctrl.tick_s,
        max_step_counts=ctrl.max_step_counts,
        trip_step_counts=ctrl.trip_step_counts,
        home_counts=np.array(ctrl.home_counts, np.int64),
        source=p,
        masses=tuple((m.frame, np.array(m.com_m, float), m.mass_kg,
                      None if m.inertia_kg_m2 is None else np.array(m.inertia_kg_m2, float))
                     for m in rf.masses),
        kinematics=kin,
        digest=description_digest(raw),
        joint_names=tuple(rf.joint_names or ()),
        payload_kg=rf.payload_kg,
        controller_kind=ctrl.kind,
        **transmission(rf),
    )


def transmission(rf: RobotFile) -> dict:
    """The Robot's level-3 fields from robot.json's ``transmission`` (or the defaults)."""
    from planecal.formats.robot import DEFAULT_HARMONICS
    t = rf.transmission
    if t is None:
        return dict(gear_orders=(DEFAULT_HARMONICS,) * 6,
                    backlash_preload_nm=(float("inf"),) * 6, transmission_given=False)
    return dict(gear_orders=tuple(tuple(int(f) for f in fs)
                                  for fs in t.harmonics_cycles_per_rev),
                backlash_preload_nm=tuple(float("inf") if v is None else float(v)
                                          for v in t.backlash_preload_nm),
                transmission_given=True)


def description_digest(raw) -> str:
    """SHA-256 of a robot description's content (canonical JSON: key order and spacing do
    not matter): what a result records to say which robot it was made for."""
    text = json.dumps(raw, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode()).hexdigest()


def within_limits(robot: Robot, q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    q = np.asarray(q, float)
    return np.all((q >= robot.limits[:, 0] - tol) & (q <= robot.limits[:, 1] + tol), axis=-1)
