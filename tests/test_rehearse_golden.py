"""The samples a seed gives: ``planecal rehearse --samples 20 --seed 0`` (the realistic twin
of thesis_final, background planning on) as the run before issue 33's speed work wrote
them (tests/data/rehearse_seed0_20.tsv, written by 22941da): the same poses (counts and
approach directions, exactly) and the same readings to 1e-6 mm (the file's resolution;
the beams and the laser model are floating point). A change that moves them must say so
in its own commit and rewrite the file."""
from pathlib import Path

import numpy as np

from planecal.cli import main
from planecal.io.samples import read_samples

GOLDEN = Path(__file__).parent / "data" / "rehearse_seed0_20.tsv"


def test_rehearse_of_seed_0_gives_the_recorded_samples(tmp_path, capsys):
    out = tmp_path / "r.tsv"
    assert main(["rehearse", "--samples", "20", "--seed", "0", "--out", str(out), "-q"]) == 0
    capsys.readouterr()
    got, want = read_samples(out), read_samples(GOLDEN)
    assert np.array_equal(got.qe, want.qe)
    assert np.array_equal(got.direction, want.direction)
    assert np.max(np.abs(got.d_mm - want.d_mm)) <= 1e-6
