"""planecal as a package (issue 25): the sdist and the wheel carry the robot models, the
scenes and the error profiles; an installed copy finds them wherever it is installed, run
from any folder; a missing or empty data folder is one line; caches go to the user's
cache folder, never into the installed package. (.ci/run installs the wheel with its
dependencies in a fresh virtual environment and runs demo and rehearse there.)"""
import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from planecal.base import paths
from repo import REPO

DATA_FILES = sorted(str(p.relative_to(REPO)) for d in paths.DATA_FOLDERS
                    for p in (REPO / d).rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def dist(tmp_path_factory):
    """``python -m build``: the sdist, then the wheel built from the sdist (as pip and
    PyPI users get it)."""
    out = tmp_path_factory.mktemp("dist")
    p = subprocess.run([sys.executable, "-m", "build", "--outdir", str(out), str(REPO)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    wheels, sdists = list(out.glob("*.whl")), list(out.glob("*.tar.gz"))
    assert len(wheels) == 1 and len(sdists) == 1
    return wheels[0], sdists[0]


def test_the_shipped_data_is_what_the_tests_expect():
    # robot models, their MJCF and error profiles, and the scenes
    for f in ("models/mc70/robot.json", "models/mc70/mc70.xml", "models/mc70/scene.xml",
              "models/mc70/errors/realistic.json", "models/mc70/errors/ideal.json",
              "models/ur5/robot.json", "scenes/thesis_final.json"):
        assert f in DATA_FILES


def test_wheel_and_sdist_carry_models_scenes_and_error_profiles(dist):
    wheel, sdist = dist
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {f"planecal/data/{f}" for f in DATA_FILES} <= names
    # byte for byte the repository's files
    with zipfile.ZipFile(wheel) as z:
        for f in DATA_FILES:
            assert z.read(f"planecal/data/{f}") == (REPO / f).read_bytes(), f
    # nothing else under data/ (no caches, no build litter)
    assert {n for n in names if n.startswith("planecal/data/")} == \
        {f"planecal/data/{f}" for f in DATA_FILES}
    with tarfile.open(sdist) as t:
        top = t.getnames()[0].split("/")[0]
        members = set(t.getnames())
    assert {f"{top}/{f}" for f in DATA_FILES} <= members


def _installed(wheel: Path, target: Path) -> dict:
    """The wheel unpacked by pip into ``target`` (no dependencies: this environment has
    them); the environment that imports planecal from there, not from the checkout."""
    p = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                        "--no-compile", "--target", str(target), str(wheel)],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-3000:]
    env = {k: v for k, v in os.environ.items() if k != "PLANECAL_HOME"}
    return {**env, "PYTHONPATH": str(target)}


def _planecal(args, env, cwd):
    return subprocess.run([sys.executable, "-m", "planecal.cli", *args], capture_output=True,
                          text=True, env=env, cwd=cwd, timeout=300)


def test_an_installed_copy_finds_its_data_from_any_folder(dist, tmp_path):
    target, elsewhere = tmp_path / "site", tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = _installed(dist[0], target)
    p = subprocess.run([sys.executable, "-c", "import planecal.base.paths as p, planecal; "
                        "print(planecal.__file__); print(p.data_root())"],
                       capture_output=True, text=True, env=env, cwd=elsewhere, timeout=60)
    assert p.stdout.split() == [str(target / "planecal" / "__init__.py"),
                                str(target / "planecal" / "data")], p.stderr
    p = _planecal(["scenes", "--json"], env, elsewhere)
    assert p.returncode == 0, p.stderr
    import json
    rows = json.loads(p.stdout)
    assert [r["name"] for r in rows] == sorted(Path(f).stem for f in DATA_FILES
                                               if f.startswith("scenes/"))
    assert all(r["path"].startswith(str(target / "planecal" / "data" / "scenes")) for r in rows)
    # a robot by name, its error profile beside it, the twin's MuJoCo model: a short rehearsal
    p = _planecal(["rehearse", "--samples", "3", "--out", "X.tsv", "-q"], env, elsewhere)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["samples"] == 3 and (elsewhere / "X.tsv").exists()
    # the history's schema and its Alembic migrations travel with the package (issue 32)
    p = _planecal(["export", str(REPO / "tests" / "corpus" / "base" / "result.json"),
                   "--history", "h.db"], env, elsewhere)
    assert p.returncode == 0 and "history: entry 1 (export: ok)" in p.stdout, p.stderr


def test_planecal_home_overrides_and_a_missing_or_empty_folder_is_one_line(tmp_path):
    empty = tmp_path / "empty"
    (empty / "scenes").mkdir(parents=True)
    cases = {str(tmp_path / "nowhere"): "is not a readable folder",
             str(empty): "is empty"}
    for home, why in cases.items():
        env = {**os.environ, "PLANECAL_HOME": home}
        for args in (["scenes"], ["rehearse", "--samples", "2", "--out", "r.tsv"],
                     ["demo", "--samples", "5"]):
            p = _planecal(args, env, tmp_path)
            assert p.returncode == 2, (args, p.stderr)
            assert p.stderr.count("\n") == 1 and "Traceback" not in p.stderr, p.stderr
            assert f"{home}/scenes: {why} ($PLANECAL_HOME;" in p.stderr, p.stderr
    assert not (tmp_path / "r.tsv").exists() and not (tmp_path / "runs").exists()
    # a folder with scenes/ but no *.json in it
    (empty / "scenes" / "README").write_text("no scenes here\n")
    p = _planecal(["scenes"], {**os.environ, "PLANECAL_HOME": str(empty)}, tmp_path)
    assert p.returncode == 2 and p.stderr == \
        f"planecal scenes: error: {empty}/scenes: no scenes (*.json) in it\n"


def test_planecal_home_is_a_shops_own_data(tmp_path, monkeypatch, capsys):
    import shutil

    from planecal.cli import main
    home = tmp_path / "shop"
    shutil.copytree(REPO / "models", home / "models")
    (home / "scenes").mkdir()
    shutil.copy(REPO / "scenes" / "three_plates.json", home / "scenes" / "cell7.json")
    monkeypatch.setenv("PLANECAL_HOME", str(home))
    assert paths.data_root() == home
    assert main(["scenes", "--json"]) == 0
    import json
    rows = json.loads(capsys.readouterr().out)
    assert [(r["name"], r["plates"]) for r in rows] == [("cell7", 4)]
    # a scene given by path is read from its path, wherever the data root is
    from planecal.model.scene import load_scene
    assert len(load_scene(REPO / "scenes" / "thesis_final.json").plates) == 1


def test_caches_go_to_the_cache_folder_not_beside_the_code(tmp_path):
    """numba's compiled tick and the hull cache under $PLANECAL_CACHE_DIR; numba's own
    default (the source's __pycache__) would be inside site-packages in an install."""
    cache = tmp_path / "cache"
    code = ("import numpy as np\n"
            "from planecal.studies.distributed import warm_twin\n"
            "from planecal.model.gravity import joint_torques\n"
            "from planecal.model.robot import load_robot\n"
            "warm_twin()\n"
            "joint_torques(load_robot('mc70'), np.zeros((1, 6)))\n"
            "import numba; print(numba.config.CACHE_DIR)\n")
    env = {**os.environ, "PLANECAL_CACHE_DIR": str(cache)}
    env.pop("NUMBA_CACHE_DIR", None)
    src = Path(paths.__file__).resolve().parents[1]
    before = {p: p.stat().st_mtime_ns for p in src.rglob("*.nb[ic]")}
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       env=env, cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == str(cache / "numba")
    names = {f.name.split("-")[0] for f in (cache / "numba").rglob("*.nbi")}
    assert {"ticks.advance", "ticks.laser", "gravity._compiled.locals.rows"} <= names, names
    assert list(cache.glob("hulls-trimesh*.npz"))
    after = {p: p.stat().st_mtime_ns for p in src.rglob("*.nb[ic]")}
    assert after == before  # nothing written beside the package's code
    # a user's own NUMBA_CACHE_DIR wins
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    p = subprocess.run([sys.executable, "-c", "from planecal.base.paths import numba_cache\n"
                        "numba_cache(); import numba; print(numba.config.CACHE_DIR)"],
                       capture_output=True, text=True, env=env, timeout=120)
    assert p.stdout.strip() == str(tmp_path / "mine"), p.stderr
