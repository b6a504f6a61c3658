"""rehearse --poses: a planned pose list (planecal plan) drives the sampling run."""
import json

import numpy as np

from planecal.cli import main
from planecal.io.samples import read_samples


def _plan(tmp_path, n=14):
    path = tmp_path / "poses.json"
    assert main(["plan", "--samples", str(n), "--candidates", "80", "--out", str(path)]) == 0
    return path, np.array(json.loads(path.read_text())["counts"])


def test_rehearse_visits_the_planned_poses_and_resumes(tmp_path, capsys):
    poses, counts = _plan(tmp_path)
    out = tmp_path / "run.tsv"
    assert main(["rehearse", "--poses", str(poses), "--samples", "5", "--out", str(out)]) == 0
    first = read_samples(out)
    assert len(first) == 5
    # resume finds the list in the sidecar and takes only poses not yet sampled
    assert main(["rehearse", "--resume", "--samples", "10", "--out", str(out)]) == 0
    capsys.readouterr()
    s = read_samples(out)
    assert len(s) == 10
    np.testing.assert_array_equal(s.qe[:5], first.qe)
    idx = [int(np.flatnonzero(np.all(counts == q, axis=1))[0]) for q in s.qe]
    assert len(set(idx)) == 10  # every sample is a distinct planned pose


def test_pose_list_errors(tmp_path, capsys):
    poses, _ = _plan(tmp_path)
    out = tmp_path / "run.tsv"
    assert main(["rehearse", "--poses", str(poses), "--samples", "20", "--out", str(out)]) == 2
    assert "--samples 20 is more than the 14 poses" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "nope"}')
    assert main(["rehearse", "--poses", str(bad), "--out", str(out), "--force"]) == 2
    assert "not a planecal pose list" in capsys.readouterr().err


def test_a_pose_list_that_runs_out_completes_with_what_it_could_measure(tmp_path, capsys):
    """A pose whose beam misses the plate is rejected by the laser; the run still ends
    'complete' (exit 0) once every pose of the list was tried, and says how many it got."""
    from planecal.model.robot import load_robot
    poses, counts = _plan(tmp_path, n=13)
    doc = json.loads(poses.read_text())
    robot = load_robot()
    away = counts[0].copy()
    away[0] += int(round(np.deg2rad(40) * robot.gains[0]))  # J1 40 deg off: beam past the plate
    doc["counts"] = counts.tolist() + [away.tolist()]
    if "plates" in doc:
        doc["plates"] = list(doc["plates"]) + [doc["plates"][0]]
    poses.write_text(json.dumps(doc))
    out = tmp_path / "run.tsv"
    capsys.readouterr()
    assert main(["rehearse", "--poses", str(poses), "--errors", "ideal", "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["status"] == "complete"
    n = summary["samples"]
    # the pose aimed past the plate is never measured; every other pose may be (a plan's
    # pose can also miss in the twin's world)
    assert 10 <= n <= 13 and summary["rejected_laser"] >= 1
    assert f"{n} of the 14 samples" in summary["stop_reason"]
    got = read_samples(out).qe
    assert len(got) == n and not np.any(np.all(got == away, axis=1))
