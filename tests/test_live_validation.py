"""Live validation (seed 8.2, 8.4): the calibrated model commands the poses while the twin
keeps its own truth; the export round trip (offsets -> FD11 integers -> the encoder zeros
the run converts with) puts a fixed-distance run back on 80 mm."""
import json

import numpy as np

from planecal.cli import main
from planecal.io.params import save_params
from planecal.io.samples import read_samples
from planecal.model.scene import load_scene
from planecal.twin.truth import draw_truth


def _run(tmp_path, capsys, *argv):
    out = tmp_path / "fixed.tsv"
    assert main(["rehearse", "--out", str(out), "--force", "--foreground", *argv]) == 0
    return json.loads(capsys.readouterr().out), read_samples(out).d_mm


def test_aiming_with_the_truth_reads_the_commanded_distance(tmp_path, capsys):
    # the exact ideal twin, aimed with its own truth (sensor, planes, offsets): every
    # reading is the commanded 80 mm to the counts' rounding; aimed with the nominal
    # model, millimetres off. The offsets are the twin's (truth), added once.
    truth = draw_truth(load_scene("thesis_final"), 3)
    tfile = tmp_path / "truth.json"
    save_params(tfile, truth)
    common = ["--samples", "8", "--seed", "5", "--twin-seed", "3", "--errors", "ideal",
              "--exact", "--fixed-distance-mm", "80"]
    s, d = _run(tmp_path, capsys, *common, "--params", str(tfile))
    assert np.abs(d - 80.0).max() < 0.02  # whole counts: ~20 urad -> ~0.02 mm
    assert s["fixed_distance"]["calibration"] == "after"
    s0, d0 = _run(tmp_path, capsys, *common)
    assert np.abs(d0 - 80.0).max() > 0.5 and s0["fixed_distance"]["calibration"] == "before"


def test_export_round_trip_reads_80_mm(tmp_path, capsys):
    # issue 12: calibrate a rehearsal, export the offsets as FD11 integers, load them as
    # the encoder zeros of a fixed-distance run at 80 mm aimed with the result: in the
    # ideal world the readings are 80 mm +- 0.05 mm
    run = tmp_path / "run.tsv"
    assert main(["rehearse", "--samples", "60", "--seed", "2", "--errors", "ideal",
                 "--out", str(run)]) == 0
    res, fd11 = tmp_path / "result.json", tmp_path / "fd11.json"
    assert main(["calibrate", str(run), "--out", str(res)]) == 0
    assert main(["export", str(res), "--out", str(fd11)]) == 0
    capsys.readouterr()
    for orient in (["--cone-deg", "0", "--roll-deg", "0"], []):
        s, d = _run(tmp_path, capsys, "--samples", "12", "--seed", "7", "--twin-seed", "2",
                    "--errors", "ideal", "--fixed-distance-mm", "80", *orient,
                    "--params", str(res), "--encoder-offsets", str(fd11))
        assert np.abs(d - 80.0).max() < 0.05, d
        f = s["fixed_distance"]
        assert f["readings"] == 12 and abs(f["mean_mm"] - 80) < 0.02
        assert f["seed"]["mean_mm"] in (80.48, 80.82)  # the thesis's own, beside it


def test_resume_keeps_the_model_it_aims_with(tmp_path, capsys):
    truth = draw_truth(load_scene("thesis_final"), 3)
    tfile = tmp_path / "truth.json"
    save_params(tfile, truth)
    out = tmp_path / "r.tsv"
    common = ["--seed", "5", "--twin-seed", "3", "--errors", "ideal", "--exact",
              "--fixed-distance-mm", "80"]
    assert main(["rehearse", "--out", str(out), "--samples", "4", *common,
                 "--params", str(tfile)]) == 0
    side = json.loads((tmp_path / "r.tsv.json").read_text())
    assert side["command"]["params"] == str(tfile.resolve())
    assert main(["rehearse", "--out", str(out), "--resume", "--samples", "8"]) == 0
    capsys.readouterr()
    d = read_samples(out).d_mm
    assert len(d) == 8 and np.abs(d - 80.0).max() < 0.02


def test_bad_encoder_offsets_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "fd11.json"
    bad.write_text('{"qe0_counts": [1, 2, 3]}')
    assert main(["rehearse", "--out", str(tmp_path / "x.tsv"), "--samples", "2",
                 "--encoder-offsets", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "six integer counts" in err and err.count("\n") == 1
