"""Issue 24: the cell's history (planecal.history) and the drift check's statistics.

The store's own tests are test_history_store.py, test_history_content.py and
test_history_place.py (issue 32; both backends); here: a file that is not a history, the
exceedance test against an
enumeration of every arrangement (its null distribution is combinatorics, not a formula
of ours) and against heavy-tailed draws (its false-alarm rate holds whatever the errors'
distribution), and the commands end to end on synthetic samples of the fit's own model:
calibrate, check (in control, and delta3 moved by 0.5 mrad), export, history list, show,
diff and rollback, on SQLite and on PostgreSQL (tests/history_db.py) with the same
assertions.
"""
from __future__ import annotations

import itertools
import json
import math
from math import comb

import numpy as np
import pytest
from scipy import stats

from conftest import INITIAL, perturbed, synthetic_counts
from planecal.cli import main
from history_db import db  # noqa: F401  (the fixture: SQLite and PostgreSQL)
from planecal.estimation.drift import exceedance_test, parameter_changes
from planecal.io.samples import write_samples

# ----- the store --------------------------------------------------------------------------

def test_a_file_that_is_not_a_history_is_refused_in_one_line(tmp_path, capsys):
    bad = tmp_path / "notes.db"
    bad.write_text("not a database")
    assert main(["history", "list", "--history", str(bad)]) == 2
    assert "not an SQLite database" in capsys.readouterr().err
    assert main(["history", "list", "--history", str(tmp_path / "none" / "h.db")]) == 2
    assert "no history here yet" in capsys.readouterr().err
    assert main(["history", "list", "--history", str(tmp_path / "fresh.db")]) == 2
    assert "no history here yet" in capsys.readouterr().err
    assert not (tmp_path / "fresh.db").exists()  # nothing written on a refusal
    result = tmp_path / "x.json"  # (a result that exists: a missing one is said first)
    result.write_text("{}")
    assert main(["export", str(result), "--history", str(tmp_path / "none" / "h.db")]) == 2
    assert "does not exist" in capsys.readouterr().err


# ----- the statistics --------------------------------------------------------------------

def test_exceedance_distribution_is_the_count_over_every_arrangement():
    """Under H0 every placement of the m run values among the n + m is equally likely:
    P(X >= x) by enumerating all C(n + m, m) of them equals the test's p."""
    n, m = 7, 4
    k = (n + 1) // 2
    counts = np.zeros(m + 1)
    for run_ranks in itertools.combinations(range(n + m), m):  # ranks, 0 = largest
        cal = [r for r in range(n + m) if r not in run_ranks]
        kth = cal[k - 1]  # the k-th largest calibration value's rank
        counts[sum(r < kth for r in run_ranks)] += 1
    tail = np.cumsum(counts[::-1])[::-1] / comb(n + m, m)
    cal_values = np.arange(n, dtype=float)[::-1] * 2 + 0.5  # any distinct values
    for x in range(m + 1):
        run = np.r_[np.full(x, 1e3), np.full(m - x, -1e3)]
        t = exceedance_test(cal_values, run, 0.05)
        assert t.exceed == x and t.p == pytest.approx(tail[x], rel=1e-12)


def test_exceedance_false_alarm_rate_holds_for_heavy_tailed_errors():
    """Errors with Student-t tails of 2 degrees of freedom (no finite variance): the
    Gaussian F test of the variance ratio alarms far above alpha, the exceedance test at
    its attained size (150 calibration, 30 run values, 20000 trials, within 3 sigma)."""
    rng = np.random.default_rng(7)
    trials = 20000
    a, b = np.abs(rng.standard_t(2, (trials, 150))), np.abs(rng.standard_t(2, (trials, 30)))
    first = [exceedance_test(a[i], b[i], 0.01) for i in range(20)]
    size, critical = first[0].attained_alpha, first[0].critical
    threshold = np.sort(a, axis=1)[:, 150 - 75]  # the 75th largest of each trial
    x = np.sum(b > threshold[:, None], axis=1)
    assert [t.exceed for t in first] == list(x[:20])
    assert [t.rejected for t in first] == list(x[:20] >= critical)
    alarms = int(np.sum(x >= critical))
    assert 0.003 < size <= 0.01
    assert abs(alarms - trials * size) < 3 * math.sqrt(trials * size)
    f_alarms = np.sum(stats.f.sf(np.mean(b ** 2, 1) / np.mean(a ** 2, 1), 30, 150) <= 0.01)
    assert f_alarms > 5 * trials * 0.01


def test_diff_flags_a_change_beyond_both_stds_with_the_bonferroni_limit():
    a = {"delta2": (1e-3, 1e-5), "delta3": (2e-3, 3e-5), "o_x": (0.03, None), "n1_z": (3.5, 1e-3)}
    b = {"delta2": (1.02e-3, 1e-5), "delta3": (2.5e-3, 4e-5), "o_x": (0.03, None),
         "n1_z": (3.5005, 1e-3)}
    changes, limit = parameter_changes(a, b, 0.01)
    assert limit == pytest.approx(stats.norm.isf(0.01 / 6))  # 3 parameters with a std
    by = {c.name: c for c in changes}
    assert by["delta3"].z == pytest.approx(5e-4 / 5e-5) and by["delta3"].significant
    assert by["delta2"].z == pytest.approx(2e-5 / math.sqrt(2e-10))
    assert not by["delta2"].significant and by["o_x"].z is None
    assert by["n1_z"].std == pytest.approx(math.sqrt(2) * 1e-3)


# ----- the commands on the fit's own model ------------------------------------------------

@pytest.fixture(scope="module")
def cell(robot, tmp_path_factory):
    """A calibration run and three short runs of synthetic samples: two in the world of
    the calibration, one with delta3 moved by +0.5 mrad; and the calibration's poses
    measured again in the moved world (a recalibration after "maintenance")."""
    from planecal.model.measurement import predict
    rng = np.random.default_rng(5)
    truth = perturbed(INITIAL, rng)
    moved = truth.copy()
    moved.joint_offsets = truth.joint_offsets + [0, 0, 5e-4, 0, 0, 0]
    d = tmp_path_factory.mktemp("cell")

    def noisy(dist):
        return (dist + rng.normal(0, 5e-6, len(dist))) * 1e3

    def run(name, n, params):
        qe, dist = synthetic_counts(robot, params, n, rng)
        write_samples(d / name, qe, noisy(dist))
        return str(d / name), qe

    cal, qe = run("cal.tsv", 150, truth)
    write_samples(d / "recal.tsv", qe, noisy(predict(robot, qe, moved)))
    return (d, cal, run("ok1.tsv", 30, truth)[0], run("ok2.tsv", 30, truth)[0],
            run("moved.tsv", 30, moved)[0], str(d / "recal.tsv"))


def test_calibrate_check_export_and_the_history_of_a_week(cell, db, capsys, monkeypatch):
    """The same outputs on SQLite and on PostgreSQL (issue 32)."""
    d, cal, ok1, ok2, moved, _ = cell
    monkeypatch.chdir(d)
    db = db.where
    h = ["--history", db]
    assert main(["calibrate", cal, "--out", "r.json", *h, "--note", "monday"]) == 0
    assert "history: entry 1 (calibrate: ok)" in capsys.readouterr().out
    for run in (ok1, ok2):
        assert main(["check", run, "--against", "r.json", *h]) == 0
        assert "IN CONTROL" in capsys.readouterr().out
    assert main(["check", moved, "--against", "r.json", *h, "--json",
                 "--out", "verdict.json"]) == 1
    cap = capsys.readouterr()
    v = json.loads(cap.out)
    assert v == json.loads((d / "verdict.json").read_text())
    assert v["format"] == "planecal-check/1"
    assert v["verdict"] == "drifted" and v["moved"] == ["delta3"]
    p = v["explanation"]["parameters"][0]
    assert abs(p["amount"] - 5e-4) < 4 * p["std"] and p["std"] < 2e-5
    assert v["explanation"]["explains"] and v["against_entry"] == 1
    # the two runs that passed are the reference now: runs after one calibration are alike
    assert v["reference"] == {"kind": "runs", "runs": [ok1, ok2], "samples": 60,
                              "meaning": "earlier in-control runs of this result"}
    assert main(["check", ok1, "--against", "r.json", "--no-history", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["reference"]["kind"] == "calibration"
    assert "history: entry 4 (check: drifted)" in cap.err  # stdout holds the JSON only
    assert main(["export", "r.json", "--out", "fd11.json", *h]) == 0
    capsys.readouterr()
    assert main(["history", "list", "--history", db]) == 0
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if ln[:1].isdigit()]
    assert [ln.split()[2] for ln in lines] == ["calibrate", "check", "check", "check", "export"]
    assert "drifted" in lines[3] and "moved: J3 (delta3)" in lines[3] and "monday" in lines[0]
    assert main(["history", "show", "5", "--history", db, "--json"]) == 0
    e = json.loads(capsys.readouterr().out)
    assert e["against"] == 1 and e["output"] == "fd11.json"
    assert {i["role"] for i in e["inputs"]} == {"result", "scene", "robot"}


def test_recalibration_diff_and_rollback(cell, db, capsys, monkeypatch):
    d, cal, _, _, _, recal = cell
    monkeypatch.chdir(d)
    db = db.where
    h = ["--history", db]
    assert main(["calibrate", cal, "--out", "a.json", *h]) == 0
    assert main(["calibrate", recal, "--out", "b.json", *h, "--note", "after maintenance"]) == 0
    capsys.readouterr()
    assert main(["history", "diff", "1", "2", "--history", db, "--json"]) == 0
    diff = json.loads(capsys.readouterr().out)
    assert diff["significant"] == ["delta3"]
    c3 = next(c for c in diff["changes"] if c["name"] == "delta3")
    assert abs(c3["change"] - 5e-4) < 4 * c3["std"]
    before = (d / "a.json").read_bytes()
    assert main(["history", "rollback", "1", "--out", "back.json", *h]) == 0
    assert "history: entry 3 (rollback: ok)" in capsys.readouterr().out
    assert main(["export", "a.json", "--out", "direct.json", "--no-history"]) == 0
    back, direct = (json.loads((d / f).read_text()) for f in ("back.json", "direct.json"))
    assert back["qe0_counts"] == direct["qe0_counts"] and back["result"] == "history entry 1"
    assert main(["history", "rollback", "1", "--out", "a.json", *h]) == 2  # not over a result
    assert (d / "a.json").read_bytes() == before
    assert main(["history", "diff", "1", "3", "--history", db]) == 2  # 3 is no calibration
    assert "entry 3 is a rollback, not a calibration" in capsys.readouterr().err


def test_diff_of_two_models_of_the_same_samples_tests_nothing(tmp_path, capsys, monkeypatch):
    """issue 33: history diff 1 2 of an offsets fit and a full fit of the same samples
    called them "two independent calibrations" and flagged J5 significant: the same draws
    fitted by two models, whose offsets mean different things (level offsets' absorb what
    level full's geometry holds). The diff says so and tests nothing; two fits of one model
    to independent samples are still tested."""
    monkeypatch.chdir(tmp_path)
    h = ["--history", str(tmp_path / "h.db")]
    assert main(["rehearse", "--out", "r.tsv", "-q"]) == 0
    assert main(["calibrate", "r.tsv", "--out", "a.json", "-q", *h]) == 0
    assert main(["calibrate", "r.tsv", "--out", "b.json", "--level", "full", "-q", *h]) == 0
    capsys.readouterr()
    assert main(["history", "diff", "1", "2", *h]) == 0
    out = capsys.readouterr().out
    assert "A and B fit the same samples with two models (level offsets; level full)" in out
    assert "independent" not in out and "SIGNIFICANT" not in out and "no significance test" in out
    assert main(["history", "diff", "1", "2", *h, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["independent"] is False and d["significant"] == []
    assert all(c["std"] is None and c["z"] is None for c in d["changes"])
    # the same model, another run of the same cell: two independent calibrations, tested
    assert main(["rehearse", "--out", "s.tsv", "--seed", "5", "-q"]) == 0
    assert main(["calibrate", "s.tsv", "--out", "c.json", "-q", *h]) == 0
    capsys.readouterr()
    assert main(["history", "diff", "1", "3", *h, "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["independent"] is True and d["basis"] is None
    assert all(c["std"] is not None for c in d["changes"] if c["name"] in ("delta2", "o_x"))


def test_check_flags_no_suspect_on_a_run_in_control(tmp_path, capsys, monkeypatch):
    """issue 33: check on an in-control run of the realistic twin listed J4 as "significant
    yes" (z -3.3 beyond the Bonferroni limit 3.14): a lone offset fitted to 40 residuals
    that hold the model's mismatch, not a move. The distribution-free test decides; on a
    run in control the z's rank the suspects and flag none."""
    monkeypatch.chdir(tmp_path)
    assert main(["rehearse", "--out", "cal.tsv", "--truth-out", "t.json", "-q"]) == 0
    assert main(["calibrate", "cal.tsv", "--out", "r.json", "-q", "--no-history"]) == 0
    assert main(["rehearse", "--out", "day.tsv", "--truth", "t.json", "--seed", "12",
                 "--samples", "40", "-q"]) == 0
    capsys.readouterr()
    assert main(["check", "day.tsv", "--against", "r.json", "--no-history", "--json"]) == 0
    v = json.loads(capsys.readouterr().out)
    assert v["verdict"] == "in_control" and v["moved"] == []
    assert max(abs(s["z"]) for s in v["suspects"]) > v["z_limit"]  # the case that was flagged
    assert not any(s["significant"] for s in v["suspects"])
    assert main(["check", "day.tsv", "--against", "r.json", "--no-history"]) == 0
    out = capsys.readouterr().out
    assert " yes " not in out and "the run is in control: none moved" in out
