"""Planned pose lists, ``planecal plan --out POSES.json`` (format ``planecal-poses/1``).

The sampling run reads ``counts`` (encoder counts, one row of 6 per pose, in the order to
visit; a pose read several times is listed once per reading), ``plates`` (0-based plate
index of each pose) and, where the plan chose them, ``approach`` (the side each reading
approaches its pose from: 1, -1, or 0 for straight in); the rest is the plan's report
(prediction of the offsets' std, D-efficiency gain, the random baseline) and is kept as
written. The format field is required: a pose list is never hand-written.
"""
from typing import Annotated, Any

from pydantic import AfterValidator, Field, model_validator

from planecal.formats.base import Int, Ranged, Record, Str, Vector, problem, short
from planecal.formats.robot import N_JOINTS

POSES_FORMAT = "planecal-poses/1"
MAX_POSES = 100_000
COUNT_BITS = 24  # the sample files' (and FD11's) encoder range


def _is_poses(v):
    if v != POSES_FORMAT:
        raise problem(f"{short(v)} is not a planecal pose list ({POSES_FORMAT})")
    return v


Counts = Vector(Ranged(0, (1 << COUNT_BITS) - 1, "", f"{COUNT_BITS}-bit encoder count",
                       base=Int), N_JOINTS, "counts, one per joint")


PosesTag = Annotated[Str, AfterValidator(_is_poses), Field(json_schema_extra={
    "enum": [POSES_FORMAT]})]
PlateIndex = Ranged(0, 99, "", "plate index (0-based)", base=Int)
CountRows = Annotated[list[Counts], Field(min_length=1, max_length=MAX_POSES)]
PlateIndices = Annotated[list[PlateIndex], Field(max_length=MAX_POSES)]
Side = Ranged(-1, 1, "", "approach side (1, -1; 0: straight in)", base=Int)
Sides = Annotated[list[Side], Field(max_length=MAX_POSES)]


class PosesFile(Record):
    format: PosesTag
    counts: CountRows
    plates: PlateIndices
    approach: Sides | None = None
    scene: Str | None = None
    seed: Int | None = None
    samples: Int | None = None
    candidates: Int | None = None
    free: list[Str] | None = None
    predicted_std_planned: dict[Str, Any] | None = None

    @model_validator(mode="after")
    def one_plate_per_pose(self):
        if len(self.plates) != len(self.counts):
            raise problem(f"{len(self.plates)} plate numbers for {len(self.counts)} poses "
                          f"(counts)", "plates")
        if self.approach is not None and len(self.approach) != len(self.counts):
            raise problem(f"{len(self.approach)} approach sides for {len(self.counts)} poses "
                          f"(counts)", "approach")
        return self
