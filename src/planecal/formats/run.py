"""The sampling run's sidecar ``RUN.tsv.json`` (format ``planecal-run/1``), written by
``sampling.run.SamplingRun`` after every sample and read by ``--resume``.

The fields are listed in ``sampling/run.py``'s docstring and in docs/FORMATS.md. A resume
takes the scene, seed, target and every setting from here, and restores the random
generator from ``rng_state``: all of it is checked before the run starts, so a damaged
sidecar is refused with its field named instead of failing inside numpy or the loop.
"""
import math
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field

from planecal.formats.base import (
    M_AS_MM, Bool, Int, Interval, Model, Num, Positive, Ranged, Record, Str, problem, short)
from planecal.formats.poses import Counts

SIDECAR_FORMAT = "planecal-run/1"
STATUSES = ("running", "complete", "stopped", "gave_up", "error")
PLATE_CHOICES = ("round_robin", "random")  # plate per sample (sampling.poses)
IK_CHOICES = ("wrist", "nearest")  # IK solution per pose (sampling.poses)


def _is_sidecar(v):
    if v != SIDECAR_FORMAT:
        raise problem(f"{short(v)} is not a planecal run sidecar ({SIDECAR_FORMAT})")
    return v


def _one_of(choices: tuple[str, ...], what: str):
    def check(v):
        if v not in choices:
            raise problem(f"{short(v)} is not a {what} ({', '.join(choices)})")
        return v
    return Annotated[Str, AfterValidator(check), Field(json_schema_extra={"enum": list(choices)})]


Count = Ranged(0, None, "", "count", base=Int)
Distance = Ranged(1.0, 10000.0, "mm", "distance", M_AS_MM)
Distances = Interval("mm", "distance range", 1.0, 10000.0, M_AS_MM)
Cone = Ranged(0.0, 89.999, "deg", "beam cone half-angle")
Margin = Ranged(0.0, 1.0, "m", "plate margin")
Roll = Ranged(0.0, 180.0, "deg", "roll range")
PlateChoice = _one_of(PLATE_CHOICES, "plate choice")
IkChoice = _one_of(IK_CHOICES, "IK choice")
BufferLen = Ranged(1, 1_000_000, "readings", "buffer length", base=Int)
Spread = Ranged(0.0, 100.0, "mm", "spread limit")
OutOfRange = Ranged(0, 100_000_000, "readings", "out-of-range limit", base=Int)
MaxReads = Ranged(1, 100_000_000, "readings", "read limit", base=Int)
Dwell = Ranged(0, 100_000, "ticks", "dwell", base=Int)
NominalStep = Ranged(1, 1 << 20, "counts", "nominal step", base=Int)
Attempts = Ranged(1, 100_000_000, "poses", "attempt limit", base=Int)
Clearance = Ranged(0.0, 1.0, "m", "clearance")
U128 = Ranged(0, (1 << 128) - 1, "", "128-bit state word", base=Int)
Flag = Ranged(0, 1, "", "flag", base=Int)
U32 = Ranged(0, (1 << 32) - 1, "", "32-bit word", base=Int)
SidecarTag = Annotated[Str, AfterValidator(_is_sidecar),
                       Field(json_schema_extra={"enum": [SIDECAR_FORMAT]})]
Status = _one_of(STATUSES, "run status")
SceneName = Annotated[Str, Field(min_length=1)]
Target = Ranged(1, 10_000_000, "samples", "sample target", base=Int)
Seconds = Ranged(0.0, None, "s", "time")
Sessions = Ranged(1, None, "", "session count", base=Int)
PlateCount = Ranged(1, 100, "", "plate count", base=Int)
Minutes = Positive("min", "robot-time budget", 100_000.0)


class PoseSettings(Model):
    """sampling.poses.PoseSettings."""
    cone_deg: Cone
    distance_mm: Distances
    fixed_distance_mm: Distance | None = None
    margin_m: Margin
    roll_deg: Roll
    plate_choice: PlateChoice
    ik_choice: IkChoice = "nearest"  # runs recorded before the choice existed


class LaserSettings(Model):
    """sampling.laserread.LaserSettings."""
    buffer_len: BufferLen
    spread_mm: Spread
    max_out_of_range: OutOfRange
    max_reads: MaxReads


class RunSettings(Model):
    """sampling.run.RunSettings.to_dict()."""
    pose: PoseSettings
    laser: LaserSettings
    dwell_ticks: Dwell
    nominal_step_counts: NominalStep
    max_attempts: Attempts
    clearance_m: Clearance
    collision_checking: Bool
    decimal_comma: Bool = False
    robot_minutes: Minutes | None = None  # runs recorded before budgets had none


class PCG64Words(Model):
    state: U128
    inc: U128


class RngState(Model):
    """numpy's PCG64 ``bit_generator.state``."""
    bit_generator: Literal["PCG64"]
    state: PCG64Words
    has_uint32: Flag
    uinteger: U32


class Rejection(Record):
    sample: Count
    kind: Str
    reason: Str


Rejections = Annotated[list[Rejection], Field(max_length=10_000)]


class TwinInfo(Record):
    """Added by ``planecal rehearse``: the twin's noise ``seed`` and its world, a
    ``twin.world.WorldRef``'s record: the error profile (a name or a path; runs recorded
    before profiles existed were the ideal world), the truth's seed (runs recorded before
    it: ``seed``), ``exact`` (no random noise) and, for a run made in a truth file's world
    (``rehearse --truth``), that file and its SHA-256: the world travels with the run
    (``jobs.runs.Run.world``)."""
    seed: Count
    exact: Bool = False
    errors: Str = "ideal"
    truth_seed: Count | None = None
    truth_file: Str | None = None
    truth_sha256: Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")] | None = None


def _distance_or_range(v):
    if isinstance(v, list):
        if len(v) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                  for x in v):
            raise problem("must be [low, high] in mm or one distance")
        for i, x in enumerate(v):
            if not math.isfinite(x):
                raise problem(f"{x} is not a finite distance in mm", i)
        return v
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        if not math.isfinite(v):
            raise problem(f"{v} is not a finite distance in mm")
        return v
    raise problem(f"must be [low, high] in mm or one distance, got {type(v).__name__}")


DistanceOrRange = Annotated[Any, AfterValidator(_distance_or_range), Field(json_schema_extra={
    "anyOf": [{"type": "number"}, {"type": "array", "items": {"type": "number"},
                                   "minItems": 2, "maxItems": 2}]})]


class RouteBack(Record):
    """The way the robot came in to its last pose (``sampling.collect.Cursor.back``):
    the configurations it passed, nearest first, as counts, and the counts it leads back
    from; a resumed run takes it only if the robot is still there."""
    from_counts: Counts
    counts: Annotated[list[Counts], Field(min_length=1, max_length=64)]


Excess = Ranged(-1.0, 1.0, "m", "laser reading beyond the commanding model")


class AimNext(Record):
    """The aiming shifts the next plan takes (``sampling.aim.Shifts``)."""
    pooled_m: Excess
    plates_m: Annotated[list[Excess | None], Field(max_length=100)]


class AimState(Record):
    """``sampling.aim.Aim``: whether the laser has read out of range on enough poses in a
    row (and how many so far), the last readings' excess over the commanding model per
    plate, the next plan's shifts."""
    engaged: Bool
    streak: Count = 0
    excess_m: Annotated[list[Annotated[list[Excess], Field(max_length=64)]],
                        Field(max_length=100)]
    next: AimNext | None = None


class SidecarFile(Record):
    """``RUN.tsv.json``; keys added by later versions are kept."""
    format: SidecarTag
    status: Status = "running"
    stop_reason: Str | None = None
    scene: SceneName
    scene_path: Str | None = None
    robot: Str | None = None
    seed: Count
    samples_target: Target
    samples: Count = 0
    cone_deg: Num | None = None
    distance_mm: DistanceOrRange = None
    settings: RunSettings
    rejected: dict[Str, Count] = {}
    laser_give_ups: dict[Str, Count] = {}
    recent_rejections: Rejections = []
    ticks: Count = 0
    robot_time_s: Seconds = 0.0
    wall_time_s: Seconds = 0.0
    max_step_counts: Count = 0
    sessions: Sessions = 1
    rng_state: RngState | None = None
    route_back: RouteBack | None = None
    aim: AimState | None = None  # runs recorded before aiming have none
    sample_file: Str | None = None
    plates: PlateCount | None = None
    updated_utc: Str | None = None
    twin: TwinInfo | None = None
    real_cell: dict[Str, Any] | None = None
    poses: Str | None = None

