"""The robot description, ``models/<robot>/robot.json`` (format ``planecal-robot/1``).

Six joints (planecal's parameter vector, sample files and IK are built for six). The chain
is given one of two ways: ``dh``, standard DH rows (the MC70's and the UR5's tables), or
``chain``, the model's own form (``planecal.model.kinematics``: modified DH with Hayati's
beta per joint, a base and a flange frame), which ``planecal robot import`` writes from a
URDF. Also: joint limits in degrees, the encoder model ``q = C x, x = (qe - qe0) / g``,
the controller's step limits, home counts and (when known) what it does with its reference
between client sessions (``controller.sessions``, `planecal.links.sessions`), and the
link masses. Checked: every number finite, lengths and angles of plausible size, non-zero
gains, coupling entries on existing joints and a non-singular C, counts within the
encoder's bits, the trip limit above the step limit, exactly one of ``dh`` and ``chain``.
The link shapes are not here but beside it (``shapes.json``, ``formats.shapes``): no
number of a calibration depends on them, so a result's record of the description
(``model.robot.description_digest``) does not either.
"""

import math
from typing import Annotated

import numpy as np
from pydantic import AfterValidator, Field, model_validator

from planecal.formats.base import (
    MM_AS_M, Angle, FormatTag, Int, Model, Num, Ranged, Str, Vector, problem, short)

ROBOT_FORMAT = "planecal-robot/1"
N_JOINTS = 6
MAX_LINK_M = 5.0  # the largest industrial arms reach ~4 m in all


# the field types (aliases: a call inside an annotation reads badly to linters)
LinkD = Ranged(-MAX_LINK_M, MAX_LINK_M, "m", "link offset d", MM_AS_M)
LinkA = Ranged(-MAX_LINK_M, MAX_LINK_M, "m", "link length a", MM_AS_M)
Degrees = Ranged(-1080.0, 1080.0, "deg", "joint limit")
Limits = Vector(Vector(Degrees, 2, "numbers, [lower, upper]"), N_JOINTS,
                "[lower, upper] pairs, one per joint")
Joint = Ranged(1, N_JOINTS, "", "joint number (1-based)", base=Int)
CouplingValue = Ranged(-10.0, 10.0, "", "coupling coefficient")  # the MC70's are ~0.017
CouplingEntry = Annotated[tuple[Joint, Joint, CouplingValue], Field(
    description="[row, col, value], 1-based: C[row, col] = value")]
Gains = Vector(Num, N_JOINTS, "gains, one per joint")
JointCounts = Vector(Int, N_JOINTS, "counts, one per joint")
Bits = Ranged(8, 32, "bits", "encoder width", base=Int)
Tick = Ranged(1e-4, 1.0, "s", "control tick")
StepLimit = Ranged(1, 1 << 20, "counts", "step limit", base=Int)
TripLimit = Ranged(1, 1 << 20, "counts", "trip limit", base=Int)
RobotTag = FormatTag(ROBOT_FORMAT, what="robot description")
Repeatability = Ranged(0.0, 5.0, "mm", "repeatability")
Name = Annotated[Str, Field(min_length=1)]
Frame = Ranged(1, N_JOINTS, "", "link frame (1-based)", base=Int)
LinkMass = Ranged(0.0, 10000.0, "kg", "link mass")
Com = Vector(Ranged(-MAX_LINK_M, MAX_LINK_M, "m", "centre of mass coordinate", MM_AS_M), 3,
             "coordinates in the frame")
SOLVERS = ("spherical_wrist", "analytic", "numeric")  # planecal.model.ik; null: chosen
Solver = Annotated[Str | None, Field(json_schema_extra={"enum": [*SOLVERS, None]})]
CONTROLLERS = ("fd11", "ur")  # what the export formats know (commands.export)
ControllerKind = Annotated[Str | None, Field(json_schema_extra={"enum": [*CONTROLLERS, None]})]
JointName = Annotated[Str, Field(min_length=1, max_length=200)]
Payload = Ranged(0.0, 10000.0, "kg", "rated payload")
Inertia = Vector(Ranged(-1e4, 1e4, "kg m^2", "inertia"), 6, "numbers, ixx iyy izz ixy ixz iyz")
FramePoint = Vector(Ranged(-MAX_LINK_M, MAX_LINK_M, "m", "frame origin coordinate", MM_AS_M), 3,
                    "coordinates, x y z")
REFERENCE_BEHAVIOURS = ("keep", "fresh_after_silence", "fresh_each_client")  # links.sessions
SilenceS = Ranged(0.01, 3600.0, "s", "silence")


def _behaviour(v):
    if v not in REFERENCE_BEHAVIOURS:
        raise problem(f"{short(v)} is not a reference behaviour "
                      f"({', '.join(REFERENCE_BEHAVIOURS)})")
    return v


Behaviour = Annotated[Str, AfterValidator(_behaviour),
                      Field(json_schema_extra={"enum": list(REFERENCE_BEHAVIOURS)})]


class DHRow(Model):
    """One standard DH row: T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)."""
    theta0_rad: Angle
    d_m: LinkD
    a_m: LinkA
    alpha_rad: Angle


DHRows = Vector(DHRow, N_JOINTS, "rows, one per joint")


class Encoder(Model):
    gain_counts_per_rad: Gains
    offset_counts: JointCounts
    bits: Bits = 24
    coupling: list[CouplingEntry] = []
    coupling_note: Str | None = None

    @model_validator(mode="after")
    def physical(self):
        for j, g in enumerate(self.gain_counts_per_rad):
            if not abs(g) >= 1.0:
                raise problem(f"{g:g} counts/rad: an encoder gain must be non-zero (its sign "
                              f"is the direction), at least 1 count/rad", "gain_counts_per_rad", j)
        for j, c in enumerate(self.offset_counts):
            if not 0 <= c < 1 << self.bits:
                raise problem(f"{c} is outside the {self.bits}-bit encoder range "
                              f"0..{(1 << self.bits) - 1}", "offset_counts", j)
        C = self.coupling_matrix()
        det, cond = float(np.linalg.det(C)), float(np.linalg.cond(C))
        if not abs(det) > 1e-9:
            raise problem(f"the coupling matrix C is singular (det {det:.3g}): joint angles "
                          f"q = C x cannot be turned back into counts", "coupling")
        if not cond < 1e9:
            raise problem(f"the coupling matrix C is ill-conditioned (condition number "
                          f"{cond:.3g}): counts from joint angles would be noise", "coupling")
        return self

    def coupling_matrix(self) -> np.ndarray:
        C = np.eye(N_JOINTS)
        for row, col, value in self.coupling:
            C[row - 1, col - 1] = value
        return C


class Sessions(Model):
    """What the controller does with its reference between client sessions
    (`planecal.links.sessions`): ``keep`` it; take a fresh one (the robot's counts) at a
    request after ``silence_s`` without any (``fresh_after_silence``); or at a request from
    another client address (``fresh_each_client``). ``source``: how it is known."""
    reference: Behaviour
    silence_s: SilenceS | None = None
    source: Str | None = None

    @model_validator(mode="after")
    def silence_with_its_behaviour(self):
        if self.reference == "fresh_after_silence" and self.silence_s is None:
            raise problem("fresh_after_silence needs silence_s, the silence (s) after which "
                          "the controller takes a new reference", "silence_s")
        if self.reference != "fresh_after_silence" and self.silence_s is not None:
            raise problem(f"silence_s goes only with fresh_after_silence, not with "
                          f"{self.reference}", "silence_s")
        return self


class Controller(Model):
    kind: ControllerKind = None  # what export formats apply (commands.export)
    tick_s: Tick
    max_step_counts: StepLimit
    trip_step_counts: TripLimit
    home_counts: JointCounts
    sessions: Sessions | None = None  # unknown: a session that cannot tell asks

    @model_validator(mode="after")
    def trip_above_step(self):
        if self.trip_step_counts < self.max_step_counts:
            raise problem(f"{self.trip_step_counts} counts is below the step limit "
                          f"max_step_counts = {self.max_step_counts}: every step would trip",
                          "trip_step_counts")
        return self


class PointMass(Model):
    """A mass of the arm, lumped at its centre of mass in link frame ``frame`` (the link it
    moves with: ``kinematics.link_frames``, the standard DH frame for a ``dh`` table): for
    the gravity torque on the joints. ``inertia_kg_m2`` (about the centre of mass, the link
    frame's axes), where known, goes into the twin's bodies."""
    frame: Frame
    com_m: Com
    mass_kg: LinkMass
    inertia_kg_m2: Inertia | None = None
    what: Str | None = None


class ChainJoint(Model):
    """One joint of the model's chain: Rx(alpha) Tx(a) Ry(beta) Rz(theta0 + q) Tz(d)."""
    alpha_rad: Angle
    a_m: LinkA
    beta_rad: Angle = 0.0
    theta0_rad: Angle
    d_m: LinkD


class FixedFrame(Model):
    """A fixed frame: translation xyz, then rotation R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's)."""
    xyz_m: FramePoint = [0.0, 0.0, 0.0]
    rpy_rad: Vector(Angle, 3, "angles, roll pitch yaw") = [0.0, 0.0, 0.0]

    def matrix(self) -> np.ndarray:
        r, p, y = self.rpy_rad
        cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                                  math.cos(y), math.sin(y))
        T = np.eye(4)
        T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]]
        T[:3, 3] = self.xyz_m
        return T


ChainJoints = Vector(ChainJoint, N_JOINTS, "joints, one per joint")


class Chain(Model):
    """The model's chain (``planecal.model.kinematics``):
    T_flange(q) = B prod_i [Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta0_i + q_i) Tz(d_i)] F."""
    convention: Str | None = None
    joints: ChainJoints
    base: FixedFrame = FixedFrame()
    flange: FixedFrame = FixedFrame()


Order = Ranged(1, 1000, "cycles per revolution", "gear harmonic order", base=Int)
Preload = Ranged(0.0, 1e6, "N m", "backlash preload torque")
DEFAULT_HARMONICS = (1, 2)  # cycles per output revolution, a robot that gives none


class Transmission(Model):
    """What level 3 (``--level nonkinematic``) models of each joint's reducer:
    ``harmonics_cycles_per_rev``, the periods of its transmission error per output
    revolution (an RV reducer's 1 and its pin count, a harmonic drive's 1 and 2), and
    ``backlash_preload_nm``: the gravity torque above which the joint rests on the flank
    gravity pushes it to, whichever way it came (null: never; the flank is the one its last
    motion left it on, a sample file's direction columns)."""
    harmonics_cycles_per_rev: Vector(Annotated[list[Order], Field(max_length=8)], N_JOINTS,
                                     "lists, one per joint")
    backlash_preload_nm: Vector(Preload | None, N_JOINTS, "torques, one per joint") = \
        [None] * N_JOINTS
    source: Str | None = None

    @model_validator(mode="after")
    def distinct(self):
        for j, fs in enumerate(self.harmonics_cycles_per_rev):
            if len(set(fs)) != len(fs):
                raise problem(f"{fs}: an order given twice", "harmonics_cycles_per_rev", j)
        return self


class RobotFile(Model):
    """``models/<robot>/robot.json``."""
    format: RobotTag = None
    name: Name
    source: Str | None = None
    dh_convention: Str | None = None
    dh: DHRows | None = None
    chain: Chain | None = None
    joint_names: Vector(JointName, N_JOINTS, "names, one per joint") | None = None
    joint_limits_deg: Limits
    encoder: Encoder
    inverse_kinematics: Solver = None
    repeatability_mm: Repeatability | None = None  # None: not given (model.robot's default)
    payload_kg: Payload | None = None
    controller: Controller
    masses: list[PointMass] = []
    masses_source: Str | None = None
    transmission: Transmission | None = None  # None: DEFAULT_HARMONICS, no preload

    @model_validator(mode="after")
    def physical(self):
        if (self.dh is None) == (self.chain is None):
            raise problem("give the chain one way: either dh (standard DH rows) or chain "
                          "(modified DH with Hayati's beta, base and flange), not "
                          + ("both" if self.dh is not None else "neither"), "dh")
        if self.inverse_kinematics not in (None, *SOLVERS):
            raise problem(f"{short(self.inverse_kinematics)} is not a known solver "
                          f"({', '.join(map(repr, SOLVERS))} or null: chosen from the "
                          "geometry)", "inverse_kinematics")
        if self.controller.kind not in (None, *CONTROLLERS):
            raise problem(f"{short(self.controller.kind)} is not a known controller "
                          f"({', '.join(map(repr, CONTROLLERS))} or null)", "controller", "kind")
        if self.joint_names is not None and len(set(self.joint_names)) != N_JOINTS:
            raise problem("two joints have the same name", "joint_names")
        for j, (lo, hi) in enumerate(self.joint_limits_deg):
            if not lo < hi:
                raise problem(f"[{lo:g}, {hi:g}] deg: the lower limit must be below the upper",
                              "joint_limits_deg", j)
        top = 1 << self.encoder.bits
        for j, c in enumerate(self.controller.home_counts):
            if not 0 <= c < top:
                raise problem(f"{c} is outside the {self.encoder.bits}-bit encoder range "
                              f"0..{top - 1}", "controller", "home_counts", j)
        if self.reach_m() < 0.05:
            raise problem(f"the link lengths add up to a reach of {self.reach_m():g} m: not "
                          f"an arm (lengths in km?)", "dh" if self.dh is not None else "chain")
        return self

    def reach_m(self) -> float:
        if self.dh is not None:
            return reach_m([r.d_m for r in self.dh], [r.a_m for r in self.dh])
        j = self.chain.joints
        return reach_m([r.d_m for r in j], [r.a_m for r in j[1:]] + [0.0]) \
            + math.hypot(*self.chain.flange.xyz_m) + abs(j[0].a_m)


def reach_m(d, a) -> float:
    """Largest distance of the flange from the base origin: each DH link moves the origin
    by a u + d z with u perpendicular to z, so by sqrt(a^2 + d^2)."""
    return float(sum(math.hypot(x, y) for x, y in zip(d, a)))

