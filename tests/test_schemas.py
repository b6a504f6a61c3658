"""Each physical and structural check of planecal.formats, through the real readers, with
the exact one-line message; the published JSON Schemas against the models (current) and
against an independent validator (jsonschema) on the shipped files."""
import copy
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.formats import MODELS, load_sidecar, schema_documents, schema_file_name
from planecal.formats.params import RESULT_FORMAT, ResultFile, provenance, result_document
from planecal.io.params import load_params, params_to_dict, save_params
from planecal.base.paths import data_path
from repo import repo_path
from planecal.model.robot import load_robot
from planecal.model.scene import load_scene, nominal_params
from planecal.studies.planning import load_poses

ROBOT = json.loads(data_path("models", "mc70", "robot.json").read_text())
SCENE = json.loads(data_path("scenes", "three_plates.json").read_text())
PARAMS = json.loads(repo_path("examples", "table10_params.json").read_text())
POSES = {"format": "planecal-poses/1", "scene": "thesis_final", "seed": 0, "samples": 2,
         "counts": [[8388608] * 6, [8388000, 8388608, 8388608, 8388608, 8388608, 8388608]],
         "plates": [0, 0]}
SIDECAR = {
    "format": "planecal-run/1", "status": "complete", "stop_reason": None,
    "scene": "thesis_final", "scene_path": "/nowhere/thesis_final.json", "robot": "NACHI MC70-01",
    "seed": 0, "samples_target": 3, "samples": 3, "cone_deg": 30.0, "distance_mm": [70.0, 90.0],
    "settings": {"pose": {"cone_deg": 30.0, "distance_mm": [70.0, 90.0], "fixed_distance_mm": None,
                          "margin_m": 0.025, "roll_deg": 180.0, "plate_choice": "round_robin"},
                 "laser": {"buffer_len": 100, "spread_mm": 0.005, "max_out_of_range": 400,
                           "max_reads": 1000},
                 "dwell_ticks": 5, "nominal_step_counts": 50, "max_attempts": 500,
                 "clearance_m": 0.01, "collision_checking": True},
    "rejected": {"collision": 0, "laser": 0, "unreachable": 0},
    "laser_give_ups": {"out_of_range": 0, "not_stable": 0}, "recent_rejections": [],
    "ticks": 1470, "robot_time_s": 14.7, "wall_time_s": 0.046, "max_step_counts": 50,
    "sessions": 1,
    "rng_state": {"bit_generator": "PCG64",
                  "state": {"state": 325115863347516500475679070535785655313,
                            "inc": 87136372517582989555478159403783844777},
                  "has_uint32": 0, "uinteger": 0},
    "sample_file": "RUN.tsv", "plates": 1, "updated_utc": "2026-11-23T04:37:02+00:00",
    "twin": {"seed": 0, "exact": False},
}


def mutated(doc, path, value):
    """A deep copy of doc with the item at path (keys/indices) set to value (or deleted
    when value is DELETE)."""
    d = copy.deepcopy(doc)
    *head, last = path
    target = d
    for k in head:
        target = target[k]
    if value is DELETE:
        del target[last]
    elif last == "+":
        target.append(value)
    else:
        target[last] = value
    return d


DELETE = object()


def refused(tmp_path, reader, doc, name="f.json"):
    """The reader's InputError message for doc written to tmp_path/name, with the file
    name checked and stripped."""
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(InputError) as e:
        reader(p)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}: "), msg
    return msg[len(f"{p}: "):]


# ----- the robot description ------------------------------------------------------------------

@pytest.mark.parametrize("path, value, message", [
    (("dh", 5), DELETE, "dh: must hold 6 rows, one per joint, got 5"),
    (("encoder", "coupling", "+"), [7, 4, 0.1],
     "encoder.coupling[3][0]: 7 is not a plausible joint number (1-based) (in [1, 6])"),
    (("encoder", "coupling", "+"), [4, 4, 0.0],
     "encoder.coupling: the coupling matrix C is singular (det 0): joint angles q = C x "
     "cannot be turned back into counts"),
    (("encoder", "gain_counts_per_rad", 2), 0,
     "encoder.gain_counts_per_rad[2]: 0 counts/rad: an encoder gain must be non-zero (its "
     "sign is the direction), at least 1 count/rad"),
    (("encoder", "gain_counts_per_rad", 2), math.nan,
     "encoder.gain_counts_per_rad[2]: Input should be a finite number, got nan"),
    (("dh", 1, "a_m"), math.nan, "dh[1].a_m: Input should be a finite number, got nan"),
    (("dh", 1, "a_m"), 900,
     "dh[1].a_m: 900 m is not a plausible link length a (in [-5, 5] m): a value in mm "
     "written as m?"),
    (("dh", 3, "d_m"), 1e308, "dh[3].d_m: 1e+308 m is not a plausible link offset d (in [-5, 5] m)"),
    (("dh", 1, "alpha_rad"), 90,
     "dh[1].alpha_rad: 90 rad is not a plausible angle (in [-6.28319, 6.28319] rad): "
     "degrees written as rad?"),
    (("controller", "home_counts"), [8388608] * 3,
     "controller.home_counts: must hold 6 counts, one per joint, got 3"),
    (("controller", "home_counts", 2), 1 << 24,
     "controller.home_counts[2]: 16777216 is outside the 24-bit encoder range 0..16777215"),
    (("encoder", "offset_counts", 0), -1,
     "encoder.offset_counts[0]: -1 is outside the 24-bit encoder range 0..16777215"),
    (("controller", "trip_step_counts"), 10,
     "controller.trip_step_counts: 10 counts is below the step limit max_step_counts = 51: "
     "every step would trip"),
    (("joint_limits_deg", 1), [80, -135],
     "joint_limits_deg[1]: [80, -135] deg: the lower limit must be below the upper"),
    (("encoder", "bits"), "24", "encoder.bits: Input should be a valid integer, got '24'"),
    (("encoder", "bits"), True, "encoder.bits: Input should be a valid integer, got True"),
    (("controller", "tick_s"), 0, "controller.tick_s: 0 s is not a plausible control tick "
                                  "(in [0.0001, 1] s)"),
    (("repeatability_mm",), -0.07, "repeatability_mm: -0.07 mm is not a plausible "
                                   "repeatability (in [0, 5] mm)"),
    (("inverse_kinematics",), "magic",
     "inverse_kinematics: 'magic' is not a known solver ('spherical_wrist', 'analytic', "
     "'numeric' or null: chosen from the geometry)"),
    (("dh",), DELETE, "dh: give the chain one way: either dh (standard DH rows) or chain "
                      "(modified DH with Hayati's beta, base and flange), not neither"),
    (("encoder", "gains"), [1] * 6, "encoder.gains: unknown key (misspelt? the format is in "
                                    "docs/FORMATS.md)"),
    (("name",), DELETE, "name: missing (required)"),
    (("dh",), "six rows", "dh: Input should be a valid list, got 'six rows'"),
])
def test_robot_checks(tmp_path, path, value, message):
    assert refused(tmp_path, load_robot, mutated(ROBOT, path, value)) == message


def test_an_ill_conditioned_coupling_is_refused(tmp_path):
    # C[1, 2] = 10, C[2, 1] = 0.099999999: det = 1e-8 (not singular), condition number
    # ~ (10.05 * 10.05) / 1e-8 ~ 1e10 (numpy's, checked against it below)
    doc = mutated(ROBOT, ("encoder", "coupling"), [[1, 2, 10.0], [2, 1, 0.099999999]])
    C = np.eye(6)
    C[0, 1], C[1, 0] = 10.0, 0.099999999
    cond = np.linalg.cond(C)
    assert 1e9 < cond < 2e10 and abs(np.linalg.det(C) - 1e-8) < 1e-15
    assert refused(tmp_path, load_robot, doc) == (
        f"encoder.coupling: the coupling matrix C is ill-conditioned (condition number "
        f"{cond:.3g}): counts from joint angles would be noise")
    assert refused(tmp_path, load_robot, mutated(ROBOT, ("encoder", "coupling", 0, 2), 1e308)) == (
        "encoder.coupling[0][2]: 1e+308 is not a plausible coupling coefficient (in [-10, 10])")


def test_a_non_singular_coupling_term_is_accepted(tmp_path):
    # C[4, 5] = 1 with C[5, 4] = -0.0111: det(C) = 1 + 0.0111, far from singular
    r = load_robot(_write(tmp_path / "r.json",
                          mutated(ROBOT, ("encoder", "coupling", "+"), [4, 5, 1.0])))
    assert r.coupling[3, 4] == 1.0
    assert np.linalg.det(r.coupling) == pytest.approx(1 + 0.01111111, abs=1e-12)


def _write(p: Path, doc) -> Path:
    p.write_text(json.dumps(doc))
    return p


def test_robot_values_reach_the_robot(tmp_path):
    r = load_robot("mc70")
    np.testing.assert_array_equal(r.d, [0.6, 0, 0, 0.99, 0, 0.175])
    np.testing.assert_array_equal(r.gains, ROBOT["encoder"]["gain_counts_per_rad"])
    assert r.coupling[4, 3] == -0.01111111 and r.coupling[5, 4] == -0.016949152
    assert r.home_counts.dtype == np.int64 and r.encoder_bits == 24
    assert r.repeatability_m == pytest.approx(7e-5, rel=1e-12)
    assert np.allclose(np.rad2deg(r.limits[5]), [-450, 450])


# ----- scenes ---------------------------------------------------------------------------------

@pytest.mark.parametrize("path, value, message", [
    (("plates",), "plate_a", "plates: Input should be a valid list, got 'plate_a'"),
    (("plates",), [], "plates: a scene needs at least one plate"),
    (("sensor", "range_mm"), "65-95", "sensor.range_mm: Input should be a valid list, got '65-95'"),
    (("sensor", "range_mm"), [95, 65],
     "sensor.range_mm: [95, 65] mm is not a plausible laser window (increasing, within "
     "[1, 10000] mm)"),
    (("sensor", "range_mm"), [0.065, 0.095],
     "sensor.range_mm: [0.065, 0.095] mm is not a plausible laser window (increasing, within "
     "[1, 10000] mm): a value in m written as mm?"),
    (("sensor", "range_mm"), [-5, 95],
     "sensor.range_mm: [-5, 95] mm is not a plausible laser window (increasing, within "
     "[1, 10000] mm)"),
    (("sensor", "origin_m"), [0.0257, -0.0725, 90.0],
     "sensor.origin_m: |sensor origin| = 90 m is not plausible (at most 1 m): a value in mm "
     "written as m?"),
    (("plates", 1, "n_tilde"), [0, 0, 0],
     "plates[1].n_tilde: n~ = 0 describes no plane (n~ . p = 1 needs n~ != 0)"),
    (("plates", 1, "n_tilde"), [0, 0, 1e6],
     "plates[1].n_tilde: |n~| = 1e+06 1/m puts the plane 1e-06 m from the base origin "
     "(plausible: 0.01 to 100 m; n~ cannot describe a plane through the origin)"),
    (("plates", 2, "corner_m"), [0.3805, -1.0568, 1.8283],
     "plates[2].corner_m: plate 'plate_c': the corner is 548.6 mm off the plane n~ . p = 1 "
     "(at most 5 mm): corner and n~ describe different plates"),
    # 84 mm off (issue 25: accepted before), and just past the tolerance either side
    (("plates", 0, "corner_m"), [0.729, 0.737, 0.484 + 0.084 * 3.7691 / 3.62708],
     "plates[0].corner_m: plate 'plate_a': the corner is 84.0 mm off the plane n~ . p = 1 "
     "(at most 5 mm): corner and n~ describe different plates"),
    (("plates", 0, "corner_m"), [0.729, 0.737, 0.484 - 0.0051 * 3.7691 / 3.62708],
     "plates[0].corner_m: plate 'plate_a': the corner is 5.1 mm off the plane n~ . p = 1 "
     "(at most 5 mm): corner and n~ describe different plates"),
    (("plates", 2, "x_axis"), [0.515464, -1.649485, -1.134021],
     "plates[2].x_axis: lies along the plate's normal: it gives no in-plane direction"),
    (("plates", 2, "face"), 0,
     "plates[2].face: 0: the measured face looks along +n~ (1) or -n~ (-1)"),
    (("plates", 0, "size_m"), [350, 250],
     "plates[0].size_m[0]: 350 m is not a plausible plate size (<= 10 m): a value in mm "
     "written as m? (and 1 more problem)"),
    (("plates", 0, "thicknes_m"), 0.012,
     "plates[0].thicknes_m: unknown key (misspelt? the format is in docs/FORMATS.md)"),
    (("positions", "home_counts"), [8388608] * 3,
     "positions.home_counts: must hold 6 counts, one per joint, got 3"),
    (("positions", "home_counts", 1), 1 << 24,
     "positions.home_counts[1]: 16777216 is outside NACHI MC70-01's 24-bit encoder range "
     "0..16777215"),
    (("sampling", "distance_mm"), [60, 90],
     "sampling.distance_mm: [60, 90] mm is not within the laser window [65, 95] mm "
     "(sensor.range_mm)"),
    (("robot",), 5, "robot: Input should be a valid string, got 5"),
])
def test_scene_checks(tmp_path, path, value, message):
    assert refused(tmp_path, load_scene, mutated(SCENE, path, value)) == message


def test_scene_that_is_an_array(tmp_path):
    assert refused(tmp_path, load_scene, [SCENE]) == "a scene is a JSON object {...}, not an array"


def test_scene_plate_beyond_reach(tmp_path):
    # plate_a moved 10 m up: its plane and corner together
    far = mutated(mutated(SCENE, ("plates", 0, "n_tilde"), [0.0, 0.0, 0.1]),
                  ("plates", 0, "corner_m"), [0.0, 0.0, 10.0])
    assert refused(tmp_path, load_scene, far) == (
        "plates[0]: the plate is at least 9.57 m from the base, beyond NACHI MC70-01's reach "
        "(2.83 m flange + 0.288 m sensor and beam)")
    # the reach is the DH chain's: sum of sqrt(a^2 + d^2) over the links
    r = ROBOT["dh"]
    assert sum(math.hypot(j["a_m"], j["d_m"]) for j in r) == pytest.approx(2.8334658, abs=1e-7)


def test_scene_robot_that_does_not_exist(tmp_path):
    msg = refused(tmp_path, load_scene, mutated(SCENE, ("robot",), "nope"))
    assert msg == f"robot: {data_path('models', 'nope', 'robot.json')}: file not found (robot description)"


def test_shipped_scenes_load_unchanged():
    s = load_scene("three_plates")
    assert [p.name for p in s.plates] == ["plate_a", "plate_b", "plate_c", "plate_d"]
    assert [p.face for p in s.plates] == [1, -1, -1, 1]
    ref, = s.references  # the stepped block: plate_d 200 mm beyond plate_a, parallel
    assert ref.plates == (0, 3) and ref.separation_m == 0.2 and ref.std_m == 5e-6
    assert s.laser_range_mm == (65.0, 95.0) and s.distance_mm == (70.0, 90.0)
    np.testing.assert_array_equal(s.plates[2].x_hint, [0.9684, 0.2055, 0.1413])
    assert load_scene("appendix_d").cone_deg == 25.0
    assert load_scene("obstacle_test").obstacles[0].name == "fin"


# ----- parameter and result files -------------------------------------------------------------

@pytest.mark.parametrize("path, value, message", [
    (("joint_offsets_rad", 1), 1e308,
     "joint_offsets_rad[1]: 1e+308 rad is not a plausible joint offset (in [-3.14159, "
     "3.14159] rad)"),
    (("joint_offsets_rad", 1), 45,
     "joint_offsets_rad[1]: 45 rad is not a plausible joint offset (in [-3.14159, 3.14159] "
     "rad): degrees written as rad?"),
    (("planes", 0, "n_tilde"), [0, 0, 0],
     "planes[0].n_tilde: n~ = 0 describes no plane (n~ . p = 1 needs n~ != 0)"),
    (("sensor", "origin_m"), [35.436, -76.901, 177.291],
     "sensor.origin_m: |sensor origin| = 196.473 m is not plausible (at most 1 m): a value "
     "in mm written as m?"),
    (("sensor", "phi_y_rad"), None, "sensor.phi_y_rad: Input should be a valid number, got None"),
    (("sensor", "origin_mm"), [0, 0, 0],
     "sensor.origin_mm: unknown key (misspelt? the format is in docs/FORMATS.md)"),
    (("planes",), [], "planes: needs at least one plane"),
    (("format",), "planecal-poses/1",
     "format: 'planecal-poses/1' is not a parameter file (planecal-params/1 or "
     "planecal-result/1)"),
])
def test_params_checks(tmp_path, path, value, message):
    assert refused(tmp_path, load_params, mutated(PARAMS, path, value)) == message


def test_params_round_trip_with_format_and_old_files(tmp_path):
    old = load_params(repo_path("examples", "table10_params.json"))  # no format field
    p = tmp_path / "p.json"
    save_params(p, old)
    written = json.loads(p.read_text())
    assert written["format"] == "planecal-params/1"
    assert {k: v for k, v in written.items() if k != "format"} == params_to_dict(old)
    np.testing.assert_array_equal(load_params(p).to_vector(), old.to_vector())


def test_result_document_is_a_parameter_file_with_provenance(tmp_path):
    samples = repo_path("examples", "seed_samples.tsv")
    params = nominal_params(load_scene("thesis_final"))
    k = params.n_planes
    result = {**params_to_dict(params),
              "std": {"joint_offsets_rad": [None, 1e-4, 1e-4, 1e-4, 1e-4, None],
                      "planes": [{"n_tilde": [1e-3] * 3}] * k,
                      "sensor": {"origin_m": [1e-4] * 3, "phi_y_rad": 1e-3, "phi_z_rad": 1e-3}},
              "residual_rms_mm": 0.01, "residual_rms_initial_mm": 1.2, "residual_max_mm": 0.03,
              "iterations": 5, "converged": True, "outliers": [], "samples_used": 5,
              "identifiability": {"sigma_mm": 0.01}, "free": ["delta2"]}
    prov = provenance([("samples", samples)], scene="thesis_final", robot="NACHI MC70-01")
    doc = result_document(result, prov)
    assert doc["format"] == RESULT_FORMAT
    import hashlib
    assert prov["inputs"] == [{"role": "samples", "path": str(samples),
                               "sha256": hashlib.sha256(samples.read_bytes()).hexdigest(),
                               "bytes": samples.stat().st_size}]
    out = tmp_path / "r.json"
    out.write_text(json.dumps(doc))
    np.testing.assert_array_equal(load_params(out).to_vector(), params.to_vector())
    with pytest.raises(ValueError, match=r"^result: residual_rms_mm: Input should be a finite "
                                         r"number, got nan$"):
        result_document({**result, "residual_rms_mm": math.nan}, prov)
    assert ResultFile.model_validate(doc).provenance.scene == "thesis_final"


# ----- pose lists -----------------------------------------------------------------------------

@pytest.mark.parametrize("path, value, message", [
    (("format",), "nope", "format: 'nope' is not a planecal pose list (planecal-poses/1)"),
    (("format",), DELETE, "format: missing (required)"),
    (("plates",), [0], "plates: 1 plate numbers for 2 poses (counts)"),
    (("counts", 1), [1, 2, 3, 4, 5], "counts[1]: must hold 6 counts, one per joint, got 5"),
    (("counts", 0, 3), 1 << 24,
     "counts[0][3]: 16777216 is not a plausible 24-bit encoder count (in [0, 16777215])"),
    (("counts", 0, 3), 8388608.5, "counts[0][3]: Input should be a valid integer, got 8388608.5"),
    (("plates", 1), -1, "plates[1]: -1 is not a plausible plate index (0-based) (in [0, 99])"),
])
def test_pose_list_checks(tmp_path, path, value, message):
    assert refused(tmp_path, load_poses, mutated(POSES, path, value)) == message


def test_pose_list_values(tmp_path):
    qe, plate, doc = load_poses(_write(tmp_path / "p.json", POSES))
    assert qe.dtype == np.int64 and qe.shape == (2, 6) and qe[1, 0] == 8388000
    assert list(plate) == [0, 0] and doc["seed"] == 0


# ----- run sidecars ---------------------------------------------------------------------------

@pytest.mark.parametrize("path, value, message", [
    (("format",), "planecal-run/0",
     "format: 'planecal-run/0' is not a planecal run sidecar (planecal-run/1)"),
    (("settings", "pose", "cone_deg"), "30",
     "settings.pose.cone_deg: Input should be a valid number, got '30'"),
    (("settings", "laser", "buffer_len"), 0,
     "settings.laser.buffer_len: 0 readings is not a plausible buffer length (in [1, 1000000] "
     "readings)"),
    (("settings", "pose", "plate_choice"), "nearest",
     "settings.pose.plate_choice: 'nearest' is not a plate choice (round_robin, random)"),
    (("settings", "collision_checking"), "yes",
     "settings.collision_checking: Input should be a valid boolean, got 'yes'"),
    (("samples_target",), 0,
     "samples_target: 0 samples is not a plausible sample target (in [1, 10000000] samples)"),
    (("status",), "finished",
     "status: 'finished' is not a run status (running, complete, stopped, gave_up, error)"),
    (("rng_state", "state", "inc"), -1,
     "rng_state.state.inc: -1 is not a plausible 128-bit state word (in [0, "
     f"{2**128 - 1}])"),
    (("rng_state", "bit_generator"), "MT19937",
     "rng_state.bit_generator: Input should be 'PCG64', got 'MT19937'"),
    (("seed",), 1.5, "seed: Input should be a valid integer, got 1.5"),
    (("settings",), DELETE, "settings: missing (required)"),
    (("scene",), "thesis\nfinal", "scene: 'thesis\\nfinal' holds a control character (newline, "
                                  "tab, NUL, ...): not allowed in a name or a path"),
])
def test_sidecar_checks(tmp_path, path, value, message):
    assert refused(tmp_path, load_sidecar, mutated(SIDECAR, path, value), "RUN.tsv.json") == message


def test_sidecar_feeds_run_settings(tmp_path):
    from planecal.sampling.run import RunSettings
    side = load_sidecar(_write(tmp_path / "RUN.tsv.json", SIDECAR))
    assert side == SIDECAR  # the plain dict the run works with
    rs = RunSettings.from_sidecar(side)
    assert rs.scene == "thesis_final" and rs.samples == 3 and rs.pose.distance_mm == (70.0, 90.0)
    rng = np.random.default_rng()
    rng.bit_generator.state = side["rng_state"]  # a validated state numpy accepts


# ----- reading: bounds that apply to every JSON file ------------------------------------------

READERS = [(load_robot, "robot description"), (load_scene, "scene"),
           (load_params, "parameter file"), (load_poses, "pose list"),
           (load_sidecar, "run sidecar")]


@pytest.mark.parametrize("reader, what", READERS)
def test_json_reading_bounds(tmp_path, reader, what):
    deep = "[" * 100_000 + "]" * 100_000
    assert refused(tmp_path, reader, deep) == f"JSON nested more than 64 levels deep, not a {what}"
    shallow_deep = '{"a": ' + "[" * 100 + "]" * 100 + "}"
    assert refused(tmp_path, reader, shallow_deep) == f"JSON nested more than 64 levels deep, not a {what}"
    assert refused(tmp_path, reader, '{"x": 1' + "0" * 400 + "}") == (
        "x: an integer of 401 digits, too large for any quantity")
    assert refused(tmp_path, reader, '{"x": 1' + "0" * 5000 + "}") == (
        "invalid JSON: Exceeds the limit (4300 digits) for integer string conversion")
    (tmp_path / "cut.json").write_text('{"x": [1, 2,')
    with pytest.raises(InputError, match=r"cut.json:1: invalid JSON: Expecting value$"):
        reader(tmp_path / "cut.json")
    (tmp_path / "bin.json").write_bytes(b'{"x": "\x00"}')
    with pytest.raises(InputError, match=rf"bin.json: binary data \(NUL bytes at byte 7\), not a {what}$"):
        reader(tmp_path / "bin.json")
    (tmp_path / "latin.json").write_bytes(b'{"name": "\xe9"}')
    with pytest.raises(InputError, match=rf"latin.json: not UTF-8 text \(byte 10\), not a {what}$"):
        reader(tmp_path / "latin.json")
    (tmp_path / "dir.json").mkdir()
    with pytest.raises(InputError, match=rf"dir.json: is a directory, not a {what}$"):
        reader(tmp_path / "dir.json")
    big = tmp_path / "big.json"
    big.write_bytes(b'{"x": "' + b" " * (16 * 2**20) + b'"}')
    with pytest.raises(InputError, match=rf"big.json: larger than 16 MiB, not a {what}$"):
        reader(big)


@pytest.mark.parametrize("reader, what", READERS)
def test_dev_zero_is_refused_at_once(reader, what):
    with pytest.raises(InputError, match=rf"^/dev/zero: binary data \(NUL bytes at byte 0\), not a {what}$"):
        reader("/dev/zero")


def test_invalid_json_names_the_line(tmp_path):
    p = tmp_path / "p.json"
    p.write_text('{\n"joint_offsets_rad": [0, 0,\n')
    with pytest.raises(InputError, match=r"p.json:3: invalid JSON: Expecting value$"):
        load_params(p)
    p.write_text('{"joint_offsets_rad": [NaN, 0, 0, 0, 0, 0]}')
    with pytest.raises(InputError, match=r"p.json: joint_offsets_rad\[0\]: Input should be a "
                                         r"finite number, got nan \(and 2 more problems\)$"):
        load_params(p)


# ----- published JSON Schemas -----------------------------------------------------------------

def test_published_schemas_are_current():
    """docs/schemas/ is what scripts/export_schemas.py makes from the models now."""
    folder = repo_path("docs", "schemas")
    docs = schema_documents()
    assert sorted(p.name for p in folder.glob("*.schema.json")) == sorted(docs)
    for name, text in docs.items():
        assert (folder / name).read_text() == text, "run scripts/export_schemas.py"


SHIPPED = [("planecal-robot/1", "models/mc70/robot.json"), ("planecal-robot/1", "models/ur5/robot.json"),
           ("planecal-scene/1", "scenes/thesis_final.json"), ("planecal-scene/1", "scenes/three_plates.json"),
           ("planecal-scene/1", "scenes/appendix_d.json"), ("planecal-scene/1", "scenes/obstacle_test.json"),
           ("planecal-params/1", "examples/table10_params.json")]


@pytest.mark.parametrize("fmt, rel", SHIPPED)
def test_an_independent_validator_accepts_the_shipped_files(fmt, rel):
    schema = json.loads(repo_path("docs", "schemas", schema_file_name(fmt)).read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(json.loads(repo_path(rel).read_text()))


@pytest.mark.parametrize("fmt, doc", [("planecal-poses/1", POSES), ("planecal-run/1", SIDECAR)])
def test_an_independent_validator_agrees_on_written_files(fmt, doc):
    schema = json.loads(repo_path("docs", "schemas", schema_file_name(fmt)).read_text())
    v = jsonschema.Draft202012Validator(schema)
    v.validate(doc)
    # and refuses what the models refuse for the same reason (type, length, range)
    bad = mutated(doc, ("format",), 5)
    assert not v.is_valid(bad)


@pytest.mark.parametrize("path, value", [
    (("dh", 5), DELETE), (("encoder", "bits"), "24"), (("dh", 1, "a_m"), 900),
    (("controller", "home_counts"), [1, 2, 3]), (("encoder", "gains"), [1] * 6),
    (("encoder", "coupling", "+"), [7, 4, 0.1]),
])
def test_schema_and_model_refuse_the_same_robot_files(tmp_path, path, value):
    schema = json.loads(repo_path("docs", "schemas", schema_file_name("planecal-robot/1")).read_text())
    doc = mutated(ROBOT, path, value)
    assert not jsonschema.Draft202012Validator(schema).is_valid(doc)
    with pytest.raises(InputError):
        load_robot(_write(tmp_path / "r.json", doc))


def test_every_model_has_a_schema_file():
    assert {schema_file_name(f) for f in MODELS} == set(schema_documents())
