"""planecal sweep: the spec's checks, the seeds of a run, one run's robot-time account, and
a killed sweep resumed to the same table (a 2 x 2 grid, 2 runs of 20-25 samples)."""
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from planecal.cli import main
from planecal.base.errors import InputError
from planecal.studies import sweep as S

TINY = """
[grid]
scene = "thesis_final"
errors = "ideal"
design = ["random", "planned+ordered"]
samples = [20, 25]
level = ["offsets"]

[sweep]
runs = 2
seed = 5
plan_candidates = 60
"""


def _spec(tmp_path, text):
    p = tmp_path / "spec.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("change, message", [
    ('level = ["offsets"]', None),
    ('level = ["fancy"]', "grid.level: 'fancy': unknown level 'fancy': one of offsets, full"),
    ('level = ["full+stiffness"]', "grid.level: 'full+stiffness': expected a level"),
    ('design = ["random", "smart"]', "grid.design: 'smart' is not a pose design"),
    ('samples = [20, 10]', "grid.samples: 10 is below 20"),
    ('errors = "nowhere.json"', "grid.errors: 'nowhere.json' is neither a profile"),
    ('colour = ["red"]', "grid.colour: unknown axis"),
    ('samples = [20, 20]', "grid.samples: a value appears twice"),
    ('samples = ["20"]', "grid.samples: '20' is not an integer"),
    # every run of such a cell would be refused (before: the sweep ran them all, failed)
    ('level = ["offsets", "full"]',
     "grid.samples: 20 samples cannot determine the 35 free parameters of level 'full' on "
     "thesis_final: give more than 35"),
])
def test_spec_checks_name_the_field(tmp_path, change, message):
    key = change.split(" =")[0]
    lines = [ln for ln in TINY.splitlines() if not ln.startswith(key + " =")]
    text = "\n".join(lines).replace("[grid]", "[grid]\n" + change)
    p = _spec(tmp_path, text)
    if message is None:
        assert S.load_spec(p).level == ("offsets",)
        return
    with pytest.raises(InputError) as e:
        S.load_spec(p)
    assert str(e.value).startswith(f"{p}: ")
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def test_spec_errors_file_is_relative_to_the_spec(tmp_path):
    from planecal.model.scene import load_scene
    src = load_scene("thesis_final").robot.source.parent / "errors" / "realistic.json"
    shutil.copy(src, tmp_path / "mine.json")
    spec = S.load_spec(_spec(tmp_path, TINY.replace('errors = "ideal"', 'errors = "mine.json"')))
    assert spec.errors == (str((tmp_path / "mine.json").resolve()),)
    p = _spec(tmp_path, TINY + "\n[extra]\n")
    with pytest.raises(InputError, match=r"unknown table \[extra\]"):
        S.load_spec(p)
    p = _spec(tmp_path, TINY.replace("runs = 2", "runs = 1"))
    with pytest.raises(InputError, match=r"sweep.runs: expected an integer in \[2, 100000\], got 1"):
        S.load_spec(p)


def test_seeds_are_fixed_by_cell_and_k(tmp_path):
    spec = S.load_spec(_spec(tmp_path, TINY))
    cells = spec.cells()
    assert len(cells) == 4 and [c["design"] for c in cells] == \
        ["random", "random", "planned+ordered", "planned+ordered"]
    seeds = {(S.cell_id(c), k): S.run_seed(spec, c, k) for c in cells for k in range(3)}
    assert len(set(seeds.values())) == len(seeds)  # every run its own stream
    # the same (cell, k) gives the same seed in another spec (other runs, other cells)
    other = S.load_spec(_spec(tmp_path, TINY.replace("runs = 2", "runs = 7")
                              .replace("samples = [20, 25]", "samples = [25, 40]")))
    c25 = [c for c in other.cells() if c["samples"] == 25]
    for c in c25:
        for k in range(3):
            assert S.run_seed(other, c, k) == seeds[(S.cell_id(c), k)]
    # the world (the truth, the robot) of run k is the same for every design and size
    assert len({S.world_seed(spec, c, 1) for c in cells}) == 1
    assert S.world_seed(spec, cells[0], 0) != S.world_seed(spec, cells[0], 1)
    # and fixed: the same integers on every machine
    assert S.derived_seed(5, {"a": 1}, 0) == S.derived_seed(5, {"a": 1}, 0)
    assert S.derived_seed(5, {"a": 1}, 0) != S.derived_seed(6, {"a": 1}, 0)


def test_a_run_is_pure_and_accounts_its_robot_time(tmp_path):
    spec = S.load_spec(_spec(tmp_path, TINY))
    item = S.items(spec, {})[0]  # random, 20 samples, k = 0
    a, b = S.run_one(item), S.run_one(item)
    assert a.keys() == b.keys()
    for k in a:
        assert np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray) else a[k] == b[k]
    assert a["samples"] == 20 and a["names"] == ["delta2", "delta3", "delta4", "delta5"]
    attempts = a["samples"] + a["rejected"]["laser"]  # every laser read followed a move
    assert a["ticks"] == a["travel_ticks"] + 5 * attempts + a["read_ticks"]
    assert a["read_ticks"] >= 100 * attempts  # a read takes its buffer at least
    assert a["robot_time_s"] == pytest.approx(a["ticks"] * 0.01)
    # an ideal twin calibrates its offsets to within a few hundred urad at 20 samples
    assert np.all(np.abs(a["err"]) < 2e-3) and a["converged"]


def _lines(p: Path) -> list[bytes]:
    return p.read_bytes().splitlines(keepends=True)


def test_a_killed_sweep_resumes_to_the_same_table(tmp_path, capsys):
    spec = _spec(tmp_path, TINY)
    full = tmp_path / "full"
    assert main(["sweep", str(spec), "--out", str(full), "--jobs", "1"]) == 0
    printed = capsys.readouterr().out
    table = (full / "sweep.txt").read_text()
    assert table.strip() in printed
    res = json.loads((full / "sweep.json").read_text())
    assert [c["runs"] + c["failed"] for c in res["cells"]] == [2, 2, 2, 2]
    assert all(c["runs"] == 2 for c in res["cells"])
    rnd = [c for c in res["cells"] if c["design"] == "random"]
    plan = [c for c in res["cells"] if c["design"] != "random"]
    # planned+ordered poses cost less robot time per sample than the random run's
    assert all(p["robot_time_per_sample_s"] < r["robot_time_per_sample_s"]
               for p, r in zip(plan, rnd))
    lines = _lines(full / "results.jsonl")
    assert len(lines) == 1 + 8
    # the kill: three runs written, the fourth torn mid-line
    part = tmp_path / "part"
    part.mkdir()
    (part / "results.jsonl").write_bytes(b"".join(lines[:4]) + lines[4][:40])
    code = main(["sweep", str(spec), "--out", str(part), "--jobs", "1"])
    assert code == 2  # without --resume the results are not overwritten
    assert "continue it with --resume" in capsys.readouterr().err
    assert main(["sweep", str(spec), "--out", str(part), "--jobs", "1", "--resume"]) == 0
    capsys.readouterr()
    assert (part / "sweep.txt").read_text() == table
    assert json.loads((part / "sweep.json").read_text()) == res
    assert len(_lines(part / "results.jsonl")) == 1 + 8
    # the figure: one PNG, a real image
    png = (part / "accuracy_vs_robot_time.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000



def test_report_of_a_sweep(tmp_path):
    """planecal report draws a sweep.json: the figure and one table row per cell."""
    from planecal.present.report import detect_kind, write_report
    cell = {"scene": "thesis_final", "errors": "ideal", "level": "offsets", "runs": 3,
            "failed": 0, "names": ["delta2", "delta3"], "samples_taken": 20.0,
            "travel_per_sample_s": 10.0, "std_rad": {"delta2": 1e-4, "delta3": 2e-4}}
    cells = [{**cell, "design": d, "samples": n, "cell": f"{d}/{n}",
              "robot_time_min": t, "offset_std_rad": s}
             for d, n, t, s in (("random", 20, 8.0, 3e-4), ("random", 40, 15.0, 2e-4),
                                ("planned+ordered", 20, 3.0, 2e-4),
                                ("planned+ordered", 40, 5.0, 1.5e-4))]
    doc = {"format": "planecal-sweep/1", "spec": {"runs": 3, "seed": 5}, "cells": cells}
    assert detect_kind(doc) == "sweep"
    index = write_report(doc, tmp_path / "rep")
    html = index.read_text()
    assert "accuracy_vs_robot_time.png" in html and html.count("<tr>") >= 5
    assert (tmp_path / "rep" / "accuracy_vs_robot_time.png").stat().st_size > 10_000
