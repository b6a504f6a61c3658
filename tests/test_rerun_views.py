"""The blueprint of every recording kind (rehearsal, real run, calibration, Monte Carlo,
bootstrap, validate), read back from the .rrd file with rerun's own reader: which views it
lays out, what they show, that the entities they show are in the recording, that the 3D
view starts on the plate and the tool and hides the rejections. Plus the numbers the study
charts carry (histograms recomputed with numpy). Headless: no viewer is started."""
from __future__ import annotations


import numpy as np
import pytest

rr = pytest.importorskip("rerun")
twin_mod = pytest.importorskip("planecal.twin")

from planecal.present.rerun.common import blueprint_views, plate_face_normal, summarize  # noqa: E402
from planecal.io.samples import Samples  # noqa: E402
from planecal.model.scene import load_scene, nominal_params  # noqa: E402
from planecal.twin.synthetic import synthetic_samples  # noqa: E402
from planecal.twin.truth import draw_truth  # noqa: E402

SPATIAL = {"/cell/**", "/robot/**", "/laser/**", "/samples/**"}


pytestmark = pytest.mark.usefixtures("rerun_home")  # rerun off the real ~/.config (conftest)


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


@pytest.fixture(scope="module")
def truth(scene):
    return draw_truth(scene, 0)


@pytest.fixture(scope="module")
def data(scene, truth):
    """40 noise-free samples of the analytic model at the truth, and their fit."""
    from planecal.estimation.calibrate import calibrate_samples
    qe, d, plate = synthetic_samples(scene, truth, 40, np.random.default_rng(5))
    s = Samples(qe, d * 1e3, plate, np.arange(1, len(d) + 1), 0)
    cal = calibrate_samples(scene.robot, s, nominal_params(scene))
    return {"samples": s, "fit": cal.result, "calibration": cal, "qe": qe, "d_m": d,
            "plate": plate}


def entities(path) -> set[str]:
    return {e for e, *_ in summarize(path)}


def check_views(path, expected: dict[str, int]) -> list[dict]:
    """The blueprint's views by class (at least these counts); every view's origin (or a
    query's root) is an entity, or the parent of one, of the recording."""
    views = blueprint_views(path)
    have = {}
    for v in views:
        have[v["class"]] = have.get(v["class"], 0) + 1
    for cls, n in expected.items():
        assert have.get(cls, 0) >= n, (cls, have)
    ents = entities(path)
    for v in views:
        roots = [q.removesuffix("/**") for q in v["contents"] if q != "$origin/**"] \
            or [v["origin"]]
        for r in roots:
            r = v["origin"] if r == "$origin" else r
            assert r == "/" or any(e == r or e.startswith(r.rstrip("/") + "/") for e in ents), \
                (v["name"], r)
    return views


def check_space_view(views, scene, path, hidden_rejections=False, tool=None):
    """One 3D view, showing the cell, robot, beam and samples, whose camera starts on the
    first plate (and the tool) from the side of the measured face, within 1.2 m."""
    sv = [v for v in views if v["class"] == "3D"]
    assert len(sv) == 1
    v = sv[0]
    assert SPATIAL <= set(v["contents"]), v["contents"]
    assert ("/rejected" in v["hidden"]) == hidden_rejections
    eye = v["eye"]
    assert eye is not None
    c = scene.plates[0].center()
    n = plate_face_normal(scene)
    target, pos = eye["look_target"], eye["position"]
    assert np.linalg.norm(target - c) < 0.15  # between the plate and the tool
    if tool is not None:
        # the tool and the plate centre are both within 30 deg of the viewing direction
        look = (target - pos) / np.linalg.norm(target - pos)
        for p in (c, tool):
            u = (p - pos) / np.linalg.norm(p - pos)
            assert np.degrees(np.arccos(np.clip(u @ look, -1, 1))) < 30
    assert 0.3 < np.linalg.norm(pos - target) < 1.2
    assert (pos - c) @ n > 0.3  # in front of the measured face
    ents = entities(path)
    for e in ("/cell/plates/plate", "/robot/tool", "/robot/tool/laser_head", "/laser/beam",
              "/samples/points"):
        assert e in ents, e
    return v


# ----- sampling runs ---------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["rehearsal", "real"])
def test_sampling_blueprints(scene, tmp_path, kind):
    from planecal.present.rerun import sampling_observer
    twin = twin_mod.Twin(scene, seed=1, options=twin_mod.TwinOptions.exact())
    obs = sampling_observer(tmp_path / f"{kind}.rrd", scene,
                            twin=twin if kind == "rehearsal" else None)
    counts = np.asarray(twin.current_counts, np.int64)
    cur = np.tile(counts, (10, 1))
    obs.on_ticks(1, np.zeros((10, 6), np.int64), cur, cur, np.full(10, 80.0))
    obs.on_sample(0, counts, 80.0, 0)
    obs.close()
    assert obs.error is None
    views = check_views(obs.path, {"3D": 1, "TimeSeries": 5, "TextDocument": 1, "TextLog": 1})
    v = check_space_view(views, scene, obs.path, hidden_rejections=True)
    assert ("rehearsal" in v["name"]) == (kind == "rehearsal")
    assert "/rejected/**" in v["contents"]
    names = {w["name"]: w for w in views}
    overview = [w for w in views if w["name"].startswith("whole run")]
    assert len(overview) == 1
    assert set(overview[0]["contents"]) == {"/series/laser_mm", "/series/model_error_mm"}
    info = [w for w in views if w["class"] == "TextDocument"][0]
    assert info["origin"] == "/run/info"
    assert "joint angles [deg]" in names and "events" in names
    assert "/samples/all" in entities(obs.path)  # the whole run, written at close


# ----- calibration -----------------------------------------------------------------------

def test_calibration_blueprint_and_log_axis(scene, data, tmp_path):
    from planecal.present.rerun import log_fit_to_file
    from planecal.present.rerun.common import tool_point
    from planecal.present.rerun.fit import pose_shown
    from test_rerun_log import read_rrd

    res, s = data["fit"], data["samples"]
    path = log_fit_to_file(tmp_path / "cal.rrd", data["calibration"], s, scene)
    views = check_views(path, {"3D": 1, "TimeSeries": 1, "BarChart": 3, "TextDocument": 3})
    tool = tool_point(scene, res.params, s.qe[pose_shown(res)])
    check_space_view(views, scene, path, tool=tool)
    conv = [v for v in views if v["class"] == "TimeSeries"][0]
    assert conv["origin"] == "/fit/log10" and "log10" in conv["name"]
    rec = read_rrd(path)
    rms = [r["Scalars:scalars"][0] for r in rec["/fit/log10/rms"]["rows"]]
    np.testing.assert_allclose(rms, np.log10([h.rms_m * 1e3 for h in res.history]), rtol=1e-12)
    # the histogram titles carry their value ranges
    after = [v for v in views if v["origin"] == "/fit/hist/error_after"][0]
    e = res.residuals_m * 1e3
    assert f"{e.min():.4g} to {e.max():.4g}" in after["name"]
    info = rec["/fit/info"]["rows"][-1]["TextDocument:text"][0]
    assert "sample colour" in info and "model error after calibration" in info
    # the robot is posed at the sample shown: its beam ends at that sample's hit point
    beam = rec["/laser/beam"]["rows"][-1]
    o, vec = np.array(beam["Arrows3D:origins"][0]), np.array(beam["Arrows3D:vectors"][0])
    hit = np.array([np.ravel(rec["/samples/points"]["rows"][-1][f"hit_{c}_m"])[pose_shown(res)]
                    for c in "xyz"])
    np.testing.assert_allclose(o + vec, hit, atol=1e-6)
    np.testing.assert_allclose(o, tool, atol=1e-6)


# ----- studies ---------------------------------------------------------------------------

def test_montecarlo_blueprint_and_histograms(scene, tmp_path):
    from scipy import stats

    from planecal.present.rerun.studies import Z_BINS, log_montecarlo, order_pose_set
    from planecal.studies.montecarlo import MCSettings, analyze, run_many
    from planecal.studies.rehearsal import synthetic_noisy_samples
    from test_rerun_log import read_rrd, tensor

    st = MCSettings(scene=str(scene.path), samples=30, runs=4, seed=10, mode="synthetic",
                    errors="ideal")
    res = analyze(run_many(st, 1, quiet=True), st)
    res["settings"]["scene"] = scene.name
    world, _ = st.world(0)
    qe, d, plate, _, _ = synthetic_noisy_samples(scene, world.params, st, st.seed)
    poses = order_pose_set(qe, d, plate, world.params, "run 0's samples")
    path = log_montecarlo(tmp_path / "mc.rrd", res, scene, poses)
    views = check_views(path, {"3D": 1, "TextDocument": 1, "BarChart": len(res["free"])})
    check_space_view(views, scene, path)
    charts = {v["origin"]: v for v in views if v["class"] == "BarChart"}
    assert {f"/normalized_error/{n}" for n in res["free"]} <= set(charts)
    rec = read_rrd(path)
    E, C = np.array(res["run_errors"]), np.array(res["run_crb_std"])
    for i, n in enumerate(res["free"]):
        row = rec[f"/normalized_error/{n}/observed"]["rows"][-1]
        np.testing.assert_array_equal(tensor(row["BarChart:values"]),
                                      np.histogram(E[:, i] / C[:, i], Z_BINS)[0])
        np.testing.assert_allclose(tensor(row["BarChart:abscissa"]),
                                   0.5 * (Z_BINS[1:] + Z_BINS[:-1]))  # a value axis
        exp = tensor(rec[f"/normalized_error/{n}/expected_normal"]["rows"][-1]["BarChart:values"])
        np.testing.assert_allclose(exp, 4 * np.diff(stats.norm.cdf(Z_BINS)))


def test_bootstrap_blueprint_lays_out_every_parameter(scene, data, tmp_path):
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.present.rerun.studies import log_bootstrap
    from planecal.studies.bootstrap import BootstrapSettings, Pool, bootstrap

    problem = Pool(scene.robot, data["qe"], data["d_m"], data["plate"], nominal_params(scene),
                   CalibrationSettings())
    res = bootstrap(problem, BootstrapSettings((20, 30), 3, 0), quiet=True)
    path = log_bootstrap(tmp_path / "boot.rrd", res, scene, problem)
    views = check_views(path, {"3D": 1, "TextDocument": 1, "TimeSeries": len(res["free"])})
    check_space_view(views, scene, path)
    series = {v["origin"] for v in views if v["class"] == "TimeSeries"}
    assert series == {f"/spread/{n}" for n in res["free"]}  # every parameter, one chart each


def test_validate_blueprint(scene, truth, data, tmp_path):
    from planecal.estimation.compensate import CalibratedModel
    from planecal.safety.collision import CollisionWorld
    from planecal.present.rerun.studies import log_validate
    from planecal.studies.validation import ValidationSettings, validate
    from test_rerun_log import read_rrd, tensor

    st = ValidationSettings(cycles=2, gauge_repeats=1)
    res = data["fit"]
    v = validate(scene, truth, CalibratedModel(scene.robot, res.params), data["qe"], st,
                 CollisionWorld(scene, 0.01), res)
    path = log_validate(tmp_path / "val.rrd", v, scene, res.params, data["qe"], data["d_m"],
                        data["plate"])
    views = check_views(path, {"3D": 1, "TextDocument": 1, "BarChart": 3})
    check_space_view(views, scene, path)
    rec = read_rrd(path)
    assert set(v["iso"]["models"]) == {"nominal", "offsets", "floor: offsets", "oracle"}
    for model, m in v["iso"]["models"].items():  # at the tool point
        model = rr.escape_entity_path_part(model)  # "floor: offsets"
        np.testing.assert_allclose(tensor(rec[f"/ap/{model}"]["rows"][-1]["BarChart:values"]),
                                   m["tool"]["ap_mm"])
        arrows = np.array(rec[f"/iso/ap_x100/{model}"]["rows"][-1]["Arrows3D:vectors"])
        np.testing.assert_allclose(arrows, 100 * np.asarray(m["tool"]["ap_xyz_mm"]) * 1e-3,
                                   rtol=1e-6, atol=1e-7)
