"""Parameter files (``planecal-params/1``) and result files (``planecal-result/1``).

A parameter file holds the cell's parameters (cell.CellParams) in SI units::

    {"format": "planecal-params/1",
     "joint_offsets_rad": [6 numbers],
     "planes": [{"n_tilde": [x, y, z]}, ...],
     "sensor": {"origin_m": [x, y, z], "phi_y_rad": .., "phi_z_rad": ..}}

A result file is a parameter file plus the fit's report (std, residuals, identifiability)
and its provenance (inputs with their SHA-256, scene, robot, planecal version, date); it
can be read wherever a parameter file is (``--initial``, ``--truth``, ``--params``).
Files without ``format`` (written before it existed) are read as parameter files.
"""
import hashlib
import math
from collections.abc import Iterable
from datetime import datetime, timezone
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, Strict, ValidationError

from planecal.formats.base import (
    DEG_AS_RAD, Angle, Bool, FormatTag, Int, Model, Point, Ranged, Record, Str, Vector,
    error_line, problem)
from planecal.formats.scene import NTilde

PARAMS_FORMAT = "planecal-params/1"
RESULT_FORMAT = "planecal-result/1"
MAX_PLANES = 100

Offset = Ranged(-math.pi, math.pi, "rad", "joint offset", DEG_AS_RAD)
Offsets = Vector(Offset, 6, "offsets, one per joint")
SensorOrigin = Point(1.0, "sensor origin")
ParamsTag = FormatTag(PARAMS_FORMAT, RESULT_FORMAT, what="parameter file")
ResultTag = FormatTag(RESULT_FORMAT, what="result file")


def _some_plane(v):
    if not v:
        raise problem("needs at least one plane")
    return v


class Plane(Model):
    n_tilde: NTilde


class SensorParams(Model):
    origin_m: SensorOrigin
    phi_y_rad: Angle
    phi_z_rad: Angle


TwistErr = Ranged(-0.1, 0.1, "rad", "angle correction", DEG_AS_RAD)
LengthErr = Ranged(-0.1, 0.1, "m", "length correction")
Compliance = Ranged(-1e-3, 1e-3, "rad/(N m)", "joint compliance")


TwistCorrections = Vector(TwistErr, 6, "corrections, one per joint")
LengthCorrections = Vector(LengthErr, 6, "corrections, one per joint")
BaseCorrection = Vector(Ranged(-1.0, 1.0, "m or rad", "base frame error"), 6,
                        "values: x, y, z [m], rx, ry, rz [rad]")
Compliances = Vector(Compliance, 6, "values, one per joint")


class KinematicCorrections(Model):
    """Level 2 (issue 13, ``model.measurement``): corrections of robot.json's model per joint in
    modified DH (alpha, a, Hayati's beta, d), the base frame (x, y, z [m], rx, ry, rz
    [rad]: T(x,y,z) Rz Ry Rx) and the joint compliance c = 1/k (theta += c tau_gravity)."""
    alpha_rad: TwistCorrections
    a_m: LengthCorrections
    beta_rad: TwistCorrections
    d_m: LengthCorrections
    base: BaseCorrection
    compliance_rad_per_nm: Compliances = [0.0] * 6


GearAmplitude = Ranged(-0.01, 0.01, "rad", "gear harmonic amplitude")
JointNumber = Ranged(1, 6, "", "joint (1-based)", base=Int)
Cycles = Ranged(1, 1000, "", "cycles", base=Int)
Backlash = Ranged(-0.01, 0.01, "rad", "backlash")
LaserAmplitude = Ranged(-0.001, 0.001, "m", "laser linearity amplitude")
RangeEnd = Ranged(0.0, 10.0, "m", "measuring range end")


class GearHarmonic(Model):
    """theta_j += sin_rad sin(f q_j) + cos_rad cos(f q_j), f = cycles_per_rev."""
    joint: JointNumber
    cycles_per_rev: Cycles
    sin_rad: GearAmplitude
    cos_rad: GearAmplitude


class LaserHarmonic(Model):
    """reading += sin_m sin(2 pi k x) + cos_m cos(2 pi k x), x the reading's place in
    ``laser_range_m``, k = cycles_per_range."""
    cycles_per_range: Cycles
    sin_m: LaserAmplitude
    cos_m: LaserAmplitude


class NonKinematic(Model):
    """Level 3 (seed 5.4, ``model.measurement``): each joint's gear harmonics and backlash
    (full width; theta_j -= b_j/2 side_j), and the laser's linearity over its measuring
    range."""
    gear: Annotated[list[GearHarmonic], Field(max_length=48)] = []
    backlash_rad: Vector(Backlash, 6, "values, one per joint") = [0.0] * 6
    laser_linearity: Annotated[list[LaserHarmonic], Field(max_length=8)] = []
    laser_range_m: Vector(RangeEnd, 2, "ends, near and far") = [0.065, 0.095]


class ParamsFile(Record):
    """Unknown top-level keys are allowed: every result file is a parameter file."""
    format: ParamsTag = None
    joint_offsets_rad: Offsets
    planes: Annotated[list[Plane], AfterValidator(_some_plane),
                      Field(max_length=MAX_PLANES, json_schema_extra={"minItems": 1})]
    sensor: SensorParams
    kinematics: KinematicCorrections | None = None
    nonkinematic: NonKinematic | None = None


# ----- result files --------------------------------------------------------------------------

Std = Annotated[Ranged(0.0, None, "", "standard deviation") | None,
                Field(description="null where the parameter is not identifiable or fixed")]
NonNeg = Ranged(0.0, None, "", "non-negative quantity")
Count = Ranged(0, None, "", "count", base=Int)
Std3, Std6 = Vector(Std, 3), Vector(Std, 6)


class PlaneStd(Model):
    n_tilde: Std3


class SensorStd(Model):
    origin_m: Std3
    phi_y_rad: Std
    phi_z_rad: Std


class KinematicsStd(Model):
    alpha_rad: Std6
    a_m: Std6
    beta_rad: Std6
    d_m: Std6
    base: Std6
    compliance_rad_per_nm: Std6


class GearStd(Model):
    joint: JointNumber
    cycles_per_rev: Cycles
    sin_rad: Std
    cos_rad: Std


class LaserStd(Model):
    cycles_per_range: Cycles
    sin_m: Std
    cos_m: Std


class NonKinematicStd(Model):
    gear: list[GearStd] = []
    backlash_rad: Std6 = [None] * 6
    laser_linearity: list[LaserStd] = []


class StdBlock(Model):
    joint_offsets_rad: Std6
    planes: list[PlaneStd]
    sensor: SensorStd
    kinematics: KinematicsStd | None = None
    nonkinematic: NonKinematicStd | None = None


class InputFile(Model):
    role: Str
    path: Str
    sha256: Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]
    bytes: Count


class Provenance(Model):
    planecal_version: Str
    created_utc: Str
    inputs: list[InputFile]
    scene: Str | None = None
    robot: Str | None = None


class CovarianceBlock(Model):
    """The free parameters' covariance, by name (SI units; null where not identifiable)."""
    names: list[Str]
    matrix: list[list[Annotated[float, Strict(), Field(allow_inf_nan=False)] | None]]


class EncoderOffsetsBlock(Model):
    """What a controller can take: the joint offsets (null, with the reason, where none)."""
    joint_offsets_rad: Offsets | None
    calibrated: list[Str] = []
    kept_initial: list[Str] = []
    reason: Str | None = None


class IdentifiabilityBlock(Record):
    """The fit's identifiability report; the residual level a drift check reads is typed."""
    sigma_mm: NonNeg | None = None
    weighted: Bool = False
    variance_factor: NonNeg | None = None


class CalibrationBlock(Record):
    """The calibration's settings; its noise model is typed (a weighted result's check)."""
    joint_sigma_rad: NonNeg | None = None
    distance_sigma_m: NonNeg | None = None


STATUSES = ("converged", "not_identifiable", "max_iterations")


def _status(v):
    if v not in STATUSES:
        raise problem(f"{v!r} is not a fit status ({', '.join(STATUSES)})")
    return v


FitStatus = Annotated[Str, AfterValidator(_status), Field(
    description="converged: the fit converged and identified every free parameter; "
                "not_identifiable: it converged, but the samples cannot identify a free "
                "parameter; max_iterations: it did not converge",
    json_schema_extra={"enum": list(STATUSES)})]


Probability = Ranged(0.0, 1.0, "", "probability")


class ComparisonBlock(Record):
    """A simpler level judged beside the calibration (``estimation.verdict.Comparison``)."""
    level: Str
    tool_mm: NonNeg
    held_out_mm: NonNeg
    p_worse: Probability
    held_out_better: Bool
    p_worse_rms: Probability


class VerdictBlock(Record):
    """The calibration judged at the tool (``estimation.verdict``): its grade, its expected
    error and the 10-90 % band of AP near the samples, the simpler levels beside it and
    why it is worse than one (what export, urdf and compensate refuse)."""
    level: Str
    grade: Literal["good", "uncertain", "worse"]
    tool_mm: NonNeg
    band_mm: Annotated[list[NonNeg], Field(min_length=2, max_length=2)]
    held_out_mm: NonNeg
    fit_rms_mm: NonNeg
    comparisons: list[ComparisonBlock]
    worse_than: list[Str]
    reasons: list[Str]
    scale: dict[str, NonNeg]
    noise_factor: NonNeg
    where: Str


class ResultFile(ParamsFile):
    """What ``planecal calibrate --out`` writes."""
    format: ResultTag = None
    status: FitStatus | None = None
    std: StdBlock
    residual_rms_mm: NonNeg
    residual_rms_initial_mm: NonNeg
    residual_max_mm: NonNeg
    iterations: Count
    converged: Bool
    outliers: list[Count]
    samples_used: Count
    identifiability: IdentifiabilityBlock
    calibration: CalibrationBlock | None = None
    free: list[Str]
    provenance: Provenance | None = None
    model_error: Str | None = None
    covariance: CovarianceBlock | None = None
    encoder_offsets: EncoderOffsetsBlock | None = None
    verdict: VerdictBlock | None = None
    selection: dict[str, Any] | None = None  # the families chosen (estimation.selection)


def provenance(inputs: Iterable[tuple[str, str | Path]], scene: str | None = None,
               robot: str | None = None) -> dict:
    """A result's provenance: each input (role, path) with its size and SHA-256, the scene
    and robot names, planecal's version and the time (UTC)."""
    from planecal import __version__
    files = []
    for role, path in inputs:
        with open(path, "rb") as f:
            digest = hashlib.file_digest(f, "sha256")
            size = f.tell()
        files.append({"role": role, "path": str(path), "sha256": digest.hexdigest(),
                      "bytes": size})
    return {"planecal_version": __version__,
            "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "inputs": files, "scene": scene, "robot": robot}


def result_document(result: dict, prov: dict) -> dict:
    """The result file's content: ``format``, the fit's ``result`` (calibrate's
    ``result_dict``) and ``prov`` (``provenance(...)``), checked against ResultFile.
    A failure here is planecal's bug, not the user's: ValueError."""
    doc = {"format": RESULT_FORMAT, **result, "provenance": prov}
    try:
        ResultFile.model_validate(doc)
    except ValidationError as e:
        raise ValueError(error_line("result", e)) from None
    return doc
