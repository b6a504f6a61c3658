"""A cell, ``scenes/<name>.json`` (format ``planecal-scene/1``): the robot's name, the
sensor's nominal pose on the flange and its laser window, the plates (each a plane
n~ . p = 1 and a rectangle on it), obstacles, home and calibration positions and the
sampling cone and distances.

Checked beside the types: n~ != 0 and not through the base origin, the plate's corner on
its plane, an in-plane x axis, lengths in metres of plausible size, the laser window
ordered and positive with the sampling distances inside it. With the robot in the
validation context (``RobotBounds``), also: home counts within the encoder's bits and
every plate within the robot's reach.
"""
import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import AfterValidator, Field, ValidationInfo, model_validator

from planecal.formats.base import (
    M_AS_MM, MM_AS_M, Angle, Bool, FormatTag, Int, Interval, Model, Num, Point,
    Positive, Ranged, Str, Vector, problem, short)
from planecal.formats.robot import N_JOINTS
from planecal.formats.shapes import AllowedPair

SCENE_FORMAT = "planecal-scene/1"
CELL_M = 20.0  # anything in a robot cell lies within 20 m of the base
MIN_PLANE_M = 0.01  # n~ describes no plane through (or within 1 cm of) the base origin
MAX_PLANE_M = 100.0
# corner_m is projected onto the plane n~ . p = 1: within 5 mm is the rounding of a
# measured corner (the projection moves it less than that, well inside the 25 mm the laser
# spot keeps from a plate's edges); further off, corner and n~ describe different plates
CORNER_OFF_PLANE_M = 0.005


def _n_tilde_ok(v):
    norm = math.hypot(*v)
    if norm == 0:
        raise problem("n~ = 0 describes no plane (n~ . p = 1 needs n~ != 0)")
    if not MIN_PLANE_M <= 1.0 / norm <= MAX_PLANE_M:
        raise problem(f"|n~| = {norm:g} 1/m puts the plane {1.0 / norm:g} m from the base "
                      f"origin (plausible: {MIN_PLANE_M:g} to {MAX_PLANE_M:g} m; n~ cannot "
                      f"describe a plane through the origin)")
    return v


NTilde = Annotated[Vector(Num, 3), AfterValidator(_n_tilde_ok),
                   Field(description="1/m: the plane n~ . p = 1 in the base frame, "
                                     "1/|n~| its distance from the origin")]


def _some_plate(v):
    if not v:
        raise problem("a scene needs at least one plate")
    return v


SensorOrigin = Point(1.0, "sensor origin")
LaserWindow = Interval("mm", "laser window", 1.0, 10000.0, M_AS_MM)
Corner = Point(CELL_M, "plate corner")
Direction = Vector(Ranged(-1e3, 1e3, "", "direction component"), 3)
PlateSize = Vector(Positive("m", "plate size", 10.0, MM_AS_M), 2, "numbers, x and y extent")
Thickness = Positive("m", "plate thickness", 1.0, MM_AS_M)
Face = Annotated[Int, Field(json_schema_extra={"enum": [1, -1]})]
Centre = Point(CELL_M, "obstacle centre")
BoxSize = Vector(Positive("m", "obstacle size", CELL_M, MM_AS_M), 3, "numbers, full extents")
Angles = Vector(Angle, 3)
JointCounts = Vector(Int, N_JOINTS, "counts, one per joint")
JointDegrees = Vector(Ranged(-1080.0, 1080.0, "deg", "joint angle"), N_JOINTS,
                      "angles, one per joint")
Cone = Ranged(0.0, 89.999, "deg", "beam cone half-angle")
Distances = Interval("mm", "sampling distance range", 1.0, 10000.0, M_AS_MM)
SceneTag = FormatTag(SCENE_FORMAT, what="scene")
Description = Annotated[str, Field(max_length=100_000)]
RobotName = Annotated[Str, Field(min_length=1)]
FloorZ = Ranged(-CELL_M, CELL_M, "m", "floor height", MM_AS_M)


@dataclass(frozen=True)
class RobotBounds:
    """What a scene is checked against from its robot (validation context ``robot``)."""
    name: str
    reach_m: float
    encoder_bits: int


class Sensor(Model):
    origin_m: SensorOrigin
    phi_y_rad: Angle
    phi_z_rad: Angle
    range_mm: LaserWindow = [65.0, 95.0]


class Plate(Model):
    name: Str | None = None
    n_tilde: NTilde
    corner_m: Corner
    x_axis: Direction = [1.0, 0.0, 0.0]
    size_m: PlateSize
    thickness_m: Thickness = 0.01
    face: Face = 1
    stand: Bool = True

    @model_validator(mode="after")
    def physical(self):
        if self.face not in (1, -1):
            raise problem(f"{self.face}: the measured face looks along +n~ (1) or -n~ (-1)",
                          "face")
        n = np.asarray(self.n_tilde)
        nhat = n / np.linalg.norm(n)
        off = (n @ np.asarray(self.corner_m) - 1.0) / np.linalg.norm(n)
        if abs(off) > CORNER_OFF_PLANE_M:
            who = f"plate {self.name!r}: " if self.name else ""
            raise problem(f"{who}the corner is {abs(off) * 1e3:.1f} mm off the plane n~ . p = 1 "
                          f"(at most {CORNER_OFF_PLANE_M * 1e3:g} mm): corner and n~ describe "
                          "different plates", "corner_m")
        x = np.asarray(self.x_axis)
        if not np.linalg.norm(x) > 1e-9:
            raise problem("x_axis = 0 gives no direction", "x_axis")
        if np.linalg.norm(x - (x @ nhat) * nhat) < 1e-3 * np.linalg.norm(x):
            raise problem("lies along the plate's normal: it gives no in-plane direction",
                          "x_axis")
        return self

    def nearest_distance_m(self) -> float:
        """A lower bound of the distance of any plate point from the base origin."""
        n = np.asarray(self.n_tilde)
        c = np.asarray(self.corner_m)
        c = c - (n @ c - 1.0) / (n @ n) * n
        return float(np.linalg.norm(c) - math.hypot(*self.size_m))


class Obstacle(Model):
    name: Str | None = None
    center_m: Centre
    size_m: BoxSize
    rpy_rad: Angles = [0.0, 0.0, 0.0]


RESERVED_TCP_NAMES = ("tool", "flange")  # the beam point and the flange: validate's own


class Tool(Model):
    """A TCP the scene names besides the laser's beam point (``planecal validate`` measures
    ISO 9283 AP there too): its position in the flange frame."""
    name: Annotated[Str, Field(min_length=1, max_length=100)]
    tcp_m: Annotated[Point(1.0, "TCP"),
                     Field(description="m: the TCP in the flange frame (standard DH frame 6)")]


def _tools_ok(v):
    names = [t.name for t in v]
    for i, n in enumerate(names):
        if n in RESERVED_TCP_NAMES:
            raise problem(f"{n!r} is validate's own name for the "
                          f"{'beam point' if n == 'tool' else 'flange'}: choose another",
                          i, "name")
        if n in names[:i]:
            raise problem(f"{n!r} is named twice", i, "name")
    return v


class Positions(Model):
    home_counts: JointCounts | None = None
    calibration_deg: JointDegrees | None = None


class Sampling(Model):
    cone_deg: Cone = 30.0
    distance_mm: Distances = [70.0, 90.0]


Separation = Ranged(-CELL_M, CELL_M, "m", "separation", MM_AS_M)
LengthStd = Ranged(1e-9, 0.01, "m", "length std", MM_AS_M)
ParallelStd = Ranged(1e-9, 0.01, "rad", "parallelism std")


class Reference(Model):
    """A known length (``model.scene.LengthReference``): plate ``plates[1]`` parallel to
    plate ``plates[0]`` (by name), ``separation_m`` further from the base origin along its
    normal (negative: nearer), measured with the std ``std_m``, the faces parallel within
    ``parallel_std_rad``."""
    kind: Annotated[Str, Field(json_schema_extra={"enum": ["parallel_plates"]})] = \
        "parallel_plates"
    plates: Vector(Str, 2, "plate names")
    separation_m: Separation
    std_m: LengthStd
    parallel_std_rad: ParallelStd = 1e-5
    source: Str | None = None

    def plate_indices(self, plates) -> list[int]:
        """0-based indices of the two plates among ``plates`` (anything with a ``name``)."""
        names = [p.name or f"plate{i + 1}" for i, p in enumerate(plates)]
        return [names.index(n) for n in self.plates]


class SceneFile(Model):
    """``scenes/<name>.json``."""
    format: SceneTag = None
    name: Str | None = None
    description: Description = ""
    robot: RobotName = "mc70"
    sensor: Sensor
    plates: Annotated[list[Plate], AfterValidator(_some_plate),
                      Field(max_length=100, json_schema_extra={"minItems": 1})]
    obstacles: Annotated[list[Obstacle], Field(max_length=10_000)] = []
    floor_z_m: FloorZ = 0.0
    tools: Annotated[list[Tool], AfterValidator(_tools_ok), Field(max_length=100)] = []
    positions: Positions = Positions()
    sampling: Sampling = Sampling()
    references: Annotated[list[Reference], Field(max_length=100)] = []
    # pairs of the tool's and the arm's pieces the collision checker does not check, each
    # with why (``scene new``: those its sampling finds touching whatever the joints do)
    allowed_pairs: Annotated[list[AllowedPair], Field(max_length=1000)] = []

    @model_validator(mode="after")
    def physical(self, info: ValidationInfo):
        lo, hi = self.sensor.range_mm
        a, b = self.sampling.distance_mm
        if not lo <= a < b <= hi:
            raise problem(f"[{a:g}, {b:g}] mm is not within the laser window "
                          f"[{lo:g}, {hi:g}] mm (sensor.range_mm)", "sampling", "distance_mm")
        for i, r in enumerate(self.references):
            self._check_reference(r, i)
        bounds = (info.context or {}).get("robot")
        if bounds is not None:
            self._check_robot(bounds)
        return self

    def _check_reference(self, r: "Reference", i: int) -> None:
        """The reference names two of the scene's plates (``model.scene.load_scene`` checks
        that their nominal planes are as parallel and as far apart as it says)."""
        names = [p.name or f"plate{k + 1}" for k, p in enumerate(self.plates)]
        for n in r.plates:
            if n not in names:
                raise problem(f"no plate named {short(n)} (the plates: {', '.join(names)})",
                              "references", i, "plates")
        if r.plates[0] == r.plates[1]:
            raise problem("a plate and itself are no length", "references", i, "plates")

    def _check_robot(self, robot: RobotBounds) -> None:
        top = 1 << robot.encoder_bits
        for j, c in enumerate(self.positions.home_counts or ()):
            if not 0 <= c < top:
                raise problem(f"{c} is outside {robot.name}'s {robot.encoder_bits}-bit encoder "
                              f"range 0..{top - 1}", "positions", "home_counts", j)
        tool = math.hypot(*self.sensor.origin_m) + self.sensor.range_mm[1] * 1e-3
        for i, plate in enumerate(self.plates):
            near = plate.nearest_distance_m()
            if near > robot.reach_m + tool:
                raise problem(f"the plate is at least {near:.3g} m from the base, beyond "
                              f"{robot.name}'s reach ({robot.reach_m:.3g} m flange + "
                              f"{tool:.3g} m sensor and beam)", "plates", i)

