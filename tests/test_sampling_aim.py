"""Aiming a random run's distances with what the laser has read (``sampling.aim``). Peers:
three_plates' truth 901, whose plates sit 9-25 mm nearer than the nominal cell puts them
(its laser out of range on 614 of 644 poses before); the same run planned ahead and in
turn, stopped and resumed; a run whose laser never misses, unchanged."""
import json

import numpy as np
import pytest

from planecal.cli import main
from planecal.io.samples import read_samples
from planecal.sampling.aim import MISSES, WINDOW, Aim, Shifts

pytest.importorskip("planecal.twin")


def test_the_shifts_are_each_plates_median_once_the_laser_has_missed():
    aim = Aim()
    for v in (68.0, 70.0, 75.0):  # read 12, 10 and 5 mm nearer than commanded at 80 mm
        aim.read(0, 0.080, v)
    aim.read(2, 0.080, 81.0)
    assert aim.shifts() is None  # nothing missed yet: the commanding model's distances
    for _ in range(MISSES - 1):  # misses at the range's edge, then a reading
        aim.missed()
    aim.read(2, 0.080, 81.0)
    for _ in range(MISSES - 1):
        aim.missed()
    assert aim.shifts() is None and aim.streak == MISSES - 1
    aim.missed()  # MISSES in a row: aimed from now on
    s = aim.shifts()
    assert s == Shifts(pytest.approx(-0.005), (pytest.approx(-0.010), None,
                                                 pytest.approx(0.001)))
    aim.read(1, 0.080, 80.0)
    assert aim.engaged and aim.streak == 0  # aimed for good
    s = aim.shifts()
    assert s.of(0) == pytest.approx(-0.010) and s.of(1) == 0.0 and s.of(7) == s.pooled
    for _ in range(WINDOW):  # the last WINDOW readings only
        aim.read(0, 0.080, 80.0)
    assert aim.shifts().of(0) == 0.0
    assert Aim.from_dict(json.loads(json.dumps(aim.to_dict()))) == aim


def rehearse(folder, name, samples, *extra, seed=901):
    out = folder / f"{name}.tsv"
    code = main(["rehearse", "--scene", "three_plates", "--seed", str(seed), "--samples",
                 str(samples), "--out", str(out), *extra])
    assert code == 0
    return out, json.loads((folder / f"{name}.tsv.json").read_text())


def test_a_cell_the_nominal_distances_miss_is_aimed_and_runs_the_same_every_way(tmp_path,
                                                                              capsys):
    out, side = rehearse(tmp_path, "ahead", 24)
    capsys.readouterr()
    # before: 614 out-of-range reads for 30 samples, 217 robot minutes
    assert side["laser_give_ups"]["out_of_range"] <= 2 * MISSES  # the streak that starts it
    assert side["robot_time_s"] < 20 * 60
    aim = side["aim"]
    assert aim["engaged"] and aim["next"] is not None
    # plate_d (the fourth) is read 20-30 mm nearer than the nominal cell: aimed so
    assert -0.032 < aim["next"]["plates_m"][3] < -0.020
    s = read_samples(out)
    assert np.all((s.d_mm > 65) & (s.d_mm < 95))
    # planned in turn: the same run (the shifts a plan takes are known before it is made)
    fg, _ = rehearse(tmp_path, "turn", 24, "--foreground")
    assert fg.read_text() == out.read_text()
    # stopped after 10 and resumed (a new session of the twin: its noise draws anew): the
    # aiming goes on from the sidecar, every plate's readings of both sessions kept
    part, first = rehearse(tmp_path, "part", 10)
    assert main(["rehearse", "--resume", "--samples", "24", "--out", str(part)]) == 0
    capsys.readouterr()
    side = json.loads((tmp_path / "part.tsv.json").read_text())
    assert first["aim"]["engaged"] and side["laser_give_ups"]["out_of_range"] <= 2 * MISSES
    plates = read_samples(part).plate
    assert [len(e) for e in side["aim"]["excess_m"]] == [
        min(WINDOW, int(np.sum(plates == k))) for k in range(4)]


def test_a_run_whose_laser_never_misses_is_not_aimed(tmp_path, capsys):
    _, side = rehearse(tmp_path, "ok", 12, seed=0)
    capsys.readouterr()
    assert side["laser_give_ups"]["out_of_range"] == 0
    assert side["aim"]["engaged"] is False and side["aim"]["next"] is None
    assert len(side["aim"]["excess_m"]) == 4  # read, kept for when it misses


def test_an_aimed_draw_is_the_same_draw_placed_that_much_further_out():
    """``PoseGenerator.draw``'s shift: the same spot, beam and roll from the same random
    state, the sensor placed the shift further back along the beam; not at a fixed
    distance (``--fixed-distance-mm``, the live validation's)."""
    from planecal.model.scene import load_scene
    from planecal.sampling.poses import PoseGenerator
    gen = PoseGenerator(load_scene("three_plates"))
    a = gen.draw(np.random.default_rng(1), 3)
    b = gen.draw(np.random.default_rng(1), 3, -0.02)
    assert b.distance_m == pytest.approx(a.distance_m + 0.02, abs=1e-12)
    assert np.array_equal(b.point, a.point) and np.array_equal(b.beam, a.beam)
    assert np.allclose(b.T_sensor[:3, 3], a.T_sensor[:3, 3] - 0.02 * a.beam, atol=1e-12)
    assert np.allclose(b.T_sensor[:3, :3], a.T_sensor[:3, :3], atol=1e-15)
    # a fixed distance is what the run measures the cell at: not shifted
    from planecal.sampling.poses import PoseSettings
    fixed = PoseGenerator(load_scene("three_plates"),
                          PoseSettings(cone_deg=15.0, fixed_distance_mm=80.0))
    assert fixed.draw(np.random.default_rng(1), 3, -0.02).distance_m == 0.080
