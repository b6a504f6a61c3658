"""planecal export: the encoder offsets to enter into the FD11, as integers, with the wrist
coupling applied, their rounding residual and its effect at the flange."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.model.encoder import counts_to_joints, encoder_zero_counts
from planecal.model.kinematics import jacobian
from planecal.model.robot import load_robot

ROBOT = load_robot()


def test_integer_offsets_realise_the_joint_offsets_to_their_rounding():
    rng = np.random.default_rng(3)
    for _ in range(50):
        delta = rng.uniform(-3e-3, 3e-3, 6)
        new, residual, tcp = encoder_zero_counts(ROBOT, delta)
        assert new.dtype == np.int64
        # the controller's joint angles with the new offsets: q + delta (+ the residual)
        qe = rng.integers(8_000_000, 8_800_000, (20, 6))
        got = counts_to_joints(ROBOT, qe, new) - counts_to_joints(ROBOT, qe)
        assert np.abs(got - (delta + residual)).max() < 1e-12
        # half a count per actuator at most, through the coupling
        bound = np.abs(ROBOT.coupling) @ (0.5 / np.abs(ROBOT.gains))
        assert np.all(np.abs(residual) <= bound + 1e-15)
        assert tcp == pytest.approx(np.linalg.norm(jacobian(ROBOT.kinematics, np.zeros(6))[:3] @ residual))


def test_a_wrist_offset_moves_the_zero_of_q6_with_delta6_fixed():
    delta = np.array([0, 0, 0, 0.02, 0, 0])  # a large delta4 only
    new, _, _ = encoder_zero_counts(ROBOT, delta)
    change = new - ROBOT.qe0.astype(np.int64)
    assert change[3] != 0 and change[4] != 0 and change[5] != 0  # q5 and q6 follow q4
    assert change[:3].tolist() == [0, 0, 0]
    # the old zero counts now read delta: q4 = 0.02, q5 and q6 stay 0 (q5 = x5 + a x4)
    q = counts_to_joints(ROBOT, ROBOT.qe0[None], new)[0]
    assert abs(q[3] - 0.02) < 1e-4 and abs(q[4]) < 1e-4 and abs(q[5]) < 1e-4


def test_export_command_writes_six_integers(tmp_path, capsys):
    out = tmp_path / "fd11.json"
    assert main(["export", "examples/table10_params.json", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["format"] == "planecal-fd11-offsets/1"
    assert len(d["qe0_counts"]) == 6 and all(isinstance(v, int) for v in d["qe0_counts"])
    # Table 10's delta2 = 0.762 mrad: qe0' = qe0 - g2 delta2 = 8388608 - 42.3 -> 8388566
    assert d["qe0_counts"][1] == 8388566 and d["change_counts"][1] == -42
    assert "J2" in text and "8388566" in text and "rounding to whole counts" in text
    assert d["rounding_flange_um"] < 20
    # current values given: the change is counted from them
    assert main(["export", "examples/table10_params.json", "--current-qe0",
                 "8388600,8388600,8388600,8388600,8388600,8388600"]) == 0
    assert "8388558" in capsys.readouterr().out


@pytest.mark.parametrize("argv,msg", [
    (["--current-qe0", "1,2,3"], "expected six integers"),
    (["--current-qe0", "a,b,c,d,e,f"], "expected six integers"),
])
def test_export_bad_input_is_one_line_exit_2(argv, msg, capsys):
    assert main(["export", "examples/table10_params.json", *argv]) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1


def test_export_refuses_to_overwrite_its_input(tmp_path, capsys):
    src = tmp_path / "r.json"
    src.write_text(open("examples/table10_params.json").read())
    assert main(["export", str(src), "--out", str(src)]) == 2
    assert "an input" in capsys.readouterr().err
    assert json.loads(src.read_text())["joint_offsets_rad"][1] == 0.000762


def test_a_kept_joint_that_changes_says_why(tmp_path, capsys):
    """issue 33: export printed J6 "kept: not fitted (current value)" beside a change of -2
    counts. The change is J4's and J5's offsets through the wrist coupling; the line says
    so, with the count the coupling gives (-g6 (C^-1 delta)_6, rounded)."""
    run, cal = tmp_path / "r.tsv", tmp_path / "cal.json"
    assert main(["rehearse", "--out", str(run), "--samples", "40", "-q"]) == 0
    assert main(["calibrate", str(run), "--out", str(cal), "-q"]) == 0
    capsys.readouterr()
    assert main(["export", str(cal), "--out", str(tmp_path / "fd11.json")]) == 0
    lines = {ln.split()[0]: ln for ln in capsys.readouterr().out.splitlines() if ln[:1] == "J"}
    d = json.loads((tmp_path / "fd11.json").read_text())
    delta = np.array(d["joint_offsets_rad"])
    assert delta[5] == 0 and "delta6" in d["kept_current"]
    coupled = -ROBOT.gains[5] * (np.linalg.inv(ROBOT.coupling) @ delta)[5]
    assert abs(coupled) > 0.5  # this run's delta4 and delta5 move J6's zero by a count or more
    assert d["change_counts"][5] == int(np.rint(coupled))
    assert lines["J6"].endswith(f"kept: delta6 not fitted (0); {d['change_counts'][5]:+d} from "
                                "J4's and J5's offsets through the wrist coupling (their "
                                "motors' zeros move q6 unless J6's zero follows)")
    assert lines["J1"].endswith("kept: not fitted (current value)")  # no coupling, no change
