"""Issue 32: no silently wrong verdict, no refusal after output.

A drift check of a run with one gross error (a reading 8 mm off among 30) was "in control"
(one value barely moves a median test's count); a truth file of another robot, written
before truth files recorded their robot, ran a UR5's world on the MC70 until 500 poses
were rejected; a resumed sweep of other settings printed its planning before refusing.
"""
from __future__ import annotations

import json
from pathlib import Path

from test_history_store import BASE, cli, one_line


def _run(tmp_path: Path, edit: float = 0.0, row: int = 3) -> Path:
    """The last 30 samples of the corpus's run (a rehearsal in the result's world), with
    sample ``row``'s laser reading moved by ``edit`` mm (staying in the laser window)."""
    lines = (BASE / "run.tsv").read_text().splitlines()
    rows = lines[-30:]
    f = rows[row].split("\t")
    f[6] = f"{float(f[6]) + edit:.6f}"
    rows[row] = "\t".join(f)
    p = tmp_path / f"short{edit:+g}.tsv"
    p.write_text(lines[0] + "\n" + "\n".join(rows) + "\n")
    return p


def test_a_gross_error_is_not_in_control(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rc, out, _ = cli(capsys, "check", _run(tmp_path), "--against", BASE / "result.json",
                     "--no-history", "--json")
    base = json.loads(out)
    assert rc == 0 and base["verdict"] == "in_control" and not base.get("gross_errors")
    d = float((BASE / "run.tsv").read_text().splitlines()[-30:][3].split("\t")[6])
    edit = 8.0 if d < 86 else -8.0
    rc, out, _ = cli(capsys, "check", _run(tmp_path, edit), "--against", BASE / "result.json",
                     "--no-history", "--json")
    v = json.loads(out)
    assert rc == 1 and v["verdict"] == "drifted" and v["exit_code"] == 1
    assert [g["sample"] for g in v["gross_errors"]] == [4]
    assert abs(v["gross_errors"][0]["model_error_mm"] + edit) < 0.5  # predicted - measured
    assert v["test"]["exceedances"] <= base["test"]["exceedances"] + 1  # the median test: blind
    rc, out, _ = cli(capsys, "check", _run(tmp_path, edit), "--against", BASE / "result.json",
                     "--no-history")
    assert rc == 1 and "gross errors" in out and "sample 4" in out


def test_an_older_truth_file_of_another_robot_is_refused(tmp_path, capsys, monkeypatch):
    """A UR5 truth file as planecal wrote it before truth files recorded their robot: its
    true geometry is no error profile's draw of the MC70's."""
    monkeypatch.chdir(tmp_path)
    rc, _, _ = cli(capsys, "rehearse", "--scene", "ur5_table", "--samples", "3", "--out",
                   "u.tsv", "--truth-out", "tu.json", "-q")
    doc = json.loads((tmp_path / "tu.json").read_text())
    assert rc == 0
    doc.pop("robot", None)  # as written before truth files recorded their robot
    (tmp_path / "old.json").write_text(json.dumps(doc))
    for truth, why in (("old.json", "a truth file of another robot"),
                       ("tu.json", "made for the robot")):
        rc, out, err = cli(capsys, "rehearse", "--truth", truth, "--samples", "5", "--out",
                           f"x-{truth}.tsv", "-q")
        assert rc == 2 and why in one_line(err) and not (tmp_path / f"x-{truth}.tsv").exists()


def test_a_resumed_sweep_of_other_settings_is_refused_before_anything(tmp_path, capsys):
    from planecal.studies.results import RESULTS_FORMAT
    from planecal.studies.sweep import spec_from_dict
    other = spec_from_dict({"grid": {"samples": [20], "design": ["random"]},
                            "sweep": {"runs": 2}})
    (tmp_path / "sw").mkdir()
    (tmp_path / "sw" / "results.jsonl").write_text(
        json.dumps({"format": RESULTS_FORMAT, "header": other.header()}) + "\n")
    (tmp_path / "spec.toml").write_text('[grid]\nsamples = [25]\ndesign = ["random"]\n'
                                        "[sweep]\nruns = 2\n")
    rc, out, err = cli(capsys, "sweep", tmp_path / "spec.toml", "--out", tmp_path / "sw",
                       "--resume", "--jobs", "1")
    assert rc == 2 and "header.samples" in one_line(err) and not out
    assert sorted(p.name for p in (tmp_path / "sw").iterdir()) == ["results.jsonl"]
