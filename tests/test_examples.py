"""The example scripts run as they are (a user copies them), with the project's python."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("planecal.twin")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_calibrate_on_the_twin_runs_and_prints_its_summaries():
    out = subprocess.run([sys.executable, str(EXAMPLES / "calibrate_on_the_twin.py")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    text = out.stdout
    for head in ("Rehearsal on scene thesis_final", "SampleSet: 60 samples",
                 "Calibration on scene thesis_final, level offsets: converged", "offset error [mrad]",
                 "Validation on the twin, in the rehearsal's world", "5 cycles"):
        assert head in text, head
    assert "Traceback" not in out.stderr
