"""Issue 24 on the realistic twin: compare (twin against real) on runs of one pose list,
the drift check on short runs in a calibration's world and in one with delta3 moved by
0.5 mrad (a truth file edited by hand, as a user injects a drift), and what a truth file
edited in place does to the runs made in it.

The chi-square verdict of compare is checked against its distribution by simulation
under the noise model; the worlds are the twin's (``rehearse --truth``), the runs small
(12 poses for compare, 30 for a check) so that the file costs seconds.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.cli import main

mujoco = pytest.importorskip("mujoco")


def rehearse(*argv) -> None:
    assert main(["rehearse", "-q", *argv]) == 0


@pytest.fixture(scope="module")
def worlds(tmp_path_factory):
    """t0: the realistic world of truth seed 3 (rehearse --truth-out); t1: a copy with
    delta3 moved by +0.5 mrad by hand; a planned list of 14 poses; the list rehearsed
    twice in t0 (noise seeds 4, 5) and once in t1."""
    d = tmp_path_factory.mktemp("worlds")
    rehearse("--samples", "14", "--seed", "3", "--out", str(d / "base.tsv"),
             "--truth-out", str(d / "t0.json"))
    t1 = json.loads((d / "t0.json").read_text())
    t1["joint_offsets_rad"][2] += 5e-4
    (d / "t1.json").write_text(json.dumps(t1, indent=2))
    assert main(["plan", "--samples", "14", "--candidates", "200", "--jobs", "1", "-q",
                 "--out", str(d / "P.json")]) == 0
    for name, world, seed in (("a", "t0", 4), ("b", "t0", 5), ("c", "t1", 6)):
        rehearse("--poses", str(d / "P.json"), "--truth", str(d / f"{world}.json"),
                 "--seed", str(seed), "--out", str(d / f"{name}.tsv"))
    return d


def test_compare_same_world_agrees_moved_world_differs_and_names_j3(worlds, capsys,
                                                                     monkeypatch):
    d = worlds
    monkeypatch.chdir(d)
    assert main(["compare", "b.tsv", "--rehearsal", "a.tsv", "--json"]) == 0
    same = json.loads(capsys.readouterr().out)
    assert same["verdict"] == "agree" and same["max_count_difference"] == 0
    assert same["test"]["p_value"] > 0.01 and same["explanation"] is None
    assert main(["compare", "c.tsv", "--rehearsal", "a.tsv", "--out", "v.json",
                 "--report", "rep", "--rrd", "cmp.rrd"]) == 1
    out = capsys.readouterr().out
    v = json.loads((d / "v.json").read_text())
    assert v["format"] == "planecal-compare/1"
    assert v["verdict"] == "differ" and v["explained_by"] == ["delta3"]
    p = v["explanation"]["parameters"][0]
    assert abs(p["amount"] - 5e-4) < max(4 * p["std"], 2e-5)
    assert "explained by: J3 (delta3)" in out and "DIFFER" in out
    # the report shows the document's numbers
    html = (d / "rep" / "index.html").read_text()
    assert f"p = {v['test']['p_value']:.3g}" in html and "J3 (delta3)" in html
    for png in ("distances", "differences", "z"):
        assert (d / "rep" / f"{png}.png").stat().st_size > 10_000
    from planecal.present.rerun import blueprint_views, summarize
    paths = {e[0] for e in summarize(d / "cmp.rrd")}
    assert {"/samples/points", "/rehearsal/points", "/series/difference_mm/difference",
            "/series/distance_mm/run", "/series/difference_mm/explained",
            "/compare/info"} <= paths
    assert {view["class"] for view in blueprint_views(d / "cmp.rrd")} >= {"3D", "TimeSeries"}


def test_compare_refuses_runs_of_other_poses_in_one_line(worlds, capsys, monkeypatch):
    monkeypatch.chdir(worlds)
    assert main(["compare", "base.tsv", "--rehearsal", "a.tsv"]) == 2  # random poses
    assert "not two runs of the same poses" in capsys.readouterr().err
    from planecal.io.samples import read_samples, write_samples
    s = read_samples(worlds / "a.tsv")
    qe = s.qe.copy()
    qe[4, 2] += 9
    write_samples(worlds / "other.tsv", qe, s.d_mm, s.plate)
    assert main(["compare", "other.tsv", "--rehearsal", "a.tsv", "--out", "x.json"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "sample 5 is not a.tsv's sample 5" in err
    assert "J3's counts differ by 9" in err and not (worlds / "x.json").exists()


def test_compare_false_alarm_rate_under_its_noise_model(robot):
    """Differences drawn from the noise model itself: the chi-square verdict alarms at its
    alpha (400 simulated pairs, within 3 sigma), as scipy's chi2 says it must."""
    from conftest import INITIAL, SEED_QE
    from planecal.estimation.agreement import Paired, compare_runs
    from planecal.estimation.noise import repeatability_sigma, sample_variance
    from planecal.model.levels import layout_for
    from planecal.model.measurement import predict_with_jacobian
    rng = np.random.default_rng(11)
    qe = SEED_QE[np.arange(20) % 5] + rng.integers(-20000, 20000, (20, 6))
    layout = layout_for(robot, 1, "full", True)
    js = repeatability_sigma(robot)
    d0, J = predict_with_jacobian(robot, qe, INITIAL, np.zeros(20, int), layout)
    sd = np.sqrt(2 * sample_variance(robot, J[:, layout.slice("joint_offsets")], js, 1e-6, True))
    alarms, trials = 0, 400
    for _ in range(trials):
        pr = Paired(qe, np.zeros(20, int), d0 + rng.normal(0, sd), d0, 0)
        ag = compare_runs(robot, INITIAL, layout, pr, js, 1e-6, 0.05, ("delta3",))
        alarms += not ag.agree
    assert abs(alarms - 0.05 * trials) < 3 * math.sqrt(trials * 0.05 * 0.95)


def test_drift_check_on_the_twin_passes_in_its_world_and_names_j3_when_moved(worlds, robot):
    """A calibration of 150 samples in t0 (rehearsal settings, set at rest where the
    errors allow), ten short runs of 30 in t0: at most one alarm (alpha 0.01; more than
    one has probability 0.004); one short run in t1: drifted, J3 named, 0.5 mrad within
    4 std."""
    from planecal.estimation.calibrate import calibrate
    from planecal.estimation.drift import FittedResult, check_run
    from planecal.model.scene import load_scene, nominal_params
    from planecal.present.calibration import document
    from planecal.studies.rehearsal import RehearsalSettings, twin_samples
    from planecal.twin.world import WorldRef
    scene = load_scene("thesis_final")
    w0, o0 = WorldRef("realistic", None, str(worlds / "t0.json")).build(scene)
    w1, o1 = WorldRef("realistic", None, str(worlds / "t1.json")).build(scene)
    qe, d, plate, _, _ = twin_samples(scene, w0, RehearsalSettings(samples=150), 100, o0)
    cal = calibrate(robot, qe, d, nominal_params(scene), plate)
    fr = FittedResult.of(document(cal, robot), robot, "result")
    short = RehearsalSettings(samples=30)
    alarms = sum(check_run(fr, (qe, d, plate), twin_samples(scene, w0, short, 200 + k, o0)[:3])
                 .drifted for k in range(10))
    assert alarms <= 1
    chk = check_run(fr, (qe, d, plate), twin_samples(scene, w1, short, 300, o1)[:3])
    assert chk.drifted and chk.moved[0] == "delta3"
    e = chk.explanation
    assert abs(e.amounts[0] - 5e-4) < 4 * e.stds[0]


def test_a_truth_file_edited_in_place_is_not_the_world_of_its_runs(worlds, tmp_path):
    """Injecting a drift by editing the truth file a run was made in would silently move
    that run into another world: its sidecar's hash refuses it, and a copy is the way."""
    import shutil

    from planecal.jobs.runs import read_run, run_world
    d = tmp_path
    for f in ("t0.json", "a.tsv", "a.tsv.json"):
        shutil.copy(worlds / f, d / f)
    side = json.loads((d / "a.tsv.json").read_text())
    side["twin"]["truth_file"] = str(d / "t0.json")
    (d / "a.tsv.json").write_text(json.dumps(side))
    run = read_run(d / "a.tsv")
    scene = run.scene
    ref = run_world(run, d / "t0.json")
    ref.build(scene)
    doc = json.loads((d / "t0.json").read_text())
    doc["joint_offsets_rad"][2] += 5e-4
    (d / "t0.json").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="not the truth file the run .* was made in"):
        run_world(run, d / "t0.json")
    with pytest.raises(InputError, match="changed since the run was made"):
        run_world(run).build(scene)
