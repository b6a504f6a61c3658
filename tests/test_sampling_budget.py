"""A robot-time budget (``--robot-minutes``, ``collect.Budget``): a run ends complete where
its next pose might not fit. Peers: the same run without a budget (a budget only cuts it
short), the command against the study's rehearsal (the same samples, the same robot time),
the two stages of a validation's aimed pose list (one budget for both)."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.io.samples import read_samples
from planecal.model.scene import load_scene
from planecal.studies.rehearsal import RehearsalSettings, staged_samples, twin_samples

pytest.importorskip("planecal.twin")


def rehearse(folder, name, *extra):
    out = folder / f"{name}.tsv"
    assert main(["rehearse", "--out", str(out), "--samples", "8", "--seed", "3", *extra]) == 0
    return read_samples(out), json.loads((folder / f"{name}.tsv.json").read_text())


def test_a_budget_cuts_the_run_short_and_the_study_cuts_it_at_the_same_sample(tmp_path,
                                                                             capsys):
    whole, side_w = rehearse(tmp_path, "whole")
    cut, side = rehearse(tmp_path, "cut", "--robot-minutes", "2.6")
    capsys.readouterr()
    assert side_w["samples"] == 8 and side_w["robot_time_s"] > 150
    # complete, said why, within the budget; the samples are the whole run's first ones
    assert side["status"] == "complete" and side["settings"]["robot_minutes"] == 2.6
    assert side["stop_reason"] == ("the robot-time budget of 2.6 min is spent (the next pose "
                                   "might not fit): 4 of the 8 samples asked for")
    assert side["robot_time_s"] <= 156.0
    assert np.array_equal(cut.qe, whole.qe[:4]) and np.array_equal(cut.d_mm, whole.d_mm[:4])
    # the study's rehearsal of the same world and seed (validate's truth 3 at seed 0)
    st = RehearsalSettings(scene="thesis_final", samples=8, errors="realistic", seed=3,
                           truth_seed=3, robot_minutes=2.6)
    world, opts = st.world(0)
    qe, d, _, _, _, robot = twin_samples(load_scene("thesis_final"), world, st, 3, opts, True)
    assert np.array_equal(qe, cut.qe) and np.allclose(d * 1e3, cut.d_mm, atol=1e-5)
    assert robot["robot_time_s"] == pytest.approx(side["robot_time_s"], abs=1e-6)


def test_resume_takes_a_new_budget_counting_every_session(tmp_path, capsys):
    _, first = rehearse(tmp_path, "r", "--robot-minutes", "1")
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--out", str(out), "--resume", "--robot-minutes", "3"]) == 0
    capsys.readouterr()
    side = json.loads((tmp_path / "r.tsv.json").read_text())
    assert first["samples"] < side["samples"] < 8 and side["sessions"] == 2
    assert side["settings"]["robot_minutes"] == 3.0 and side["robot_time_s"] <= 180.0
    # the budget spent, a resume without a new one takes nothing more
    assert main(["rehearse", "--out", str(out), "--resume"]) == 0
    capsys.readouterr()
    again = json.loads((tmp_path / "r.tsv.json").read_text())
    assert again["samples"] == side["samples"] and "budget" in again["stop_reason"]


def test_an_aimed_pose_lists_two_stages_share_one_budget(tmp_path, capsys):
    """``staged_samples`` (validate --poses --aim-samples): the aiming run's robot time
    counts against the list's; the aiming run is the same with or without the budget."""
    scene = load_scene("thesis_final")
    plan, _ = rehearse(tmp_path, "plan")  # 8 poses measured once: a list to visit again
    capsys.readouterr()
    poses = tuple((tuple(int(v) for v in c), 0, 0) for c in plan.qe)
    runs = {}
    for minutes in (None, 8.0):
        st = RehearsalSettings(scene="thesis_final", samples=8, errors="realistic", seed=5,
                               truth_seed=5, poses=poses, robot_minutes=minutes)
        world, opts = st.world(0)
        runs[minutes] = staged_samples(scene, world, st, 5, opts, True, aim_samples=20)
    whole, cut = runs[None], runs[8.0]
    assert len(whole[0]) == 28 and whole[5]["robot_time_s"] > 8.0 * 60
    assert 20 < len(cut[0]) < 28 and cut[5]["robot_time_s"] <= 8.0 * 60
    assert cut[5]["aim_samples"] == 20 and np.array_equal(cut[0], whole[0][:len(cut[0])])


def test_a_budget_is_a_positive_number_of_minutes(tmp_path, capsys):
    for bad in ("0", "-1", "nan"):
        assert main(["rehearse", "--out", str(tmp_path / "x.tsv"), "--robot-minutes", bad]) == 2
        assert "argument --robot-minutes: " in capsys.readouterr().err
    assert not (tmp_path / "x.tsv").exists()
    given = [tmp_path / n for n in ("result.json", "truth.json", "run.tsv")]
    for f in given:
        f.write_text("{}")
    code = main(["validate", "--calibrated", str(given[0]), "--truth", str(given[1]), "--run",
                 str(given[2]), "--robot-minutes", "5", "--no-history"])
    err = capsys.readouterr().err
    assert code == 2 and "--robot-minutes budgets the rehearsed calibration runs" in err


def test_a_truth_whose_budget_leaves_too_few_samples_fails_alone():
    """validate's truth: a run its budget cut short of a calibration is that truth's
    failure, with the reason (the other truths stand), not the validation's end."""
    from planecal.studies.common import cached_scene
    from planecal.studies.validation import TruthJob, validate_truth
    from planecal.twin.profile import DEFAULT_PROFILE, load_profile

    scene = cached_scene("thesis_final")
    errors = str(load_profile(DEFAULT_PROFILE, scene.robot).path)
    v = validate_truth(TruthJob(scene=str(scene.path), errors=errors, truth_seed=3,
                                robot_minutes=1.0))
    assert v["truth_seed"] == 3
    assert "samples cannot determine" in v["failed"], v


def test_a_plan_the_budget_cannot_fit_is_dropped_whole():
    """``collect``: the plan that does not fit is not taken, nor are its rejected draws
    counted; the random state stays before it, so a resume with more budget draws it
    again and counts them once."""
    from planecal.sampling.collect import Budget, Cursor, MemoryRecorder, Tally, collect
    from planecal.sampling.planner import Plan

    class OnePlan:
        pure = False

        def index_matters(self):
            return False

        def plan(self, q_start, index, rng_state, budget, back=(), aim=None):
            out = Plan(index, q_start, [("collision", None, "collision (target)")],
                       {"n": rng_state["n"] + 1})
            out.q, out.qe_goal = np.ones(6), np.zeros(6, np.int64)
            return out

    cursor, tally, rec = Cursor(np.zeros(6), {"n": 0}), Tally(), MemoryRecorder()
    collect(OnePlan(), None, rec, 5, cursor, tally, 500,
            budget=Budget(60.0, lambda: 55.0, lambda plan: 6.0))
    assert tally.status == "complete" and "budget of 1 min is spent" in tally.reason
    assert tally.samples == 0 and tally.rejected["collision"] == 0
    assert cursor.rng_state == {"n": 0}
