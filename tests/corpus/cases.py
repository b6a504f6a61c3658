"""The malformed-input corpus (issue 16): one manifest entry per case.

A case is ``Case(name, argv, files, code, fragment)``:
* ``argv``: the command line after ``planecal``; ``{d}`` is the case's own directory
  (a fresh temporary copy), ``{base}`` tests/corpus/base (valid files, never written);
* ``files``: name -> content, built into ``{d}`` in order before the run (see ``build``
  in tests/test_corpus.py): ``Text(...)``, ``Tmpl(...)`` (with ``{d}`` filled in),
  ``Raw(bytes)``, ``Json(value)``, ``Mut(base, set=..., drop=..., raw=...)`` (a valid
  base file with fields replaced, deleted or given a raw JSON literal such as ``NaN``),
  ``Nest(depth)``, ``Bytes(n)``, ``Dir()``, ``Rows(...)``, ``Link(target, hard=False)``
  (a symbolic or a hard link);
* ``code``: the expected exit status (2 bad input or usage, 1 a fit that failed, 0 valid);
* ``fragment``: text the one stderr line must hold (it names the file or field, and the
  problem); ``None`` for a valid case (exit 0).
``pipe``: run through a shell pipe (``| head -1``) in a subprocess; ``rss``: run in a
subprocess and check its peak RSS.

Base files (tests/corpus/base): ``robot.json`` (models/mc70), ``scene.json``
(thesis_final), ``params.json`` (the seed's Table 10 values), ``poses.json``, ``run.tsv``
+ ``run.tsv.json`` (a 120-sample twin rehearsal on thesis_final, seed 3, realistic errors,
and its sidecar), ``run3.tsv`` (30 samples on three_plates), ``errors.json`` (the
realistic error profile), ``result.json`` (``calibrate run.tsv`` in this folder: its
provenance records ``run.tsv`` beside it).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Text:
    text: str


@dataclass(frozen=True)
class Json:
    value: Any


@dataclass(frozen=True)
class Mut:
    """A base file (JSON) with ``set`` (path -> value), ``drop`` (paths) and ``raw`` (path ->
    a JSON literal written as is: NaN, Infinity, 1e999, a 400-digit integer)."""
    base: str
    set: tuple = ()
    drop: tuple = ()
    raw: tuple = ()


@dataclass(frozen=True)
class Nest:
    depth: int


@dataclass(frozen=True)
class Bytes:
    n: int
    seed: int = 0


@dataclass(frozen=True)
class Dir:
    pass


@dataclass(frozen=True)
class Rows:
    """A sample file from the base ``run.tsv`` (or ``run3.tsv``): ``edit`` (row index ->
    the row's new text, tab-separated fields), ``repeat`` (the first row n times), ``comma``
    (decimal comma)."""
    base: str = "run.tsv"
    edit: tuple = ()
    repeat: int = 0
    comma: bool = False
    drop_plate: tuple = ()  # rows (0-based) whose plate column is removed
    head: int = 0  # keep the first n rows only


@dataclass(frozen=True)
class Tmpl:
    """Text with ``{d}`` (the case's directory) and ``{base}`` filled in (a config naming
    a path)."""
    text: str


@dataclass(frozen=True)
class Link:
    """A symbolic link to ``target`` (``{d}``, ``{base}`` filled in), or with ``hard`` a
    hard link (its target built before it)."""
    target: str
    hard: bool = False


@dataclass(frozen=True)
class Raw:
    """These bytes (a UTF-16 file)."""
    data: bytes


@dataclass(frozen=True)
class Case:
    name: str
    argv: tuple
    files: dict = field(default_factory=dict)
    code: int = 2
    fragment: str | None = None
    pipe: str | None = None
    rss: bool = False


def A(text: str) -> tuple:
    return tuple(text.split())


CASES: list[Case] = []


def case(name, argv, files=None, code=2, fragment=None, **kw):
    CASES.append(Case(name, A(argv) if isinstance(argv, str) else tuple(argv),
                      files or {}, code, fragment, **kw))


RUN = "{base}/run.tsv"
PARAMS = "{base}/params.json"

# ----- robot.json (through predict --robot) ---------------------------------------------------
PRED = f"predict {RUN} --params {PARAMS} --robot {{d}}/robot.json"
ROBOT_BAD = [
    ("robot-dh-5-rows", dict(drop=(("dh", 5),)), "dh"),
    ("robot-dh-not-array", dict(set=((("dh",), "six rows"),)), "dh"),
    ("robot-dh-object-row-array", dict(set=((("dh", 0), [0, 0.6, 0.15, 1.57]),)), "dh[0]"),
    ("robot-dh-missing-d", dict(drop=(("dh", 2, "d_m"),)), "dh[2].d_m"),
    ("robot-dh-string-length", dict(set=((("dh", 1, "a_m"), "0.9"),)), "dh[1].a_m"),
    ("robot-dh-nan-length", dict(raw=((("dh", 1, "a_m"), "NaN"),)), "dh[1].a_m"),
    ("robot-dh-inf-length", dict(raw=((("dh", 3, "d_m"), "Infinity"),)), "dh[3].d_m"),
    ("robot-dh-length-in-mm", dict(set=((("dh", 1, "a_m"), 900.0),)), "dh[1].a_m"),
    ("robot-dh-huge-int", dict(raw=((("dh", 0, "d_m"), "1" + "0" * 400),)), "dh[0].d_m"),
    ("robot-dh-1e308", dict(set=((("dh", 0, "d_m"), 1e308),)), "dh[0].d_m"),
    ("robot-dh-angle-in-deg", dict(set=((("dh", 0, "alpha_rad"), 90.0),)), "dh[0].alpha_rad"),
    ("robot-dh-bool-length", dict(set=((("dh", 0, "d_m"), True),)), "dh[0].d_m"),
    ("robot-gain-zero", dict(set=((("encoder", "gain_counts_per_rad", 2), 0.0),)),
     "encoder.gain_counts_per_rad"),
    ("robot-gain-nan", dict(raw=((("encoder", "gain_counts_per_rad", 0), "NaN"),)),
     "encoder.gain_counts_per_rad[0]"),
    ("robot-gain-5-values", dict(drop=(("encoder", "gain_counts_per_rad", 5),)),
     "encoder.gain_counts_per_rad"),
    ("robot-gain-string", dict(set=((("encoder", "gain_counts_per_rad"), "42744"),)),
     "encoder.gain_counts_per_rad"),
    ("robot-offset-float", dict(set=((("encoder", "offset_counts", 0), 8388608.5),)),
     "encoder.offset_counts[0]"),
    ("robot-offset-beyond-bits", dict(set=((("encoder", "offset_counts", 0), 1 << 25),)),
     "encoder.offset_counts"),
    ("robot-coupling-row-7", dict(set=((("encoder", "coupling", 0), [7, 4, 0.01]),)),
     "encoder.coupling"),
    ("robot-coupling-singular", dict(set=((("encoder", "coupling", 0), [5, 5, 0.0]),)),
     "coupling"),
    ("robot-coupling-not-triple", dict(set=((("encoder", "coupling", 0), [5, 4]),)),
     "encoder.coupling[0]"),
    ("robot-coupling-object", dict(set=((("encoder", "coupling"), {"5,4": 0.1}),)),
     "encoder.coupling"),
    ("robot-encoder-missing", dict(drop=(("encoder",),)), "encoder"),
    ("robot-encoder-array", dict(set=((("encoder",), [1, 2, 3]),)), "encoder"),
    ("robot-limits-reversed", dict(set=((("joint_limits_deg", 0), [165, -165]),)),
     "joint_limits_deg[0]"),
    ("robot-limits-5", dict(drop=(("joint_limits_deg", 5),)), "joint_limits_deg"),
    ("robot-unknown-key", dict(set=((("dh_rows",), 6),)), "dh_rows"),
    ("robot-name-number", dict(set=((("name",), 70),)), "name"),
    ("robot-repeatability-negative", dict(set=((("repeatability_mm",), -0.07),)),
     "repeatability_mm"),
    ("robot-controller-missing", dict(drop=(("controller",),)), "controller"),
    ("robot-tick-zero", dict(set=((("controller", "tick_s"), 0.0),)), "controller.tick_s"),
    ("robot-ik-unknown", dict(set=((("inverse_kinematics",), "magic"),)), "inverse_kinematics"),
]
for name, mut, frag in ROBOT_BAD:
    case(name, PRED, {"robot.json": Mut("robot.json", **mut)}, 2, frag)
case("robot-top-array", PRED, {"robot.json": Json([1, 2, 3])}, 2, "JSON object")
case("robot-top-string", PRED, {"robot.json": Json("mc70")}, 2, "JSON object")
case("robot-empty", PRED, {"robot.json": Text("")}, 2, "invalid JSON")
case("robot-truncated", PRED, {"robot.json": Text('{"name": "x", "dh": [')}, 2, "invalid JSON")
case("robot-deep-100000", PRED, {"robot.json": Nest(100_000)}, 2, "nested")
case("robot-is-directory", PRED, {"robot.json": Dir()}, 2, "directory")
case("robot-binary", PRED, {"robot.json": Bytes(4096)}, 2, "robot.json")
case("robot-missing-file", f"predict {RUN} --params {PARAMS} --robot {{d}}/nothere.json",
     {}, 2, "not found")
case("robot-dev-zero", f"predict {RUN} --params {PARAMS} --robot /dev/zero", {}, 2,
     "/dev/zero", rss=True)
case("robot-valid", PRED, {"robot.json": Mut("robot.json")}, 0)

# ----- scene (through calibrate --scene) -------------------------------------------------------
CAL = f"calibrate {RUN} --scene {{d}}/scene.json"
SCENE_BAD = [
    ("scene-plates-string", dict(set=((("plates",), "plate"),)), "plates"),
    ("scene-plates-empty", dict(set=((("plates",), []),)), "plates"),
    ("scene-plates-object", dict(set=((("plates",), {"name": "plate"}),)), "plates"),
    ("scene-ntilde-zero", dict(set=((("plates", 0, "n_tilde"), [0.0, 0.0, 0.0]),)),
     "plates[0].n_tilde"),
    ("scene-ntilde-tiny", dict(set=((("plates", 0, "n_tilde"), [0.0, 1e-300, 0.0]),)),
     "plates[0].n_tilde"),
    ("scene-ntilde-2", dict(set=((("plates", 0, "n_tilde"), [0.0, 1.0]),)), "plates[0].n_tilde"),
    ("scene-ntilde-nan", dict(raw=((("plates", 0, "n_tilde", 1), "NaN"),)),
     "plates[0].n_tilde[1]"),
    ("scene-ntilde-strings", dict(set=((("plates", 0, "n_tilde"), ["0", "-1", "3"]),)),
     "plates[0].n_tilde[0]"),
    ("scene-corner-in-mm", dict(set=((("plates", 0, "corner_m"), [729.0, 737.0, 484.0]),)),
     "plates[0].corner_m"),
    ("scene-corner-out-of-reach", dict(set=((("plates", 0, "corner_m"), [9.0, 9.0, 0.5]),)),
     "plates[0]"),
    ("scene-size-negative", dict(set=((("plates", 0, "size_m"), [-0.35, 0.25]),)),
     "plates[0].size_m"),
    ("scene-thickness-mm", dict(set=((("plates", 0, "thickness_m"), 12.0),)),
     "plates[0].thickness_m"),
    ("scene-face-3", dict(set=((("plates", 0, "face"), 3),)), "plates[0].face"),
    ("scene-sensor-origin-mm", dict(set=((("sensor", "origin_m"), [25.7, -72.5, 90.0]),)),
     "sensor.origin_m"),
    ("scene-sensor-origin-2", dict(set=((("sensor", "origin_m"), [0.0, 0.1]),)),
     "sensor.origin_m"),
    ("scene-sensor-angle-deg", dict(set=((("sensor", "phi_y_rad"), 71.2),)), "sensor.phi_y_rad"),
    ("scene-sensor-missing", dict(drop=(("sensor",),)), "sensor"),
    ("scene-sensor-array", dict(set=((("sensor",), [0.0257, -0.0725, 0.1769]),)), "sensor"),
    ("scene-range-string", dict(set=((("sensor", "range_mm"), "65-95"),)), "sensor.range_mm"),
    ("scene-range-reversed", dict(set=((("sensor", "range_mm"), [95.0, 65.0]),)),
     "sensor.range_mm"),
    ("scene-range-in-m", dict(set=((("sensor", "range_mm"), [0.065, 0.095]),)),
     "sensor.range_mm"),
    ("scene-home-3-values", dict(set=((("positions", "home_counts"), [1, 2, 3]),)),
     "positions.home_counts"),
    ("scene-home-float", dict(set=((("positions", "home_counts", 0), 8388608.0),)),
     "positions.home_counts[0]"),
    ("scene-home-huge", dict(raw=((("positions", "home_counts", 0), "9" * 500),)),
     "positions.home_counts[0]"),
    ("scene-calibration-5", dict(set=((("positions", "calibration_deg"), [1, 2, 3, 4, 5]),)),
     "positions.calibration_deg"),
    ("scene-sampling-outside-window", dict(set=((("sampling", "distance_mm"), [50.0, 90.0]),)),
     "sampling"),
    ("scene-cone-negative", dict(set=((("sampling", "cone_deg"), -5.0),)), "sampling.cone_deg"),
    ("scene-robot-unknown", dict(set=((("robot",), "abb_irb"),)), "robot"),
    ("scene-robot-number", dict(set=((("robot",), 70),)), "robot"),
    ("scene-obstacles-string", dict(set=((("obstacles",), "none"),)), "obstacles"),
    ("scene-obstacle-size-zero", dict(set=((("obstacles",), [
        {"name": "box", "center_m": [1, 1, 1], "size_m": [0, 0.1, 0.1],
         "rpy_rad": [0, 0, 0]}]),)), "obstacles[0]"),
    ("scene-floor-string", dict(set=((("floor_z_m",), "0"),)), "floor_z_m"),
    ("scene-unknown-key", dict(set=((("plate",), {}),)), "plate"),
    ("scene-1e308-corner", dict(set=((("plates", 0, "corner_m", 0), 1e308),)),
     "plates[0].corner_m"),
]
for name, mut, frag in SCENE_BAD:
    case(name, CAL, {"scene.json": Mut("scene.json", **mut)}, 2, frag)
case("scene-top-array", CAL, {"scene.json": Json([{"name": "x"}])}, 2, "JSON object")
case("scene-top-null", CAL, {"scene.json": Json(None)}, 2, "JSON object")
case("scene-deep-100000", CAL, {"scene.json": Nest(100_000)}, 2, "nested")
case("scene-is-directory", CAL, {"scene.json": Dir()}, 2, "directory")
case("scene-binary", CAL, {"scene.json": Bytes(2048, 1)}, 2, "scene.json")
case("scene-latin1", CAL, {"scene.json": Text('{"name": "caf\udce9"}')}, 2, "scene.json")
case("scene-unknown-name", f"calibrate {RUN} --scene no_such_scene", {}, 2, "no_such_scene")
case("scene-valid", CAL, {"scene.json": Mut("scene.json")}, 0)

# ----- parameter files: --initial (calibrate), --params (predict, replay), --truth ---------
PARAM_BAD = [
    ("offsets-5", dict(drop=(("joint_offsets_rad", 5),)), "joint_offsets_rad"),
    ("offsets-string", dict(set=((("joint_offsets_rad",), "0 0 0 0 0 0"),)),
     "joint_offsets_rad"),
    ("offsets-nan", dict(raw=((("joint_offsets_rad", 1), "NaN"),)), "joint_offsets_rad[1]"),
    ("offsets-1e308", dict(set=((("joint_offsets_rad", 1), 1e308),)), "joint_offsets_rad[1]"),
    ("offsets-degrees", dict(set=((("joint_offsets_rad", 2), 45.0),)), "joint_offsets_rad[2]"),
    ("offsets-missing", dict(drop=(("joint_offsets_rad",),)), "joint_offsets_rad"),
    ("planes-object", dict(set=((("planes",), {"n_tilde": [0, -1, 4]}),)), "planes"),
    ("planes-empty", dict(set=((("planes",), []),)), "planes"),
    ("plane-ntilde-zero", dict(set=((("planes", 0, "n_tilde"), [0, 0, 0]),)),
     "planes[0].n_tilde"),
    ("plane-ntilde-inf", dict(raw=((("planes", 0, "n_tilde", 2), "-Infinity"),)),
     "planes[0].n_tilde[2]"),
    ("sensor-origin-mm", dict(set=((("sensor", "origin_m"), [35.4, -76.9, 177.3]),)),
     "sensor.origin_m"),
    ("sensor-origin-90m", dict(set=((("sensor", "origin_m"), [0.0, 0.0, 90.0]),)),
     "sensor.origin_m"),
    ("sensor-phi-string", dict(set=((("sensor", "phi_y_rad"), "1.25"),)), "sensor.phi_y_rad"),
    ("sensor-missing", dict(drop=(("sensor",),)), "sensor"),
    ("sensor-array", dict(set=((("sensor",), [0.03, -0.07, 0.17, 1.25, -1.04]),)), "sensor"),
    ("format-wrong", dict(set=((("format",), "planecal-scene/1"),)), "format"),
    ("huge-int", dict(raw=((("joint_offsets_rad", 0), "7" * 330),)), "joint_offsets_rad[0]"),
]
for name, mut, frag in PARAM_BAD:
    case(f"initial-{name}", f"calibrate {RUN} --initial {{d}}/p.json",
         {"p.json": Mut("params.json", **mut)}, 2, frag)
for name, mut, frag in PARAM_BAD[::2]:
    case(f"params-{name}", f"predict {RUN} --params {{d}}/p.json",
         {"p.json": Mut("params.json", **mut)}, 2, frag)
for name, mut, frag in PARAM_BAD[1::3]:
    case(f"truth-{name}", f"replay {RUN} --params {{d}}/p.json",
         {"p.json": Mut("params.json", **mut)}, 2, frag)
case("initial-deep-100000", f"calibrate {RUN} --initial {{d}}/p.json",
     {"p.json": Nest(100_000)}, 2, "nested")
case("initial-is-directory", f"calibrate {RUN} --initial {{d}}/p.json", {"p.json": Dir()}, 2,
     "directory")
case("params-top-array", f"predict {RUN} --params {{d}}/p.json", {"p.json": Json([0.0] * 6)}, 2,
     "JSON object")
case("params-dev-zero", f"predict {RUN} --params /dev/zero", {}, 2, "/dev/zero", rss=True)
case("params-valid", f"predict {RUN} --params {{d}}/p.json", {"p.json": Mut("params.json")}, 0)

# ----- pose lists (rehearse --poses) -------------------------------------------------------------
REH_POSES = "rehearse --poses {d}/poses.json --out {d}/out.tsv --samples 2"
POSES_BAD = [
    ("poses-counts-string", dict(set=((("counts",), "none"),)), "counts"),
    ("poses-counts-5", dict(set=((("counts", 0), [8388608] * 5),)), "counts[0]"),
    ("poses-counts-float", dict(set=((("counts", 0, 0), 8388608.5),)), "counts[0][0]"),
    ("poses-plates-length", dict(set=((("plates",), [0]),)), "plates"),
    ("poses-plate-negative", dict(set=((("plates", 0), -1),)), "plates[0]"),
    ("poses-missing-counts", dict(drop=(("counts",),)), "counts"),
    ("poses-format-wrong", dict(set=((("format",), "planecal-run/1"),)), "format"),
    ("poses-counts-huge", dict(raw=((("counts", 0, 0), "1" * 400),)), "counts[0][0]"),
]
for name, mut, frag in POSES_BAD:
    case(name, REH_POSES, {"poses.json": Mut("poses.json", **mut)}, 2, frag)
case("poses-deep-100000", REH_POSES, {"poses.json": Nest(100_000)}, 2, "nested")
# a plate the scene does not have: refused by every command that takes a pose list
case("poses-plate-beyond-scene", REH_POSES,
     {"poses.json": Mut("poses.json", set=((("plates", 0), 7),))}, 2, "plate numbers must be")
case("validate-poses-plate-beyond-scene",
     "validate --poses {d}/poses.json --truth-seeds 0 --out {d}/v.json --no-history",
     {"poses.json": Mut("poses.json", set=((("plates", 0), 7),))}, 2, "plate numbers must be")
case("poses-is-directory", REH_POSES, {"poses.json": Dir()}, 2, "directory")

# ----- run sidecar (rehearse --resume) -----------------------------------------------------------
RESUME = "rehearse --resume --out {d}/run.tsv"
SIDE_BAD = [
    ("sidecar-samples-string", dict(set=((("samples",), "40"),)), "samples"),
    ("sidecar-samples-negative", dict(set=((("samples",), -3),)), "samples"),
    ("sidecar-seed-float", dict(set=((("seed",), 0.5),)), "seed"),
    ("sidecar-settings-array", dict(set=((("settings",), [1, 2]),)), "settings"),
    ("sidecar-settings-missing", dict(drop=(("settings",),)), "settings"),
    ("sidecar-rng-state-string", dict(set=((("rng_state",), "PCG64"),)), "rng_state"),
    ("sidecar-distance-nan", dict(raw=((("distance_mm", 0), "NaN"),)), "distance_mm[0]"),
    ("sidecar-status-unknown", dict(set=((("status",), "exploded"),)), "status"),
    ("sidecar-budget-negative", dict(set=((("settings", "robot_minutes"), -5),)),
     "settings.robot_minutes"),
    ("sidecar-format-wrong", dict(set=((("format",), "planecal-poses/1"),)), "format"),
    ("sidecar-rejected-list", dict(set=((("rejected",), [0, 0, 0]),)), "rejected"),
    ("sidecar-ticks-huge", dict(raw=((("ticks",), "1" * 400),)), "ticks"),
    ("sidecar-twin-string", dict(set=((("twin",), "yes"),)), "twin"),
]
for name, mut, frag in SIDE_BAD:
    case(name, RESUME, {"run.tsv": Rows(), "run.tsv.json": Mut("run.tsv.json", **mut)}, 2, frag)
case("sidecar-top-array", RESUME, {"run.tsv": Rows(), "run.tsv.json": Json([])}, 2,
     "JSON object")
case("sidecar-deep-100000", RESUME, {"run.tsv": Rows(), "run.tsv.json": Nest(100_000)}, 2,
     "nested")
case("sidecar-is-directory", RESUME, {"run.tsv": Rows(), "run.tsv.json": Dir()}, 2, "directory")
case("sidecar-binary", RESUME, {"run.tsv": Rows(), "run.tsv.json": Bytes(1000, 2)}, 2,
     "run.tsv.json")

# ----- error profiles (rehearse --errors) --------------------------------------------------------
REH_ERR = "rehearse --errors {d}/e.json --out {d}/out.tsv --samples 2"
ERR_BAD = [
    ("errors-cell-array", dict(set=((("cell",), [0.003] * 6),)), "cell"),
    ("errors-offsets-nan", dict(raw=((("cell", "joint_offsets_rad", 0), "NaN"),)),
     "cell.joint_offsets_rad[0]"),
    ("errors-offsets-5", dict(drop=(("cell", "joint_offsets_rad", 5),)),
     "cell.joint_offsets_rad"),
    ("errors-sensor-origin-mm", dict(set=((("cell", "sensor_origin_m"), 10.0),)),
     "cell.sensor_origin_m"),
    ("errors-negative", dict(set=((("cell", "plane_point_m"), -0.01),)), "cell.plane_point_m"),
    ("errors-format-wrong", dict(set=((("format",), "planecal-params/1"),)), "format"),
    ("errors-name-number", dict(set=((("name",), 3),)), "name"),
    ("errors-unknown-key", dict(set=((("cel",), {}),)), "cel"),
]
for name, mut, frag in ERR_BAD:
    case(name, REH_ERR, {"e.json": Mut("errors.json", **mut)}, 2, frag)
case("errors-deep-100000", REH_ERR, {"e.json": Nest(100_000)}, 2, "nested")
case("errors-is-directory", REH_ERR, {"e.json": Dir()}, 2, "directory")
case("errors-unknown-name", "rehearse --errors perfect --out {d}/out.tsv", {}, 2, "perfect")

# ----- sample files ------------------------------------------------------------------------------
CS = "calibrate {d}/s.tsv"
case("samples-dm-500-window", CS, {"s.tsv": Rows(edit=((3, None, "500.000000"),))}, 2,
     "laser window")
case("samples-dm-negative", CS, {"s.tsv": Rows(edit=((2, None, "-70.1"),))}, 2, "Dm")
case("samples-dm-nan", CS, {"s.tsv": Rows(edit=((2, None, "nan"),))}, 2, "Dm")
case("samples-dm-inf", CS, {"s.tsv": Rows(edit=((2, None, "inf"),))}, 2, "Dm")
case("samples-dm-word", CS, {"s.tsv": Rows(edit=((2, None, "eighty"),))}, 2, "Dm")
case("samples-dm-1e400", CS, {"s.tsv": Rows(edit=((2, None, "1e400"),))}, 2, "Dm")
case("samples-q-float", CS, {"s.tsv": Rows(edit=((1, 0, "8388608.5"),))}, 2, "q1")
case("samples-q-negative", CS, {"s.tsv": Rows(edit=((1, 2, "-5"),))}, 2, "q3")
case("samples-q-25-bit", CS, {"s.tsv": Rows(edit=((1, 3, str(1 << 25)),))}, 2, "q4")
case("samples-q-huge", CS, {"s.tsv": Rows(edit=((1, 3, "9" * 5000),))}, 2, "s.tsv:")
case("samples-6-columns", CS, {"s.tsv": Rows(edit=((4, 6, ""),))}, 2, "columns")
case("samples-40-copies", CS, {"s.tsv": Rows(repeat=40)}, 2, "no information")
case("samples-empty", CS, {"s.tsv": Text("")}, 2, "no samples")
case("samples-header-only", CS, {"s.tsv": Text("q1\tq2\tq3\tq4\tq5\tq6\tDm\n")}, 2, "no samples")
case("samples-only-zeros", CS, {"s.tsv": Text("8388608\t" * 6 + "0\n" + "8388000\t" * 6 + "0\n")},
     2, "laser zeros")
case("samples-binary", CS, {"s.tsv": Bytes(100_000, 3)}, 2, "s.tsv")
case("samples-utf16", CS, {"s.tsv": Text("\ufeffq1\tq2")}, 2, "s.tsv")
case("samples-is-directory", CS, {"s.tsv": Dir()}, 2, "directory")
case("samples-missing", "calibrate {d}/none.tsv", {}, 2, "not found")
case("samples-dev-zero", "calibrate /dev/zero", {}, 2, "/dev/zero", rss=True)
case("samples-json-given", "calibrate {base}/params.json", {}, 2, "params.json")
case("samples-three-plate-column-missing",
     "calibrate {d}/s.tsv --scene three_plates",
     {"s.tsv": Rows(base="run3.tsv", drop_plate=(3, 4, 5, 6))}, 2, "plate column")
case("samples-three-plate-number-5", "calibrate {d}/s.tsv --scene three_plates",
     {"s.tsv": Rows(base="run3.tsv", edit=((2, 7, "5"),))}, 2, "plate 5")
case("samples-plate-zero", "calibrate {d}/s.tsv --scene three_plates",
     {"s.tsv": Rows(base="run3.tsv", edit=((2, 7, "0"),))}, 2, "plate")
case("samples-decimal-comma-valid", CS, {"s.tsv": Rows(comma=True)}, 0)
case("samples-header-middle", CS, {"s.tsv": Rows(edit=((5, "header", ""),))}, 2, "header")

# ----- options ------------------------------------------------------------------------------------
case("opt-outlier-sigma-0", f"calibrate {RUN} --outlier-sigma 0", {}, 2, "--outlier-sigma")
case("opt-outlier-sigma-negative", f"calibrate {RUN} --outlier-sigma -3", {}, 2,
     "--outlier-sigma")
case("opt-outlier-sigma-nan", f"calibrate {RUN} --outlier-sigma nan", {}, 2, "--outlier-sigma")
case("opt-improvement-limit-nan", f"calibrate {RUN} --improvement-limit nan", {}, 2,
     "--improvement-limit")
case("opt-improvement-limit-negative", f"calibrate {RUN} --improvement-limit -1", {}, 2,
     "--improvement-limit")
case("opt-max-iter-0", f"calibrate {RUN} --max-iter 0", {}, 2, "--max-iter")
case("opt-max-iter-word", f"calibrate {RUN} --max-iter many", {}, 2, "--max-iter")
case("opt-free-unknown", f"calibrate {RUN} --free delta9", {}, 2, "delta9")
case("opt-method-unknown", f"calibrate {RUN} --method newton", {}, 2, "--method")
case("opt-unknown-option", f"calibrate {RUN} --frobnicate", {}, 2, "--help")
case("opt-unknown-command", "frobnicate", {}, 2, "--help")
case("opt-no-samples", "calibrate", {}, 2, "--help")
case("opt-no-command", (), {}, 2, "--help")
case("opt-only-quiet", "-q", {}, 2, "--help")
case("opt-help", "calibrate --help", {}, 0)
case("opt-version", "--version", {}, 0)
case("opt-repeatability-negative", f"calibrate {RUN} --repeatability-mm -1", {}, 2,
     "--repeatability-mm")
case("opt-distance-sigma-inf", f"calibrate {RUN} --distance-sigma-um inf", {}, 2,
     "--distance-sigma-um")
case("opt-rehearse-samples-0", "rehearse --out {d}/o.tsv --samples 0", {}, 2, "--samples")
case("opt-rehearse-cone-nan", "rehearse --out {d}/o.tsv --cone-deg nan", {}, 2, "--cone-deg")
case("opt-rehearse-distance-reversed", "rehearse --out {d}/o.tsv --distance-mm 90 70", {}, 2,
     "--distance-mm")
case("opt-bootstrap-sizes-word", f"bootstrap {RUN} --sizes ten", {}, 2, "--sizes")
case("opt-bootstrap-repeats-0", f"bootstrap {RUN} --repeats 0", {}, 2, "--repeats")
case("opt-export-qe0-5", "export {base}/params.json --current-qe0 1,2,3,4,5", {}, 2,
     "--current-qe0")
case("opt-config-missing", f"calibrate {RUN} --config {{d}}/none.toml", {}, 2, "not found")
case("opt-config-dev-zero", f"calibrate {RUN} --config /dev/zero", {}, 2, "/dev/zero", rss=True)
case("opt-config-directory", f"calibrate {RUN} --config {{d}}/c.toml", {"c.toml": Dir()}, 2,
     "directory")
case("opt-config-binary", f"calibrate {RUN} --config {{d}}/c.toml", {"c.toml": Bytes(500, 4)}, 2,
     "c.toml")
case("opt-config-bad-toml", f"calibrate {RUN} --config {{d}}/c.toml",
     {"c.toml": Text("[calibrate\nmax_iter = 3\n")}, 2, "TOML")
case("opt-config-bad-value", f"calibrate {RUN} --config {{d}}/c.toml",
     {"c.toml": Text("[calibrate]\nmax-iter = \"lots\"\n")}, 2, "--max-iter")

# ----- outputs --------------------------------------------------------------------------------
case("out-calibrate-equals-input", "calibrate {d}/s.tsv --out {d}/s.tsv", {"s.tsv": Rows()}, 2,
     "input")
case("out-calibrate-equals-initial", f"calibrate {RUN} --initial {{d}}/p.json --out {{d}}/p.json",
     {"p.json": Mut("params.json")}, 2, "input")
case("out-calibrate-directory", f"calibrate {RUN} --out {{d}}/sub", {"sub": Dir()}, 2,
     "directory")
case("out-calibrate-missing-dir", f"calibrate {RUN} --out {{d}}/no/r.json", {}, 2,
     "does not exist")
case("out-calibrate-foreign-file", f"calibrate {RUN} --out {{d}}/notes.txt",
     {"notes.txt": Text("my notes\n")}, 2, "--force")
case("out-calibrate-dev-full-dir", f"calibrate {RUN} --out /proc/r.json", {}, 2, "/proc")
case("out-rehearse-truth-equals-out", "rehearse --truth-out {d}/t.json --out {d}/t.json", {}, 2,
     "--truth-out")
case("out-rehearse-out-directory", "rehearse --out {d}/sub", {"sub": Dir()}, 2, "directory")
case("out-rehearse-exists", "rehearse --out {d}/s.tsv", {"s.tsv": Rows()}, 2, "--resume")
case("out-replay-equals-input", "replay {d}/s.tsv --params {base}/params.json --out {d}/s.tsv",
     {"s.tsv": Rows()}, 2, "input")
case("out-replay-equals-params", "replay {base}/run.tsv --params {d}/p.json --out {d}/p.json",
     {"p.json": Mut("params.json")}, 2, "input")
case("out-bootstrap-equals-input", "bootstrap {d}/s.tsv --out {d}/s.tsv", {"s.tsv": Rows()}, 2,
     "input")
case("out-export-equals-result", "export {d}/p.json --out {d}/p.json",
     {"p.json": Mut("params.json")}, 2, "input")
case("out-plan-directory", "plan --out {d}/sub --samples 5", {"sub": Dir()}, 2, "directory")
case("out-montecarlo-directory", "montecarlo --out {d}/sub --runs 2", {"sub": Dir()}, 2,
     "directory")
case("out-validate-directory", "validate --out {d}/sub", {"sub": Dir()}, 2, "directory")

# ----- exit 1: fits that fail ---------------------------------------------------------------------
case("fit-not-converged", f"calibrate {RUN} --max-iter 1", {}, 1, "converge")
# 16 samples with compliance: delta2's std 1.5x its limit (the model's mismatch: a robot
# parameter must meet it; 40 samples at level offsets failed only through phi_y's
# mismatch-inflated std, a warning now that the sensor's frame is judged at the noise)

# ----- pipes and valid runs -----------------------------------------------------------------------
case("pipe-predict-head", f"predict {RUN} --params {PARAMS}", {}, 0, None, pipe="head -1")
case("valid-calibrate", f"calibrate {RUN} --out {{d}}/r.json", {}, 0)
case("valid-predict", f"predict {RUN} --params {PARAMS}", {}, 0)

# ----- the real-cell commands refuse bad inputs before touching a link -------------------------
case("out-sample-directory", "sample --rt 127.0.0.1 --out {d}/sub", {"sub": Dir()}, 2, "directory")
case("out-sample-equals-poses",
     "sample --rt 127.0.0.1 --out {d}/poses.json --poses {d}/poses.json",
     {"poses.json": Mut("poses.json")}, 2, "input")
case("out-rehearse-truth-is-poses", "rehearse --out {d}/o.tsv --poses {d}/poses.json "
     "--truth-out {d}/poses.json", {"poses.json": Mut("poses.json")}, 2, "input")
case("emulate-truth-ntilde-zero", "emulate --truth {d}/p.json",
     {"p.json": Mut("params.json", set=((("planes", 0, "n_tilde"), [0, 0, 0]),))}, 2,
     "planes[0].n_tilde")
case("emulate-truth-directory", "emulate --truth {d}/p.json", {"p.json": Dir()}, 2, "directory")
case("emulate-scene-binary", "emulate --scene {d}/s.json", {"s.json": Bytes(300, 5)}, 2, "s.json")

# ----- issue 25: no output replaces an input, whatever the path to it ---------------------------
SC, ER, RT = Mut("scene.json"), Mut("errors.json"), Rows()
RES = Mut("result.json")
SPEC = '[grid]\nsamples = [20]\ndesign = ["random"]\n[sweep]\nruns = 2\n'
INPUT_AS_OUTPUT = [  # (name, argv, files): an output that is an input, refused
    ("out-urdf-equals-scene", "urdf --scene {d}/scene.json --out {d}/scene.json",
     {"scene.json": SC}),
    ("out-export-equals-scene", "export {base}/result.json --scene {d}/scene.json "
     "--out {d}/scene.json", {"scene.json": SC}),
    ("out-plan-equals-scene-force", "plan --scene {d}/scene.json --out {d}/scene.json --force",
     {"scene.json": SC}),
    ("out-layouts-equals-scene-force", "layouts --scene {d}/scene.json --out {d}/scene.json "
     "--force", {"scene.json": SC}),
    ("out-montecarlo-equals-nan-errors-force", "montecarlo --errors {d}/e.json --out {d}/e.json "
     "--force", {"e.json": Mut("errors.json", raw=((("cell", "joint_offsets_rad", 0), "NaN"),))}),
    ("out-validate-equals-errors-force", "validate --errors {d}/e.json --out {d}/e.json --force",
     {"e.json": ER}),
    ("out-validate-equals-poses-force", "validate --poses {d}/p.json --out {d}/p.json --force",
     {"p.json": Mut("poses.json")}),
    ("results-bootstrap-equals-pool-force", "bootstrap {d}/s.tsv --results {d}/s.tsv --force",
     {"s.tsv": RT}),
    ("results-bootstrap-equals-scene-force", "bootstrap {base}/run.tsv --scene {d}/scene.json "
     "--results {d}/scene.json --force", {"scene.json": SC}),
    ("out-bootstrap-equals-scene-force", "bootstrap {base}/run.tsv --scene {d}/scene.json "
     "--out {d}/scene.json --force", {"scene.json": SC}),
    ("out-calibrate-equals-scene-force", "calibrate {base}/run.tsv --scene {d}/scene.json "
     "--out {d}/scene.json --force", {"scene.json": SC}),
    ("out-calibrate-equals-input-sidecar-force", "calibrate {d}/s.tsv --out {d}/s.tsv.json --force",
     {"s.tsv": RT, "s.tsv.json": Mut("run.tsv.json")}),
    ("out-calibrate-hard-link-to-input-force", "calibrate {d}/s.tsv --out {d}/h.json --force",
     {"s.tsv": RT, "h.json": Link("{d}/s.tsv", hard=True)}),
    ("out-layouts-link-to-scene-force", "layouts --scene {d}/scene.json --out {d}/l.json --force",
     {"scene.json": SC, "l.json": Link("{d}/scene.json")}),
    ("results-montecarlo-link-to-scene-force", "montecarlo --scene {d}/scene.json --results "
     "{d}/r.jsonl --force", {"scene.json": SC, "r.jsonl": Link("{d}/scene.json")}),
    ("report-index-is-the-result-link", "report {d}/r.json --out {d}/rep",
     {"r.json": RES, "run.tsv": RT, "rep": Dir(), "rep/index.html": Link("{d}/r.json")}),
    ("report-png-is-the-recorded-samples-link", "report {d}/r.json --out {d}/rep",
     {"r.json": RES, "run.tsv": RT, "rep": Dir(), "rep/offsets.png": Link("{d}/run.tsv")}),
    ("report-bootstrap-index-is-a-sample-file", "bootstrap {d}/rep/index.html --report {d}/rep",
     {"rep": Dir(), "rep/index.html": RT}),
    ("report-plan-index-is-the-scene", "plan --scene {d}/rep/index.html --report {d}/rep "
     "--out {d}/p.json", {"rep": Dir(), "rep/index.html": SC}),
    ("sweep-txt-is-the-spec-link", "sweep {d}/spec.toml --out {d}/sw",
     {"spec.toml": Text(SPEC), "sw": Dir(), "sw/sweep.txt": Link("{d}/spec.toml")}),
    ("sweep-spec-is-sweep-txt", "sweep {d}/sw/sweep.txt --out {d}/sw",
     {"sw": Dir(), "sw/sweep.txt": Text(SPEC)}),
    ("sweep-errors-profile-is-sweep-json", "sweep {d}/spec.toml --out {d}/sw",
     {"spec.toml": Text(SPEC.replace("[sweep]", 'errors = ["sw/sweep.json"]\n[sweep]')),
      "sw": Dir(), "sw/sweep.json": ER}),
    ("rrd-calibrate-equals-samples", "calibrate {d}/s.tsv --rrd {d}/s.tsv", {"s.tsv": RT}),
    ("rrd-rehearse-equals-errors", "rehearse --errors {d}/e.json --rrd {d}/e.json "
     "--out {d}/o.tsv", {"e.json": ER}),
    ("rrd-validate-equals-errors", "validate --errors {d}/e.json --rrd {d}/e.json",
     {"e.json": ER}),
    ("rrd-demo-equals-scene", "demo --scene {d}/scene.json --rrd {d}/scene.json --dir {d}/dd",
     {"scene.json": SC}),
    ("out-rehearse-equals-errors-force", "rehearse --errors {d}/e.json --out {d}/e.json --force",
     {"e.json": ER}),
    ("out-rehearse-equals-scene-force", "rehearse --scene {d}/s.json --out {d}/s.json --force",
     {"s.json": SC}),
    ("truth-out-rehearse-equals-errors-force", "rehearse --errors {d}/e.json --truth-out "
     "{d}/e.json --out {d}/o.tsv --force", {"e.json": ER}),
    ("out-rehearse-sidecar-equals-scene-force", "rehearse --scene {d}/s.tsv.json --out {d}/s.tsv "
     "--force", {"s.tsv.json": SC}),
    ("out-montecarlo-equals-scene-force", "montecarlo --scene {d}/scene.json --out "
     "{d}/scene.json --force", {"scene.json": SC}),
    ("results-montecarlo-equals-scene-force", "montecarlo --scene {d}/scene.json --results "
     "{d}/scene.json --force", {"scene.json": SC}),
    ("dir-demo-holds-the-scene-force", "demo --dir {d}/dd --scene {d}/dd/result.json --force",
     {"dd": Dir(), "dd/result.json": SC}),
]
for name, argv, files in INPUT_AS_OUTPUT:
    case(name, argv, files, 2, "input")
CFG_CMDS = {"calibrate": "calibrate {base}/run.tsv", "plan": "plan",
            "compensate": "compensate {d}/t.csv --params {base}/result.json",
            "rehearse": "rehearse"}
for cmd, line in CFG_CMDS.items():
    case(f"out-{cmd}-equals-config-force", f"{line} --config {{d}}/c.toml --out {{d}}/c.toml "
         "--force", {"c.toml": Text(f"[{cmd}]\n")}, 2, "input")
    case(f"config-{cmd}-out-is-the-config", f"{line} --config {{d}}/c.toml",
         {"c.toml": Tmpl(f'[{cmd}]\nout = "{{d}}/c.toml"\nforce = true\n')}, 2, "input")
for name, row, col, text, frag in (("corrupt-last-line", 119, 0, "x#", "run.tsv:121"),
                                   ("corrupt-middle-line", 50, 0, "x#", "run.tsv:52"),
                                   ("nan-dm-line", 119, None, "nan", "run.tsv:121"),
                                   ("inf-dm-line", 60, None, "inf", "run.tsv:62")):
    case(f"resume-{name}", RESUME, {"run.tsv": Rows(edit=((row, col, text),)),
                                    "run.tsv.json": Mut("run.tsv.json")}, 2, frag)
case("results-montecarlo-equals-out", "montecarlo --results {d}/m.json --out {d}/m.json", {}, 2,
     "writes that file too")

# ----- issue 25: files planecal did not write are replaced only with --force ------------------
NOTES = Text("my notes\n")
case("out-export-foreign-file", "export {base}/result.json --out {d}/notes.txt",
     {"notes.txt": NOTES}, 2, "--force")
case("out-export-sample-file", "export {base}/result.json --out {d}/s.tsv", {"s.tsv": RT}, 2,
     "--force")
case("out-export-directory", "export {base}/result.json --out {d}/sub", {"sub": Dir()}, 2,
     "directory")
case("report-foreign-index", "report {base}/result.json --out {d}/rep",
     {"rep": Dir(), "rep/index.html": Text("<p>mine</p>\n")}, 2, "did not write")
case("report-calibrate-foreign-png", "calibrate {base}/run.tsv --report {d}/rep",
     {"rep": Dir(), "rep/offsets.png": Bytes(300)}, 2, "did not write")
case("report-out-is-a-folder-of-other-files", "report {d}/r.json --out {d}",
     {"r.json": RES}, 2, "did not write")
case("rrd-calibrate-foreign-file", "calibrate {base}/run.tsv --rrd {d}/notes.txt",
     {"notes.txt": NOTES}, 2, "--force")
case("rrd-rehearse-foreign-file", "rehearse --out {d}/o.tsv --rrd {d}/notes.txt",
     {"notes.txt": NOTES}, 2, "--force")
case("out-urdf-foreign-file", "urdf --out {d}/notes.txt", {"notes.txt": NOTES}, 2, "--force")
case("urdf-meshes-foreign-stl", "urdf --out {d}/x.urdf",
     {"x_meshes": Dir(), "x_meshes/base_link_visual.stl": Bytes(300)}, 2, "--force")
case("sweep-foreign-txt", "sweep {d}/spec.toml --out {d}/sw",
     {"spec.toml": Text(SPEC), "sw": Dir(), "sw/sweep.txt": NOTES}, 2, "did not write")

# ----- issue 25: a refusal writes nothing ------------------------------------------------------
NEW = "calibrate {base}/run.tsv --out {d}/new.json"
case("calibrate-report-is-a-file", f"{NEW} --report {{d}}/notes.txt", {"notes.txt": NOTES}, 2,
     "not a directory")
case("calibrate-report-in-proc", f"{NEW} --report /proc/x", {}, 2, "/proc")
case("calibrate-report-missing-parent", f"{NEW} --report {{d}}/no/such/dir", {}, 2,
     "does not exist")
case("calibrate-rrd-missing-dir", f"{NEW} --rrd {{d}}/no/x.rrd", {}, 2, "does not exist")
case("calibrate-rrd-in-proc", f"{NEW} --rrd /proc/x", {}, 2, "/proc")
case("plan-report-is-a-file", "plan --out {d}/pp.json --report {d}/notes.txt",
     {"notes.txt": NOTES}, 2, "not a directory")
REPORT_BAD = [
    ("residual-nan", dict(raw=((("residual_rms_mm",), "NaN"),)), "residual_rms_mm"),
    ("model-error-number", dict(set=((("model_error",), 3),)), "model_error"),
    ("covariance-list", dict(set=((("covariance",), [1, 2]),)), "covariance"),
    ("identifiability-list", dict(set=((("identifiability",), [1]),)), "identifiability"),
    ("samples-used-string", dict(set=((("samples_used",), "120"),)), "samples_used"),
    ("encoder-offsets-string", dict(set=((("encoder_offsets",), "none"),)), "encoder_offsets"),
    ("provenance-list", dict(set=((("provenance",), []),)), "provenance"),
]
for name, mut, frag in REPORT_BAD:
    case(f"report-{name}", "report {d}/r.json --out {d}/rep",
         {"r.json": Mut("result.json", **mut), "run.tsv": RT}, 2, frag)
case("report-samples-missing", "report {base}/result.json --out {d}/rep --samples {d}/none.tsv",
     {}, 2, "none.tsv")
for v in ("nan", "inf"):
    case(f"sweep-clearance-{v}", "sweep {d}/spec.toml --out {d}/sw",
         {"spec.toml": Text(SPEC + f"clearance_m = {v}\n")}, 2, "clearance_m")
case("demo-samples-0", "demo --samples 0 --dir {d}/dd", {}, 2, "--samples")
case("demo-free-unknown", "demo --free delta9 --dir {d}/dd", {}, 2, "delta9")

# ----- issue 25: unreadable inputs and numbers too large are one line ------------------------
case("sweep-spec-binary", "sweep {d}/spec.toml --out {d}/sw", {"spec.toml": Bytes(500, 6)}, 2,
     "spec.toml")
case("sweep-spec-utf16", "sweep {d}/spec.toml --out {d}/sw",
     {"spec.toml": Raw(SPEC.encode("utf-16"))}, 2, "spec.toml")
case("sweep-spec-dev-zero", "sweep /dev/zero --out {d}/sw", {}, 2, "/dev/zero", rss=True)
COUNTS_HEAD = "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n"
COMP = "compensate {d}/t.csv --params {base}/result.json --samples {base}/run.tsv --out {d}/o.tsv"
case("compensate-field-2-mib", COMP, {"t.csv": Text(COUNTS_HEAD + "1" * 2**21 + ",0,0,0,0,0\n")},
     2, "t.csv:2")
for name, head in (("q1-twice", "q1,q1,q3,q4,q5,q6\n"),
                   ("q6-deg-twice", "q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q6_deg\n"),
                   ("name-twice", "name,name," + COUNTS_HEAD)):
    case(f"compensate-column-{name}", COMP, {"t.csv": Text(head)}, 2, "twice")
case("export-current-qe0-overflow", "export {base}/result.json --current-qe0 "
     "99999999999999999999,1,2,3,4,5", {}, 2, "--current-qe0")
case("sample-baud-negative", "sample --rt 127.0.0.1 --laser /dev/null --out {d}/o.tsv --baud -1",
     {}, 2, "--baud")
BIG = "100000000000000000000"
for name, line in (("sweep-samples-2-63", "samples = [9223372036854775808]"),
                   ("sweep-samples-1e9", "samples = [1000000000]")):
    case(name, "sweep {d}/spec.toml --out {d}/sw", {"spec.toml": Text(f"[grid]\n{line}\n")}, 2,
         "grid.samples")
for key, value in (("runs", "1000000000000"), ("plan_candidates", "1000000000000"),
                   ("seed", "1e20"), ("seed", BIG)):
    case(f"sweep-{key}-{value[:5]}", "sweep {d}/spec.toml --out {d}/sw",
         {"spec.toml": Text(f"[sweep]\n{key} = {value}\n")}, 2, f"sweep.{key}")
for line, opt in ((f"rehearse --out {{d}}/o.tsv --samples {BIG}", "--samples"),
                  (f"montecarlo --runs {BIG}", "--runs"), (f"montecarlo --samples {BIG}", "--samples"),
                  (f"bootstrap {RUN} --repeats {BIG}", "--repeats"),
                  (f"plan --out {{d}}/p.json --candidates {BIG}", "--candidates"),
                  (f"bootstrap {RUN} --jobs 100000", "--jobs")):
    case(f"count-{line.split()[0]}-{opt[2:]}-{line.split()[-1][:6]}", line, {}, 2, opt)

# ----- issue 25: numbers that are not defined are refused or written as null -----------------
for opt, v in (("--target-ap-mm", "inf"), ("--target-std-urad", "inf"), ("--target-ap-mm", "nan"),
               ("--target-ap-mm", "0"), ("--target-std-urad", "-1")):
    case(f"plan-target-{opt[9:]}-{v}", f"plan --out {{d}}/p.json {opt} {v}", {}, 2, opt)
case("plan-target-unreachable", "plan --out {d}/p.json --samples 13 --candidates 40 "
     "--target-std-urad 0.001", {}, 2, "not reached")
case("valid-bootstrap-writes-null-not-nan", f"bootstrap {RUN} --sizes 60 --repeats 2 --jobs 1 "
     "--out {d}/b.json", {}, 0)
case("valid-montecarlo-errors-file-writes-null-not-nan", "montecarlo --errors "
     "{base}/errors.json --runs 2 --samples 40 --jobs 1 --out {d}/m.json -q", {}, 0)
case("valid-validate-writes-null-not-nan", "validate --truth-seeds 0 --samples 20 --breakdown "
     "none --jobs 1 --cycles 2 --gauge-repeats 1 --out {d}/v.json -q", {}, 0)

# ----- issue 25: exit codes -------------------------------------------------------------------
LONG = "{d}/" + "x" * 300
LONG_OUT = {
    "urdf": f"urdf --out {LONG}", "export": f"export {{base}}/result.json --out {LONG}",
    "calibrate": f"calibrate {RUN} --out {LONG}", "rehearse": f"rehearse --out {LONG}",
    "mjcf": f"mjcf --out {LONG}", "layouts": f"layouts --out {LONG}",
    "replay": f"replay {RUN} --params {PARAMS} --out {LONG}",
    "compensate": f"compensate {{d}}/t.csv --params {{base}}/result.json --out {LONG}",
    "bootstrap": f"bootstrap {RUN} --out {LONG}", "montecarlo": f"montecarlo --out {LONG}",
    "plan": f"plan --out {LONG}", "validate": f"validate --out {LONG}",
    "scene-new": f"scene new --robot mc70 --out {LONG}",
    "robot-import": f"robot import {{d}}/r.urdf --out {LONG}",
    "report": f"report {{base}}/result.json --out {LONG}",
    "sweep": f"sweep {{d}}/spec.toml --out {LONG}"}
for cmd, line in LONG_OUT.items():
    case(f"out-{cmd}-name-too-long", line, {"spec.toml": Text(SPEC)}, 2, "too long")
for cmd, line in (("urdf", "urdf"), ("export", "export {base}/result.json"),
                  ("scene-new", "scene new --robot mc70"), ("sweep", "sweep {d}/spec.toml")):
    case(f"out-{cmd}-in-proc", f"{line} --out /proc/o.json", {"spec.toml": Text(SPEC)}, 2,
         "/proc")
case("predict-distances-in-metres", "predict {d}/s.tsv --params {base}/params.json",
     {"s.tsv": Rows(edit=((3, None, "0.08"),))}, 2, "laser window")
case("replay-distances-in-metres", "replay {d}/s.tsv --params {base}/params.json",
     {"s.tsv": Rows(edit=((3, None, "0.08"),))}, 2, "laser window")
case("config-flag-given-a-file", f"calibrate {RUN} --config {{d}}/c.toml",
     {"c.toml": Text('[calibrate]\nweighted = "fresh.tsv"\n')}, 2, "--weighted is a flag")
case("config-value-given-a-list", f"calibrate {RUN} --config {{d}}/c.toml",
     {"c.toml": Text('[calibrate]\nmax-iter = [20, "fresh.tsv"]\n')}, 2, "--max-iter")
case("config-robot-show-out", "robot show mc70 --config {d}/c.toml",
     {"c.toml": Text('[robot]\nout = "x"\n')}, 2, "--out")
case("robot-show-out", "robot show mc70 --out {d}/x", {}, 2, "robot import")
case("robot-import-bad-file-one-line", "robot import {d}/r.urdf --out {d}/rb",
     {"r.urdf": Text("<robot><link\n")}, 2, "r.urdf")
case("emulate-host-empty", ("emulate", "--host", ""), {}, 2, "0.0.0.0")
case("validate-two-poses-quiet", "validate --poses {base}/poses.json -q --jobs 1", {}, 2,
     "poses.json")

# ----- issue 32: a result read as a result, a run and a truth of another robot, ... -----------
RES = "result.json"
for name, raw, frag in (
        ("export-encoder-offset-nan", (("encoder_offsets", "joint_offsets_rad", 2), "NaN"),
         "encoder_offsets.joint_offsets_rad[2]"),
        ("export-encoder-offset-huge", (("encoder_offsets", "joint_offsets_rad", 2), "1e300"),
         "encoder_offsets.joint_offsets_rad[2]"),
        ("export-encoder-offset-string", (("encoder_offsets", "joint_offsets_rad", 2),
                                          '"-0.0019"'), "encoder_offsets.joint_offsets_rad[2]"),
        ("export-encoder-calibrated-string", (("encoder_offsets", "calibrated"), '"delta3"'),
         "encoder_offsets.calibrated")):
    case(name, "export {d}/r.json --out {d}/fd11.json", {"r.json": Mut(RES, raw=(raw,))}, 2, frag)
case("check-result-sigma-string", "check {base}/run.tsv --against {d}/r.json "
     "--calibration-samples {base}/run.tsv",
     {"r.json": Mut(RES, set=((("identifiability", "sigma_mm"), "0.05"),))}, 2,
     "identifiability.sigma_mm")
case("check-run-of-another-robot", "check {d}/r.tsv --against {base}/result.json",
     {"r.tsv": Rows(head=30), "r.tsv.json": Mut("run.tsv.json", set=(
         (("robot",), "Universal Robots UR5 (nominal DH)"), (("sample_file",), "r.tsv")))}, 2,
     "Universal Robots UR5")
case("check-run-too-short", "check {d}/r.tsv --against {base}/result.json",
     {"r.tsv": Rows(head=5)}, 2, "cannot show a drift")
case("rehearse-truth-of-another-robot", "rehearse --truth {d}/t.json --samples 5 --out {d}/o.tsv",
     {"t.json": Mut("params.json", set=((("robot",), {"name": "Universal Robots UR5 (nominal "
                                                               "DH)"}),))}, 2, "made for the robot")
for v in ("inf", "nan", "-inf", "1e308"):
    case(f"scene-new-floor-{v}", f"scene new --robot mc70 --out {{d}}/s.json --floor-z={v}", {}, 2,
         "--floor-z")
case("scene-new-floor-out-of-reach", "scene new --robot mc70 --out {d}/s.json --floor-z=5", {}, 2,
     "the default cell (floor_z_m 5)")
case("sweep-grid-of-1e9-runs", "sweep {d}/spec.toml --out {d}/sw",
     {"spec.toml": Text("[grid]\nsamples = [" + ", ".join(str(20 + k) for k in range(10_000))
                        + "]\n[sweep]\nruns = 100000\n")}, 2, "a sweep runs at most")
case("history-rollback-of-nothing", "history rollback 1 --history {d}/h.db --out {d}/fd11.json",
     {}, 2, "no history here yet")
case("history-note-newline", ("export", "{base}/result.json", "--note", "two\nlines"), {}, 2,
     "--note")
case("history-cell-too-long", ("export", "{base}/result.json", "--cell", "c" * 201), {}, 2,
     "--cell")
case("history-is-the-rrd-force", f"calibrate {RUN} --rrd {{d}}/h.db --force --history {{d}}/h.db",
     {}, 2, "the history")
