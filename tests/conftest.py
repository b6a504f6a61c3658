"""Shared test data: the seed's real samples and synthetic data generated through the model."""
from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "disable")

from planecal.model.cell_params import CellParams
from planecal.model.measurement import plane_distance, predict, sensor_in_base  # noqa: E402
from planecal.model.encoder import counts_to_joints, joints_to_counts  # noqa: E402
from planecal.model.kinematics import fk
from planecal.model.ik import ik_nearest
from planecal.model.robot import load_robot  # noqa: E402

# Seed 7.1.4: five real MC70 samples (counts, laser mm)
SEED_QE = np.array([
    [8416544, 8371251, 8443192, 8360940, 8321861, 8334082],
    [8413857, 8368248, 8434524, 8358003, 8326447, 8334590],
    [8406018, 8362710, 8437072, 8345914, 8316588, 8340976],
    [8416300, 8379234, 8436265, 8353210, 8344995, 8338298],
    [8413598, 8364575, 8446433, 8371446, 8312776, 8340034],
])
SEED_DM = np.array([92.52, 85.30, 69.86, 67.34, 73.95])

# Seed Table 10 and 6.4 (with MODEL-NOTES' erratum)
TABLE10 = CellParams([0, 0.000762, -0.001237, 0.000731, 4.851769e-5, 0],
                     [0.035436, -0.076901, 0.177291], 1.258098, -1.041635,
                     [[-0.017564, -1.249418, 4.005407]])
INITIAL = CellParams(np.zeros(6), [0.0257, -0.0725, 0.1769], 1.2427, -1.0472,
                     [[0.0, -1.02511, 3.62708]])


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: two workers per core, at most two more than the cores. A third of the
    suite's wall time is waiting (a link's silence, a resend, a scheduler's timeout, a
    subprocess), not computing: on 2 cores 4 workers ran it in 382 s against 446-468 s
    for 2, the CPU time the same (measured on the whole suite, idle)."""
    n = os.cpu_count() or 1
    return min(2 * n, n + 2)


WARM_UP = """
import sys, tempfile, os
from planecal.cli import main
os.chdir(tempfile.mkdtemp(prefix="planecal-warm-"))
assert main(["rehearse", "--samples", "30", "--out", "w.tsv", "-q"]) in (0, 1)
for level in ("offsets", "nonkinematic"):
    main(["calibrate", "w.tsv", "--level", level, "--out", level + ".json", "--no-history",
          "-q"])
"""


def pytest_sessionstart(session):
    """Before xdist's workers start (in the controlling process): one short rehearsal and
    calibration compile numba's kernels into the cache folder, so that on a new machine
    the workers load them instead of each compiling the same kernels at once (about 24 s of CPU each, cold; about 3 s once cached). Its outcome is
    not a test: a failure shows in the tests that run the same commands."""
    if hasattr(session.config, "workerinput") or not session.config.getoption(
            "numprocesses", None):  # a worker, or -n 0: the one process compiles as it goes
        return
    import subprocess
    import sys
    env = {k: v for k, v in os.environ.items() if k != "PLANECAL_HISTORY"}
    subprocess.run([sys.executable, "-c", WARM_UP], env=env, capture_output=True,
                   stdin=subprocess.DEVNULL, timeout=600)


@pytest.fixture(scope="session", autouse=True)
def session_history(tmp_path_factory):
    """The commands that record in the cell's history (calibrate, validate, export, check,
    compare) write to one history of the test session, never to planecal.db in the
    working folder (the checkout): set for the whole session, before any module's
    fixtures run commands."""
    path = tmp_path_factory.mktemp("history") / "planecal.db"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLANECAL_HISTORY", str(path))
        yield path


@pytest.fixture(scope="module")
def rerun_home(tmp_path_factory):
    """HOME and the XDG directories in a fresh folder for one module, restored after: keeps
    rerun (and anything it might start) off the real ~/.config and ~/.local. planecal's
    cache folder stays the session's (its compiled kernels and hulls: a fresh one makes
    every subprocess compile them again, a minute on a loaded machine)."""
    from planecal.base.paths import cache_dir
    home = tmp_path_factory.mktemp("home")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLANECAL_CACHE_DIR", str(cache_dir()))
        for key, sub in (("HOME", ""), ("XDG_CONFIG_HOME", ".config"),
                         ("XDG_DATA_HOME", ".local/share"), ("XDG_CACHE_HOME", ".cache")):
            mp.setenv(key, str(home / sub))
        yield home


@pytest.fixture(scope="session")
def robot():
    return load_robot()


def synthetic_counts(robot, params: CellParams, n: int, rng, plane: int = 0,
                     q_ref=None, spread_deg: float = 15.0, d_range=(0.070, 0.090)):
    """Encoder counts of n poses whose beam meets plane ``plane`` within d_range, made by
    perturbing a reference configuration and sliding the flange along the beam (IK)."""
    q_ref = counts_to_joints(robot, SEED_QE[0]) if q_ref is None else q_ref
    out = []
    while len(out) < n:
        q = q_ref + np.deg2rad(rng.uniform(-spread_deg, spread_deg, 6))
        o_b, z_b = sensor_in_base(robot, q, params)
        n_t = params.planes[plane]
        if abs(n_t @ z_b) <= 0.5 * np.linalg.norm(n_t):  # beam parallel or too oblique
            continue
        d = plane_distance(n_t, o_b, z_b)
        if not 0.0 < d < 0.5:
            continue
        target = rng.uniform(*d_range)
        T = fk(robot.kinematics.with_offsets(params.joint_offsets), q)
        T[:3, 3] += (d - target) * z_b
        q2 = ik_nearest(robot, T, q, params.joint_offsets)
        if q2 is None:
            continue
        out.append(joints_to_counts(robot, q2))
    qe = np.array(out)
    d = predict(robot, qe, params, np.full(n, plane))
    keep = (d > 0.065) & (d < 0.095)
    return qe[keep], d[keep]


def perturbed(params: CellParams, rng, offsets=2e-3, length=0.005, angle=0.02) -> CellParams:
    """Truth near the nominal parameters: offsets within +-offsets rad (delta1 = delta6 = 0),
    sensor origin within +-length m, angles within +-angle rad, plane moved accordingly."""
    from planecal.model.planes import n_tilde_from_point_normal, point_normal_from_n_tilde
    t = params.copy()
    t.joint_offsets = params.joint_offsets + rng.uniform(-offsets, offsets, 6) * [0, 1, 1, 1, 1, 0]
    t.sensor_origin = params.sensor_origin + rng.uniform(-length, length, 3)
    t.phi_y += rng.uniform(-angle, angle)
    t.phi_z += rng.uniform(-angle, angle)
    planes = []
    for n_t in params.planes:
        p, nh = point_normal_from_n_tilde(n_t)
        nh = nh + rng.uniform(-angle, angle, 3)
        planes.append(n_tilde_from_point_normal(p + rng.uniform(-length, length, 3), nh))
    t.planes = np.array(planes)
    return t


@pytest.fixture(autouse=True)
def _fd11_state_dir(tmp_path_factory):
    """The FD11 controllers' state files (`planecal.links.sessions.state_dir`) in a fresh
    folder per test (subprocesses inherit it): never the user's ~/.local/state. (Its own
    MonkeyPatch: a test's ``monkeypatch.undo()`` does not take it back.)"""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PLANECAL_STATE_DIR", str(tmp_path_factory.mktemp("fd11-state")))
        yield


@pytest.fixture(scope="session")
def public_robots(tmp_path_factory):
    """The public robots the tests ship, each imported once per session on first use
    (tests/public_robots.py)."""
    from public_robots import Imported
    return Imported(tmp_path_factory.mktemp("public_robots"))
