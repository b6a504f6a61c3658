"""Issue 33: a mistyped input is said at once. The CLI's guard (``cli._check_files`` with
``io.outputs.check_files``) refuses an input the command line names that does not exist,
before the command loads its heavy libraries: checked by which modules a fresh process
has imported when it refuses, not by a clock. The positive control: the same command
given an input that exists goes on and loads them. (Commands whose declaration of files
reads a jobs module -- bootstrap, replay, urdf, check, compare, the sampling and study
commands, and calibrate's other inputs once its run exists (the run's recorded cell is
read by the jobs layer) -- refuse the same way, after those imports.)"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numba", "scipy", "mujoco", "sqlalchemy", "fcl", "trimesh", "matplotlib", "dask",
         "rerun")
CODE = f"""
import json, sys
from planecal.cli import main
code = main(sys.argv[1:])
print(json.dumps([code, sorted(m for m in {HEAVY!r} if m in sys.modules)]))
"""

CASES = [
    (["calibrate", "nosuch.tsv"], "nosuch.tsv"),
    (["export", "nosuch.json"], "nosuch.json"),
    (["mjcf", "--truth", "nosuch.json", "--out", "x.xml"], "nosuch.json"),
    (["plan", "--params", "nosuch.json", "--out", "p.json"], "nosuch.json"),
    (["demo", "--errors", "nosuch.json"], "nosuch.json"),
    (["plan", "--scene", "nosuch.json", "--out", "p.json"], "nosuch.json"),
    (["demo", "--scene", "nosuch.json"], "nosuch.json"),
    (["robot", "import", "nosuch.urdf", "--out", "newrobot"], "nosuch.urdf"),
    (["layouts", "--config", "nosuch.toml"], "nosuch.toml"),
]


def _run(argv, cwd):
    p = subprocess.run([sys.executable, "-c", CODE, *argv], capture_output=True, text=True,
                       cwd=cwd, timeout=300)
    code, heavy = json.loads(p.stdout.strip().splitlines()[-1])
    return code, heavy, p.stderr


@pytest.fixture
def folder(tmp_path):
    """A working folder with a sample file and a parameter file that exist (the seed's)."""
    from conftest import SEED_DM, SEED_QE
    from planecal.io.samples import write_samples
    from planecal.io.params import save_params
    from planecal.model.scene import load_scene, nominal_params
    write_samples(tmp_path / "SEED.tsv", SEED_QE, SEED_DM)
    save_params(tmp_path / "SEED.json", nominal_params(load_scene("thesis_final")))
    return tmp_path


@pytest.mark.parametrize("argv, missing", CASES, ids=[" ".join(c[0][:2]) for c in CASES])
def test_a_missing_input_is_refused_before_the_heavy_imports(folder, argv, missing):
    code, heavy, err = _run(argv, folder)
    assert code == 2 and heavy == [], (heavy, err)
    assert err.count("\n") == 1 and f"{missing}: file not found" in err, err


def test_an_input_that_exists_goes_on_to_load_them(folder):
    # the control: the check passes and the command runs, imports what it needs and says
    # what it finds (five samples cannot determine the fit: exit 2, from the fit)
    code, heavy, err = _run(["calibrate", "SEED.tsv"], folder)
    assert {"numba", "scipy"} <= set(heavy), (code, heavy, err)
    assert "not found" not in err and "5 samples cannot determine" in err


@pytest.mark.parametrize("command", ["rehearse", "sample"])
def test_a_bad_pose_list_is_one_line_before_any_kernel_compiles(tmp_path, command):
    """A --poses list that is not one is refused in one line on a cold numba cache (a new
    machine), before the scene's kernels compile or a link opens (before: CI's cold cache
    said "compiling kernels" five times above the refusal, which came after the twin and,
    for ``sample``, after the laser's port and the controller's lock)."""
    import os
    bad = tmp_path / "poses.json"
    bad.write_text('{"format": "planecal-poses/1", "counts": "none", "plates": [0]}')
    argv = [command, "--poses", str(bad), "--out", str(tmp_path / "r.tsv")]
    if command == "sample":
        argv += ["--rt", "127.0.0.1:1", "--laser", str(tmp_path / "no-such-port")]
    env = {**os.environ, "PLANECAL_CACHE_DIR": str(tmp_path / "cold")}
    env.pop("NUMBA_CACHE_DIR", None)
    p = subprocess.run([sys.executable, "-c", CODE, *argv], capture_output=True, text=True,
                       cwd=tmp_path, timeout=300, env=env)
    code, _ = json.loads(p.stdout.strip().splitlines()[-1])
    assert code == 2 and p.stderr.count("\n") == 1, p.stderr
    assert f"{bad}: counts: Input should be a valid list" in p.stderr
