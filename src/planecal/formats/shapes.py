"""A robot's link shapes, ``models/<robot>/shapes.json`` (format ``planecal-shapes/1``),
beside its robot.json: what the twin, the collision checker, Rerun and the URDF export
draw (``planecal.model.geometry``). No number of a calibration depends on them, so they
are not part of the description a result records (``model.robot.description_digest``).

A piece is the convex hull of its primitives, in its link's frame (``link`` 0 = the base,
j = the link joint j turns, 6 = the flange; ``kinematics.link_frames``: the standard DH
frames for a DH table):

* ``cylinder``: ``from_m`` -> ``to_m``, ``radius_m``;
* ``box``: ``center_m``, ``size_m`` (full extents), ``rpy_rad`` (R = Rz Ry Rx);
* ``sphere``: ``center_m``, ``radius_m``;
* ``mesh``: ``file``, a binary STL beside shapes.json (vertices in metres, in the link's
  frame; ``planecal robot import`` writes them so).

``allowed_pairs``: pairs of pieces the collision checker does not check, each with why
(its own ``allowed_pairs`` adds to them): where the robot's structure keeps two pieces
apart at every angle though their hulls pass within the clearance (a UR's nested wrist
joints).

``unchecked``: why the arm has no collision pieces (a URDF without <collision> or
<visual> elements, ``planecal robot import``): the checker then sees only the tool and the
cell, never the arm's links; ``pieces`` may then be empty, and ``planecal robot show`` and
``scene new`` say so.

``use``: ``both`` (default; the MC70's): the visual shape is the pieces' polygons and the
collision shape the same grown by the margin; ``visual`` or ``collision``: that one only
(a URDF's <visual> and <collision> elements). A visual piece of one mesh is drawn as the
mesh itself (it may be concave); every other shape is a convex hull, and every collision
shape is grown by ``collision_margin_m`` (default ``geometry.COLLISION_MARGIN``).
"""
from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from planecal.formats.base import (MM_AS_M, Angle, FormatTag, Int, Model, Ranged, Str, Vector,
                                   problem)

SHAPES_FORMAT = "planecal-shapes/1"
USES = ("both", "visual", "collision")
MAX_SHAPE_M = 5.0  # a link shape reaches at most this far from its frame

Coord = Ranged(-MAX_SHAPE_M, MAX_SHAPE_M, "m", "shape coordinate", MM_AS_M)
Point = Vector(Coord, 3, "coordinates, x y z")
Radius = Ranged(1e-4, MAX_SHAPE_M, "m", "radius", MM_AS_M)
Size = Vector(Ranged(1e-4, 2 * MAX_SHAPE_M, "m", "box size", MM_AS_M), 3, "numbers, x y z extent")
Link = Ranged(0, 6, "", "link (0 = base, 6 = flange)", base=Int)
Name = Annotated[Str, Field(min_length=1, max_length=200)]
Use = Annotated[Str, Field(json_schema_extra={"enum": list(USES)})]
Margin = Ranged(0.0, 0.1, "m", "collision margin", MM_AS_M)
ShapesTag = FormatTag(SHAPES_FORMAT, what="robot shapes")


class Cylinder(Model):
    from_m: Point
    to_m: Point
    radius_m: Radius

    @model_validator(mode="after")
    def has_length(self):
        if sum((a - b) ** 2 for a, b in zip(self.from_m, self.to_m)) < 1e-12:
            raise problem("from_m and to_m are the same point: a cylinder needs a length",
                          "to_m")
        return self


class Box(Model):
    center_m: Point
    size_m: Size
    rpy_rad: Vector(Angle, 3, "angles, roll pitch yaw") = [0.0, 0.0, 0.0]


class Sphere(Model):
    center_m: Point
    radius_m: Radius


class MeshFile(Model):
    file: Annotated[Str, Field(min_length=1)]

    @model_validator(mode="after")
    def inside_the_folder(self):
        parts = self.file.replace("\\", "/").split("/")
        if self.file.startswith("/") or ".." in parts:
            raise problem(f"{self.file!r}: give a path inside the robot's folder (relative, "
                          "no '..')", "file")
        if not self.file.lower().endswith(".stl"):
            raise problem(f"{self.file!r}: a mesh is a binary STL file (.stl)", "file")
        return self


class Primitive(Model):
    """Exactly one of cylinder, box, sphere, mesh."""
    cylinder: Cylinder | None = None
    box: Box | None = None
    sphere: Sphere | None = None
    mesh: MeshFile | None = None

    @model_validator(mode="after")
    def one_kind(self):
        given = [k for k in ("cylinder", "box", "sphere", "mesh") if getattr(self, k) is not None]
        if len(given) != 1:
            raise problem("give exactly one of cylinder, box, sphere, mesh"
                          + (f" (got {', '.join(given)})" if given else ""))
        return self


class Piece(Model):
    name: Name
    link: Link
    use: Use = "both"
    primitives: Annotated[list[Primitive], Field(min_length=1, max_length=1000)]
    what: Str | None = None

    @model_validator(mode="after")
    def known_use(self):
        if self.use not in USES:
            raise problem(f"{self.use!r} is not a use ({', '.join(USES)})", "use")
        return self


class AllowedPair(Model):
    pieces: Vector(Name, 2, "piece names")
    why: Annotated[Str, Field(min_length=1)]


class ShapesFile(Model):
    """``models/<robot>/shapes.json``."""
    format: ShapesTag = None
    source: Str | None = None
    collision_margin_m: Margin | None = None
    pieces: Annotated[list[Piece], Field(max_length=10_000)]
    allowed_pairs: list[AllowedPair] = []
    unchecked: Str | None = None

    @model_validator(mode="after")
    def unique_names(self):
        if not self.pieces and not self.unchecked:
            raise problem("no pieces: give at least one, or say in 'unchecked' why the arm "
                          "has none", "pieces")
        seen = set()
        for i, p in enumerate(self.pieces):
            if p.name in seen:
                raise problem(f"{p.name!r}: another piece has this name", "pieces", i, "name")
            seen.add(p.name)
        for i, pair in enumerate(self.allowed_pairs):
            for k, name in enumerate(pair.pieces):
                if name not in seen:
                    raise problem(f"{name!r} is no piece of this file", "allowed_pairs", i,
                                  "pieces", k)
        return self
