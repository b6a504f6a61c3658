"""Issue 31 (never a worse robot, a verdict from one calibration) and issue 30 item 8 (the
accuracy estimate on other arms). Peers: refits without each fold (the closed-form held-out
residuals against ``accuracy.cross_validate``), the twin's own true model (the estimate
against the true tool-point error), validate (a refusal against the validated AP), fresh
samples of a world planecal's error model does not draw (level 3 against level 2)."""
import json

import numpy as np
import pytest

from off_model import OffModelWorld
from planecal.cli import main
from planecal.estimation.accuracy import cross_validate
from planecal.estimation.calibrate import CalibrationSettings, calibrate
from planecal.estimation.fit import linearized
from planecal.estimation.selection import HeldOut
from planecal.estimation.tool import tool_point
from planecal.estimation.verdict import refusal, verdict_of
from planecal.io.samples import write_samples
from planecal.model.encoder import counts_to_joints
from planecal.model.measurement import backlash_sides, predict
from planecal.model.scene import load_scene, nominal_params
from planecal.studies.rehearsal import RehearsalSettings, twin_samples
from planecal.twin.world import true_params


def realistic_run(scene_name: str, truth: int, samples: int = 150):
    """``planecal rehearse --scene S --seed T``'s run of the realistic world T (validate's
    calibration set of truth T): (scene, qe, d_m, plate, direction, world, options)."""
    scene = load_scene(scene_name)
    st = RehearsalSettings(scene=scene_name, samples=samples, errors="realistic", seed=truth,
                           truth_seed=truth)
    world, opts = st.world(0)
    qe, d, plate, direction, _ = twin_samples(scene, world, st, truth, opts)
    return scene, qe, d, plate, direction, world, opts


@pytest.fixture(scope="module")
def one_plate():
    return realistic_run("thesis_final", 100)


def test_the_closed_form_held_out_residuals_are_refits_without_each_fold(one_plate):
    """The selection's held-out residuals (the fit linearised at its solution, each fold
    left out in closed form) against ten real calibrations, each without one fold: the
    same folds, the same residuals to the linearisation's second order."""
    scene, qe, d, plate, direction, _, _ = one_plate
    for level in ("offsets", "full"):
        st = CalibrationSettings(level=level, select=False)
        cal = calibrate(scene.robot, qe, d, nominal_params(scene), plate, st, direction)
        lin = linearized(cal.result)
        held = HeldOut(lin).residuals(np.ones(len(lin.names), bool),
                                      np.ones(len(lin.rp), bool))[0]
        real = cross_validate(scene.robot, qe, d, nominal_params(scene), plate, st, direction)
        # offsets: 0.3 % of the residuals' rms; full (its weak directions move more): 3 %
        tol = {"offsets": 3e-3, "full": 3e-2}[level]
        assert np.sqrt(np.mean((held - real) ** 2)) < tol * np.sqrt(np.mean(real ** 2)), level


def true_tool_error_mm(scene, cal, qe, direction, world, opts) -> float:
    """The calibration's tool point against the twin's own (its true model), rms over the
    samples' poses [mm]."""
    robot = scene.robot
    q = counts_to_joints(robot, qe)
    side = backlash_sides(robot, q, direction)
    truth = true_params(robot, world, opts, fold_flange=True)
    e = (tool_point(robot, q, cal.params, side, scene.standoff_m)
         - tool_point(robot, q, truth, side, scene.standoff_m))
    return float(np.sqrt(np.mean(np.sum(e ** 2, 1))) * 1e3)


@pytest.fixture(scope="module")
def ur5_runs():
    return {t: realistic_run("ur5_table", t) for t in (100, 103)}


@pytest.mark.parametrize("scene_name, truth, level", [
    ("ur5_table", 100, "offsets"), ("ur5_table", 103, "offsets"),
    ("ur5_table", 103, "nonkinematic"), ("thesis_final", 100, "offsets"),
    ("thesis_final", 100, "nonkinematic")])
def test_the_estimate_is_within_2x_of_the_true_tool_error(scene_name, truth, level, one_plate,
                                                          ur5_runs):
    """Issue 30 item 8: the calibration's own estimate at the tool (the verdict's, against
    the reference model) within 2x of its true error on the UR5 and the MC70; the
    covariance alone at the fit's residual level (the estimate before issue 31:
    ``covariance_mm``) is more than 2x low on the UR5's offsets fits (its link geometry
    absorbed into the offsets: a bias no covariance holds). (On the UR5 the level-3 estimate
    is high rather than low: 16 of validate's truths 100-119 within 2x of AP.)"""
    run = one_plate if scene_name == "thesis_final" else ur5_runs[truth]
    scene, qe, d, plate, direction, world, opts = run
    cal = calibrate(scene.robot, qe, d, nominal_params(scene), plate,
                    CalibrationSettings(level=level), direction, scene.references)
    true = true_tool_error_mm(scene, cal, qe, direction, world, opts)
    said = verdict_of(cal).tool_mm
    assert 0.5 * true <= said <= 2.0 * true, (said, true)
    if scene_name == "ur5_table" and level == "offsets":
        from planecal.estimation.accuracy import accuracy
        old = accuracy(scene.robot, cal, qe, d, plate, direction).covariance_mm
        assert old < 0.5 * true, (old, true)


def test_refusal_reads_the_verdict_of_a_result_document():
    comps = [{"level": "offsets", "tool_mm": 0.6}, {"level": "full + compliance",
                                                     "tool_mm": 0.4}]
    doc = {"verdict": {"grade": "worse", "reasons": ["full is no better than offsets"],
                       "comparisons": comps}}
    why = refusal(doc)
    assert why.startswith("refused by its verdict: full is no better than offsets")
    assert why.endswith("calibrate with --level full --compliance") and "--force" not in why
    for grade in ("good", "uncertain"):
        assert refusal({"verdict": {"grade": grade}}) is None
    assert refusal({}) is None and refusal({"verdict": None}) is None


@pytest.fixture(scope="module")
def full_result(tmp_path_factory, one_plate):
    """``planecal calibrate --level full`` of the one-plate cell's realistic run (truth 100):
    its residuals fall (0.06 -> 0.04 mm), its tool point goes millimetres off."""
    scene, qe, d, plate, _, _, _ = one_plate
    folder = tmp_path_factory.mktemp("full")
    run = folder / "r.tsv"
    write_samples(run, qe, d * 1e3)
    out = folder / "full.json"
    assert main(["calibrate", str(run), "--level", "full", "--out", str(out),
                 "--no-history"]) in (0, 1)
    return folder, out


def test_a_level_no_better_than_offsets_says_so_and_every_writer_refuses_it(full_result,
                                                                            capsys):
    folder, out = full_result
    doc = json.loads(out.read_text())
    v = doc["verdict"]
    assert v["grade"] == "worse" and v["worse_than"] == ["offsets"]
    off = v["comparisons"][0]
    assert off["level"] == "offsets" and v["tool_mm"] > 2 * off["tool_mm"]
    for argv, written in (
            (["export", str(out), "--format", "offsets", "--out", str(folder / "e.json"),
              "--no-history"], folder / "e.json"),
            (["urdf", "--params", str(out), "--out", str(folder / "f.urdf"), "--no-meshes"],
             folder / "f.urdf")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"{out}: refused by its verdict: full is no better than offsets" in err
        assert "calibrate with --level offsets: not a calibration to use" in err
        assert "(--force writes it anyway)" in err
        assert not written.exists()
    targets = folder / "t.csv"
    targets.write_text("q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg\n0,0,0,0,30,0\n")
    assert main(["compensate", str(targets), "--params", str(out), "--out",
                 str(folder / "c.tsv"), "--samples", str(folder / "r.tsv")]) == 2
    assert "refused by its verdict" in capsys.readouterr().err
    assert main(["export", str(out), "--format", "offsets", "--out", str(folder / "e.json"),
                 "--no-history", "--force"]) == 0
    assert json.loads((folder / "e.json").read_text())


@pytest.mark.parametrize("scene_name, truth", [("thesis_final", 100), ("ur5_table", 101)])
def test_no_level_exports_a_result_validate_finds_worse_than_offsets(scene_name, truth):
    """Issue 31's done-when on the default one-plate cell and on the UR5: every level
    whose validated AP at the tool is above the offsets-only calibration's is refused by
    its verdict (the levels of ``validate --level full`` and ``--level nonkinematic``, on
    the same poses)."""
    from planecal.studies.validation.settings import ValidationSettings
    from planecal.studies.validation.truths import TruthJob, validate_truth
    worse = 0
    for level in ("full", "nonkinematic"):
        v = validate_truth(TruthJob(scene_name, "realistic", truth,
                                    settings=ValidationSettings(cycles=5, gauge=False),
                                    calibration=CalibrationSettings(level=level)))
        rows = v["levels"]
        assert rows[0]["level"] == "offsets"
        for r in rows[1:]:
            if r["ap_after_tool_mm"] > rows[0]["ap_after_tool_mm"]:
                worse += 1
                assert r["verdict"] == "worse", (level, r["level"], r["ap_after_tool_mm"],
                                                 rows[0]["ap_after_tool_mm"])
    assert worse >= 1  # the truth has a level worse than offsets: the test can fail


def test_level3_without_directions_predicts_fresh_samples_no_worse_than_level2():
    """A world planecal's error model does not draw (``off_model``: UR5-class geometry,
    gear terms at orders robot.json does not name, a joint-coupled deformation; no
    direction column): level 3 with every family and its geometry prior (the selection
    off, as before issue 31) predicts fresh samples of the world 1.2x worse than level 2;
    with the selection, which takes level 2's model where that predicts the held-out
    samples significantly better and puts the tool no further off, no worse (the same
    model, fitted in level 3's layout: to its rounding)."""
    scene = load_scene("three_plates")
    world = OffModelWorld(scene, 6)
    qe, d, plate = world.samples(6)
    qf, df, pf = world.samples(1006)

    def predicts(st):
        cal = calibrate(scene.robot, qe, d, nominal_params(scene), plate, st, None,
                        scene.references)
        return float(np.sqrt(np.mean((predict(scene.robot, qf, cal.params, pf) - df) ** 2)))
    level2 = predicts(CalibrationSettings(level="full"))
    assert predicts(CalibrationSettings(level="nonkinematic", select=False)) > 1.15 * level2
    assert predicts(CalibrationSettings(level="nonkinematic")) <= level2 * (1 + 1e-6)


def test_the_band_stated_is_the_draws_band_placed_where_validate_found_ap():
    """``verdict._band``: the draws' 10-90 % band (log-normal draws: exp(mu +- 1.2816
    sigma)), its ends at ``CALIBRATED``'s half-widths from its geometric middle (the
    percentiles of where validate's AP fell), in mm from draws in m; a run that reads its
    poses again (a planned list) gets its own (``readings``)."""
    from planecal.estimation.verdict import CALIBRATED, _band, readings
    mu, sigma = np.log(1e-4), 0.4
    ap = np.exp(mu + sigma * np.random.default_rng(3).standard_normal(200_000))
    half = 1.2816 * sigma
    assert CALIBRATED == {"single": (-1.45, 1.1), "repeated": (-1.4, 0.7)}
    for read, (a, b) in CALIBRATED.items():
        lo, hi = _band(ap, read)
        assert lo == pytest.approx(0.1 * np.exp(a * half), rel=0.01)
        assert hi == pytest.approx(0.1 * np.exp(b * half), rel=0.01)
    qe = np.arange(60).reshape(10, 6) * 1000
    assert readings(qe) == "single"
    assert readings(np.concatenate([qe[:4], qe[:4], qe[4:6]])) == "repeated"  # 8 of 10
    assert readings(np.concatenate([qe, qe[:2]])) == "single"  # 4 of 12
    # a real robot settles a count or two apart at a pose it reads again
    wobble = np.concatenate([qe[:4], qe[:4] + np.array([2, -1, 0, 3, 0, -2]), qe[4:6]])
    assert readings(wobble) == "repeated"
