"""One cell per run (issue 30 item 1): every command that reads a run, or a result, takes
its cell from it (the run's sidecar, the result's provenance). On the UR5's own scene and
on a ``scene new`` cell of the UR5, each command run without --scene prints what it
prints with the right --scene, and a --scene that contradicts the files is one line,
exit 2. Before: ``calibrate`` fitted the UR5's samples with the MC70's cell (a traceback),
``bootstrap`` exited 0 with delta2 at 8 rad, ``predict`` and ``replay`` refused, ``export``
asked for --scene."""
import json
import re
import shutil

import numpy as np
import pytest

from planecal.cli import main

NO_HISTORY = ["--no-history"]


def _run(capsys, argv):
    """(exit code, stdout, stderr) of one in-process command."""
    capsys.readouterr()
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def _refused(capsys, argv, *words):
    code, out, err = _run(capsys, argv)
    assert code == 2, (argv, out, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, (w, err)
    return err


@pytest.fixture(scope="module")
def cells(tmp_path_factory):
    """Per cell (the UR5's ``ur5_table``; a ``scene new`` cell of the UR5), a folder with
    two rehearsals of it (r.tsv with its truth, s.tsv: another seed), the calibration of
    r.tsv (c.json, made with the right --scene: the same before and after the fix), and
    the scene to name."""
    d = tmp_path_factory.mktemp("cells")
    new = d / "ur5cell.json"
    assert main(["scene", "new", "--robot", "ur5", "--out", str(new)]) == 0
    out = {}
    for name, scene in (("ur5_table", "ur5_table"), ("scene_new", str(new))):
        f = d / name
        f.mkdir()
        for run, seed in (("r", 1), ("s", 2)):
            argv = ["rehearse", "--scene", scene, "--samples", "40", "--seed", str(seed),
                    "--out", str(f / f"{run}.tsv"), "--errors", "ideal", "-q"]
            if run == "r":
                argv += ["--truth-out", str(f / "t.json")]
            assert main(argv) == 0
        assert main(["calibrate", str(f / "r.tsv"), "--scene", scene, "--out",
                     str(f / "c.json"), "-q", *NO_HISTORY]) == 0
        out[name] = (f, scene)
    return out


def _commands(f):
    """Every command that reads a run or a result, as (name, argv) without --scene; the
    outputs each writes go to a fresh name (``{k}``: 0 without --scene, 1 with)."""
    r, s, c, t = (str(f / n) for n in ("r.tsv", "s.tsv", "c.json", "t.json"))
    return [
        ("calibrate", ["calibrate", r, *NO_HISTORY]),
        ("calibrate two runs", ["calibrate", r, s, "--max-iter", "5", *NO_HISTORY]),
        ("bootstrap", ["bootstrap", r, "--sizes", "30", "--repeats", "2", "--jobs", "1"]),
        ("predict", ["predict", s, "--params", c]),
        ("replay", ["replay", s, "--params", t]),
        ("check", ["check", s, "--against", c, *NO_HISTORY]),
        ("compare", ["compare", r, "--rehearsal", r, *NO_HISTORY]),
        ("validate", ["validate", "--calibrated", c, "--truth", t, "--run", r, "--cycles", "2",
                      "--gauge-repeats", "1", *NO_HISTORY]),
        ("export", ["export", c, "--format", "offsets", *NO_HISTORY]),
        ("urdf", ["urdf", "--params", c, "--out", str(f / "u{k}.urdf"), "--no-meshes"]),
        ("report", ["report", c, "--out", str(f / "rep{k}")]),
    ]


def _same(text: str, f) -> str:
    """What may differ between the two calls: the output names, wall times."""
    text = re.sub(r"u[01]\.urdf|rep[01]", "OUT", text)
    return re.sub(r'"(wall|planning)[a-z_]*": [0-9.]+', "TIME", text)


@pytest.mark.parametrize("cell", ["ur5_table", "scene_new"])
def test_every_command_takes_the_cell_of_its_run(cells, capsys, cell):
    f, scene = cells[cell]
    for name, argv in _commands(f):
        got = []
        for k, extra in enumerate(([], ["--scene", scene])):
            code, out, err = _run(capsys, [a.format(k=k) for a in argv] + extra)
            assert code in (0, 1) and "Traceback" not in err, (name, code, err)
            got.append((code, _same(out, f)))
        assert got[0] == got[1], name  # without --scene: the run's cell, the same figures
        # the MC70's scene contradicts the files: one line, exit 2, nothing run
        _refused(capsys, [a.format(k=2) for a in argv] + ["--scene", "thesis_final"],
                 "--scene thesis_final")
    assert not (f / "u2.urdf").exists() and not (f / "rep2").exists()


@pytest.mark.parametrize("cell", ["ur5_table", "scene_new"])
def test_calibrate_without_scene_is_the_calibration_in_its_cell(cells, tmp_path, capsys,
                                                                cell):
    """The issue's case: ``rehearse --scene S`` then ``calibrate RUN`` with no --scene
    gives the result the run's cell gives (before: a traceback, the MC70's cell)."""
    f, scene = cells[cell]
    out = tmp_path / "c.json"
    code, _, err = _run(capsys, ["calibrate", str(f / "r.tsv"), "--out", str(out),
                                 *NO_HISTORY])
    assert code == 0, err
    a, b = (json.loads(p.read_text()) for p in (out, f / "c.json"))
    a.pop("provenance"), b.pop("provenance")
    assert a == b
    assert a["robot"]["name"].startswith("Universal Robots UR5")
    # the bootstrap's subsets are calibrations in that cell too (before: delta2 at 8 rad)
    code, text, _ = _run(capsys, ["bootstrap", str(f / "r.tsv"), "--sizes", "30",
                                  "--repeats", "2", "--jobs", "1"])
    assert code == 0 and "delta2" in text


def test_runs_of_two_cells_are_refused_together(cells, capsys):
    ur5, _ = cells["ur5_table"]
    new, _ = cells["scene_new"]
    _refused(capsys, ["calibrate", str(ur5 / "r.tsv"), str(new / "r.tsv"), *NO_HISTORY],
             "of one cell")
    # a result and a run of different cells
    _refused(capsys, ["predict", str(new / "s.tsv"), "--params", str(ur5 / "c.json")],
             "of one cell")
    # compensate's calibrated region: the result's cell's samples only
    targets = ur5 / "targets.csv"
    q = np.loadtxt(ur5 / "r.tsv", skiprows=1)[:3, :6].astype(np.int64)
    targets.write_text("name,q1,q2,q3,q4,q5,q6\n"
                       + "".join(f"p{i}," + ",".join(map(str, row)) + "\n"
                                 for i, row in enumerate(q)))
    _refused(capsys, ["compensate", str(targets), "--params", str(ur5 / "c.json"),
                      "--samples", str(new / "r.tsv"), "--out", str(ur5 / "o.tsv")],
             "of one cell")
    code, out, err = _run(capsys, ["compensate", str(targets), "--params",
                                   str(ur5 / "c.json"), "--out", str(ur5 / "o.tsv")])
    assert code == 0, err


def test_a_file_without_a_sidecar_takes_scene_or_the_default(cells, tmp_path, capsys):
    f, scene = cells["ur5_table"]
    bare = tmp_path / "bare.tsv"
    shutil.copy(f / "r.tsv", bare)  # no sidecar: a hand-made file
    with_scene = _run(capsys, ["calibrate", str(bare), "--scene", scene, *NO_HISTORY])
    assert with_scene[0] == 0
    assert _same(with_scene[1], f) == _run(capsys, ["calibrate", str(f / "r.tsv"),
                                                    *NO_HISTORY])[1]
    # without --scene: the default cell (the MC70's), which cannot fit the UR5's samples:
    # one line, exit 1, no traceback (before: a traceback)
    code, _, err = _run(capsys, ["calibrate", str(bare), *NO_HISTORY])
    assert code in (1, 2) and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    # beside a run with a sidecar: the sidecar's cell
    assert _run(capsys, ["calibrate", str(bare), str(f / "s.tsv"), "--max-iter", "5",
                         *NO_HISTORY])[0] in (0, 1)


def test_a_moved_scene_file_is_named(cells, tmp_path, capsys):
    """A run whose recorded scene file is gone: one line naming it; --scene with the
    moved file stands in for it."""
    _, scene = cells["scene_new"]
    src = tmp_path / "cell.json"
    shutil.copy(scene, src)
    run = tmp_path / "r.tsv"
    assert main(["rehearse", "--scene", str(src), "--samples", "20", "--out", str(run),
                 "--errors", "ideal", "-q"]) == 0
    moved = tmp_path / "moved.json"
    src.rename(moved)
    err = _refused(capsys, ["calibrate", str(run), *NO_HISTORY])
    assert "not here" in err and "--scene" in err and str(src) in err
    code, _, err = _run(capsys, ["calibrate", str(run), "--scene", str(moved), *NO_HISTORY])
    assert code == 0, err


def test_the_api_the_cli_and_the_demo_give_one_result_document(tmp_path, capsys):
    """One calibration pipeline (jobs.calibrate): ``planecal demo``'s result.json,
    ``planecal calibrate`` of the demo's run and ``planecal.calibrate`` of it are the same
    document, number for number (before: the API's lacked the accuracy and the
    provenance), on the UR5's cell."""
    import planecal
    d = tmp_path / "demo"
    code, _, err = _run(capsys, ["demo", "--scene", "ur5_table", "--samples", "30",
                                 "--seed", "2", "--errors", "ideal", "--dir", str(d)])
    assert code == 0, err
    run = d / "demo.tsv"
    cli = tmp_path / "cli.json"
    assert _run(capsys, ["calibrate", str(run), "--out", str(cli), *NO_HISTORY])[0] == 0
    from planecal.io.params import save_json
    api = tmp_path / "api.json"
    save_json(api, planecal.calibrate(run).document)  # as a file holds it
    docs = [json.loads(p.read_text()) for p in (d / "result.json", cli, api)]
    for doc in docs:
        assert "accuracy" in doc and doc["provenance"]["scene"] == "ur5_table"
        doc["provenance"].pop("created_utc")
    assert docs[0] == docs[1] == docs[2]
