"""The output guard (planecal.io.outputs) and the writers of issue 25: every command that
writes declares its files, every count option has a bound, no JSON planecal writes holds
NaN or Infinity (a results file reads back what was written), and the cases the corpus
cannot set up (environment variables, a monkeypatched study)."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.cli import COMMANDS, build_parser, main, parse
from planecal.io.outputs import Files, check_files, check_output
from repo import repo_path

BASE = Path(__file__).parent / "corpus" / "base"
OUTPUT_OPTIONS = {"out", "rrd", "report", "truth-out", "results", "dir", "rt-state"}


# ----- every writer goes through the guard --------------------------------------------------

def test_every_command_that_writes_declares_its_files():
    """A command with an output option has ``files(args)`` (the CLI checks it before
    ``run``); one without any has none to declare."""
    import importlib
    parser = build_parser([], full=True)
    for name in COMMANDS:
        module = importlib.import_module(f"planecal.commands.{name.replace('-', '_')}")
        writes = bool(parser.commands[name].long_options & OUTPUT_OPTIONS)
        assert hasattr(module, "files") == writes, name


DECLARED = [  # argv -> the outputs its declaration must hold (under tmp)
    (["calibrate", str(BASE / "run.tsv"), "--out", "{t}/r.json", "--report", "{t}/rep",
      "--rrd", "{t}/f.rrd"], ["r.json", "rep", "f.rrd"]),
    (["rehearse", "--out", "{t}/o.tsv", "--truth-out", "{t}/t.json", "--rrd", "{t}/r.rrd"],
     ["o.tsv", "o.tsv.json", "o.tsv.lock", "t.json", "r.rrd"]),
    (["montecarlo", "--out", "{t}/m.json", "--slope", "50,100", "--rrd", "{t}/x"],
     ["m.json", "m.runs.jsonl", "m.slope-50.runs.jsonl", "m.slope-100.runs.jsonl", "x.rrd"]),
    (["bootstrap", str(BASE / "run.tsv"), "--out", "{t}/b.json", "--report", "{t}/rep"],
     ["b.json", "b.runs.jsonl", "rep"]),
    (["urdf", "--out", "{t}/x.urdf"], ["x.urdf", "x_meshes"]),
    (["demo", "--dir", "{t}/dd", "--rrd", "{t}/d.rrd"], ["dd", "d.rrd"]),
    (["sample", "--rt", "127.0.0.1", "--out", "{t}/s.tsv", "--rt-state", "{t}/st"],
     ["s.tsv", "s.tsv.json", "st", "st.lock"]),
]


@pytest.mark.parametrize("argv, names", DECLARED, ids=[a[0] for a, _ in DECLARED])
def test_a_declaration_holds_every_file_the_command_writes(tmp_path, argv, names):
    import importlib
    args = parse([a.format(t=tmp_path) for a in argv])
    module = importlib.import_module(f"planecal.commands.{args.command}")
    written = {o.path.name for o in module.files(args).outputs}
    assert set(names) <= written, (names, written)


def test_every_count_option_has_a_stated_bound():
    """No option converts with a bare ``int`` (a count without an upper bound can ask for
    a run that never ends): counts, seeds and ports have their shared types."""
    parser = build_parser([], full=True)
    for name, p in parser.commands.items():
        for action in p._actions:
            assert action.type is not int or action.choices, (name, action.option_strings)


# ----- the guard ------------------------------------------------------------------------------

def test_an_input_is_found_by_path_link_and_inode(tmp_path):
    src = tmp_path / "in.json"
    src.write_text("{}")
    (tmp_path / "sym.json").symlink_to(src)
    os.link(src, tmp_path / "hard.json")
    for out in ("in.json", "sym.json", "hard.json", "./in.json"):
        with pytest.raises(InputError, match="that is an input of this command"):
            check_output(tmp_path / out, [src], force=True)
    with pytest.raises(InputError, match="a symbolic link to nothing"):
        (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
        check_output(tmp_path / "dangling", [src])
    assert check_output(tmp_path / "new.json", [src]) == tmp_path / "new.json"


def test_a_folder_output_and_its_members(tmp_path):
    rep = tmp_path / "rep"
    members = (("index.html", (b"<!--ours-->",)), ("*.png", (b"ours",)))
    f = Files().write(rep, "--report", folder=True, members=members, anchor="index.html")
    check_files(f)  # missing: fine, its parent exists
    rep.mkdir()
    (rep / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="holds files planecal did not write"):
        check_files(f)
    (rep / "index.html").write_text("<!--ours-->")
    check_files(f)  # planecal's folder; notes.txt is not a name the report writes
    (rep / "a.png").write_bytes(b"theirs")
    with pytest.raises(InputError, match=r"\(a.png\).*not a file planecal wrote"):
        check_files(f)
    check_files(f, force=True)
    g = Files().write(rep / "a.png", "--out").write(rep, "--report", folder=True,
                                                     members=members, anchor="index.html")
    with pytest.raises(InputError, match="writes that file too"):
        check_files(g, force=True)
    deep = Files().write(tmp_path / "a" / "b", "--dir", folder=True, parents=True)
    check_files(deep)
    with pytest.raises(InputError, match="does not exist"):
        check_files(Files().write(tmp_path / "a" / "b", "--report", folder=True))


# ----- no NaN or Infinity in a file planecal writes ---------------------------------------------

def test_the_json_writers_write_null_for_a_number_that_is_not_defined(tmp_path):
    from planecal.formats.base import dumps
    from planecal.io.params import save_json
    doc = {"a": float("nan"), "b": [1.0, float("inf")], "c": np.array([np.nan, 2.0]),
           "d": np.float64("-inf"), "e": (3, 4)}
    save_json(tmp_path / "x.json", doc)
    want = {"a": None, "b": [1.0, None], "c": [None, 2.0], "d": None, "e": [3, 4]}
    assert json.loads((tmp_path / "x.json").read_text()) == want
    assert json.loads(dumps(doc)) == want


def test_a_results_file_reads_back_what_was_written_and_refuses_a_bare_nan(tmp_path):
    from planecal.studies.results import ResultsFile
    path = tmp_path / "r.jsonl"
    f = ResultsFile(path, {"study": "x"}, resume=False)
    res = {"err": np.array([1.0, np.nan, -np.inf]), "x": float("nan"), "n": 3}
    back = f.append(0, res)
    f.close()
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    for line in text.splitlines():
        json.loads(line, parse_constant=lambda c: pytest.fail(c))
    g = ResultsFile(path, {"study": "x"}, resume=True)
    (_, again), = g.done.values()
    g.close()
    for r in (back, again):
        np.testing.assert_array_equal(r["err"], res["err"])
        assert math.isnan(r["x"]) and r["n"] == 3
    # a line holding a bare NaN (not planecal's): refused, naming the line
    with open(path, "a") as fh:
        fh.write('{"key": 1, "result": {"err": [NaN, 1.0]}, "arrays": {}}\n')
    with pytest.raises(InputError, match=r"r.jsonl, line 3: NaN is not a value planecal writes"):
        ResultsFile(path, {"study": "x"}, resume=True)


# ----- what the corpus cannot set up ------------------------------------------------------------

def test_a_bad_laser_port_is_refused_before_the_controllers_state(tmp_path, monkeypatch,
                                                                  capsys):
    state = tmp_path / "state"
    monkeypatch.setenv("PLANECAL_STATE_DIR", str(state))
    code = main(["sample", "--rt", "127.0.0.1", "--local-port", "0", "--laser",
                 str(tmp_path / "no-laser"), "--out", str(tmp_path / "o.tsv")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--laser" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no state folder, no run files


def test_one_bad_scene_does_not_hide_the_others(tmp_path, monkeypatch, capsys):
    import shutil
    home = tmp_path / "home"
    shutil.copytree(repo_path("models"), home / "models")
    (home / "scenes").mkdir()
    shutil.copy(repo_path("scenes", "thesis_final.json"), home / "scenes")
    (home / "scenes" / "broken.json").write_text("{")
    monkeypatch.setenv("PLANECAL_HOME", str(home))
    assert main(["scenes"]) == 2
    cap = capsys.readouterr()
    assert cap.out.startswith("thesis_final ") and "broken" not in cap.out
    assert cap.err.count("\n") == 1 and "broken.json" in cap.err


def test_a_sweep_whose_every_run_failed_exits_1(tmp_path, monkeypatch, capsys):
    import planecal.studies.sweep as sweep
    monkeypatch.setattr(sweep, "run_one", lambda item: {"failed": "the test's failure"})
    spec = tmp_path / "spec.toml"
    spec.write_text('[grid]\nsamples = [20]\ndesign = ["random"]\n[sweep]\nruns = 2\n')
    assert main(["sweep", str(spec), "--out", str(tmp_path / "sw"), "--jobs", "1", "-q"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "every run of the sweep failed" in err, err
    assert (tmp_path / "sw" / "sweep.json").exists()  # the files written stay valid


def test_a_scheduler_that_does_not_answer_is_one_line_and_makes_no_folder(tmp_path, capsys):
    """The scheduler is reached before anything is said or made (validate printed its
    plan first, sweep made an empty DIR): nothing listens on port 1 (about 9 s of wall
    time, hardly any CPU)."""
    spec = tmp_path / "spec.toml"
    spec.write_text('[grid]\nsamples = [20]\ndesign = ["random"]\n[sweep]\nruns = 2\n')
    assert main(["sweep", str(spec), "--out", str(tmp_path / "sw"), "--scheduler",
                 "tcp://127.0.0.1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Dask scheduler answered" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["spec.toml"]


def test_a_planecal_document_longer_than_the_probe_is_still_planecals(tmp_path):
    """A validation of 20 truths (330 kB) is replaced by the next one without --force: its
    format, written first, is found though the probe does not hold the whole document;
    another file that size is not, nor a document whose format comes later."""
    ours = tmp_path / "v.json"
    ours.write_text(json.dumps({"format": "planecal-validate/3", "truths": ["x" * 100] * 4000},
                               indent=2))
    assert ours.stat().st_size > 1 << 16
    assert check_output(ours, fmt="planecal-validate/3") == ours
    for name, doc in (("late.json", {"truths": ["x" * 100] * 4000, "format": "planecal-validate/3"}),
                      ("other.json", {"format": "other/1", "truths": ["x" * 100] * 4000})):
        (tmp_path / name).write_text(json.dumps(doc))
        with pytest.raises(InputError, match="exists and is not a file planecal wrote there"):
            check_output(tmp_path / name, fmt="planecal-validate/3")
