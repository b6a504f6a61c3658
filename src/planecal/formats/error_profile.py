"""The twin's error profile, ``models/<robot>/errors/<name>.json`` or a user's copy (format
``planecal-errors/1``): how the twin's hidden truth and its world differ from the nominal
model. ``ideal`` is the world of the first twin (only the joint offsets, the sensor pose
and the plates drawn; no other error), ``realistic`` a robot of the MC70's class.

Sections (every magnitude carries a ``source`` string saying where it comes from):

* ``cell``: the truth's joint offsets (a uniform bound per joint), sensor pose and plates
  (a displacement within a ball, angles within bounds), as ``twin.truth.Tolerances``.
* ``geometry``: the true robot's kinematics (``planecal.model.kinematics``): per joint the std
  of a normal error of alpha, a, d and Hayati's beta (used where consecutive axes are
  parallel), and the base and flange frames (translation std [m], rotation std [rad] per
  axis).
* ``joints``: the errors the tick adds to each joint angle (``twin.ticks``):
  repeatability (mm at the flange, 3 sigma; null: robot.json's), encoder quantisation,
  backlash per joint [rad] and the gravity torque that holds a joint on one flank
  (``backlash_preload_nm``; null: the direction of motion decides), gear transmission
  error per joint (harmonics: amplitude [rad] and cycles per joint revolution; phases
  drawn with the truth), stiffness of the joints that yield to gravity [N m/rad] (null:
  rigid).
* ``payload``: the tool on the flange (sensor + adapter): mass and centre of mass in the
  flange frame, for the gravity torque.
* ``thermal``: growth of the links over a run (off unless ``enabled``).
* ``servo`` and ``laser``: the servo model; the laser's noise, quantum and linearity
  error (amplitude [mm], its phases drawn with the truth).
"""
from typing import Annotated

from pydantic import Field, model_validator

from planecal.formats.base import (
    MM_AS_M, Bool, FormatTag, Int, Model, Ranged, Str, Vector, problem)

ERRORS_FORMAT = "planecal-errors/1"
N_JOINTS = 6

ErrorsTag = FormatTag(ERRORS_FORMAT, what="error profile")
Name = Annotated[Str, Field(min_length=1)]
Source = Annotated[Str, Field(min_length=1, description="where the magnitudes come from")]
OffsetBound = Ranged(0.0, 0.1, "rad", "joint offset bound")
Offsets = Vector(OffsetBound, N_JOINTS, "bounds, one per joint")
LengthStd = Ranged(0.0, 0.05, "m", "length error std", MM_AS_M)
AngleStd = Ranged(0.0, 0.05, "rad", "angle error std")
Lengths = Vector(LengthStd, N_JOINTS, "stds, one per joint")
Angles = Vector(AngleStd, N_JOINTS, "stds, one per joint")
Ball = Ranged(0.0, 0.1, "m", "displacement bound", MM_AS_M)
SmallAngle = Ranged(0.0, 0.5, "rad", "angle bound")
Backlash = Ranged(0.0, 0.01, "rad", "backlash")
Amplitude = Ranged(0.0, 0.01, "rad", "gear error amplitude")
Cycles = Ranged(0.0, 10000.0, "cycles/rev", "gear error frequency")
Joint = Ranged(1, N_JOINTS, "", "joint number (1-based)", base=Int)
Stiffness = Ranged(1e3, 1e10, "N m/rad", "joint stiffness")
Repeatability = Ranged(0.0, 5.0, "mm", "repeatability")
Mass = Ranged(0.0, 500.0, "kg", "payload mass")
Offset = Ranged(-2.0, 2.0, "m", "payload offset", MM_AS_M)
Expansion = Ranged(0.0, 1e-4, "1/K", "thermal expansion")
Kelvin = Ranged(0.0, 100.0, "K", "temperature rise")
TimeConstant = Ranged(1.0, 1e6, "s", "time constant")
ServoMode = Annotated[Str, Field(json_schema_extra={"enum": ["ideal", "lag"]})]
Quantum = Ranged(0.0, 1.0, "mm", "laser quantum")
Backlashes = Vector(Backlash, N_JOINTS, "backlash, one per joint")
Stiffnesses = Vector(Stiffness | None, N_JOINTS, "stiffnesses (or null: rigid), one per joint")
Com = Vector(Offset, 3, "coordinates in the flange frame")
Preload = Ranged(0.0, 1e6, "N m", "preload torque")
Preloads = Vector(Preload | None, N_JOINTS, "preload torques (or null: none), one per joint")
Linearity = Ranged(0.0, 1.0, "mm", "laser linearity")
Tau = Ranged(1e-4, 10.0, "s", "servo time constant")
Noise = Ranged(0.0, 1.0, "mm", "laser noise")


class Cell(Model):
    joint_offsets_rad: Offsets
    sensor_origin_m: Ball
    sensor_angles_rad: SmallAngle
    plane_point_m: Ball
    plane_normal_rad: SmallAngle
    source: Source


class Frame(Model):
    translation_m: LengthStd
    rotation_rad: AngleStd


class Geometry(Model):
    alpha_rad: Angles
    a_m: Lengths
    d_m: Lengths
    beta_rad: Angles
    base: Frame
    flange: Frame
    source: Source


class Harmonic(Model):
    joint: Joint
    amplitude_rad: Amplitude
    cycles_per_rev: Cycles


class Joints(Model):
    repeatability_mm: Repeatability | None = None
    quantization: Bool = False
    backlash_rad: Backlashes
    backlash_preload_nm: Preloads | None = None
    gear: list[Harmonic] = []
    stiffness_nm_per_rad: Stiffnesses
    source: Source

    @model_validator(mode="after")
    def at_most_four_harmonics(self):
        for j in range(1, N_JOINTS + 1):
            if sum(h.joint == j for h in self.gear) > 4:
                raise problem(f"joint {j} has more than 4 harmonics (the twin's tick holds 4)",
                              "gear")
        return self


class Payload(Model):
    mass_kg: Mass
    com_m: Com
    source: Source


class Thermal(Model):
    enabled: Bool = False
    expansion_per_k: Expansion
    rise_k: Kelvin
    time_constant_s: TimeConstant
    source: Source


class Servo(Model):
    mode: ServoMode
    tau_s: Tau

    @model_validator(mode="after")
    def known_mode(self):
        if self.mode not in ("ideal", "lag"):
            raise problem(f"{self.mode!r} is not a servo mode (ideal, lag)", "mode")
        return self


class Laser(Model):
    noise_mm: Noise
    quantum_mm: Quantum | None = None
    linearity_mm: Linearity = 0.0
    source: Source | None = None


class ErrorProfileFile(Model):
    format: ErrorsTag
    name: Name
    description: Str = ""
    cell: Cell
    geometry: Geometry | None = None
    joints: Joints
    payload: Payload | None = None
    thermal: Thermal | None = None
    servo: Servo
    laser: Laser
