"""rehearse --poses: a planned pose list (planecal plan) drives the sampling run."""
import json

import numpy as np

from planecal.cli import main
from planecal.samples import read_samples


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
