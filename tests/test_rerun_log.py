"""Rerun recordings (planecal.present.rerun, planecal view), read back with rerun's own reader:
the entity tree, samples and hit points of a short twin rehearsal, the same run replayed
as real-cell data, the optimizer's histograms, file naming, and the view command. Headless:
no viewer is ever spawned, and rerun's config/data dirs point into a temporary HOME."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

rr = pytest.importorskip("rerun")
twin_mod = pytest.importorskip("planecal.twin")
collision = pytest.importorskip("planecal.safety.collision")

from rerun.chunk import RrdReader  # noqa: E402

from planecal import cli  # noqa: E402
from planecal.model.measurement import predict  # noqa: E402
from planecal.base.errors import InputError  # noqa: E402
from planecal.links.base import AlwaysEnabled  # noqa: E402
from planecal.present.rerun import (HIST_BINS, SamplingObserver, log_fit_to_file,  # noqa: E402
                                open_recording, recording_path, reject_kind, sampling_observer)
from planecal.io.samples import read_samples  # noqa: E402
from planecal.sampling import Driver, RunSettings, SamplingRun  # noqa: E402
from planecal.model.scene import load_scene, nominal_params  # noqa: E402
from wire import sample_argv  # noqa: E402

N_SAMPLES = 20
EVERY = 5


pytestmark = pytest.mark.usefixtures("rerun_home")  # rerun off the real ~/.config (conftest)


# ----- reading recordings back -----

def read_rrd(path) -> dict:
    """entity -> {"static": bool, "rows": [dict column -> value]} sorted by tick."""
    out: dict = {}
    for ch in RrdReader(str(path)).store().stream():
        rb = ch.to_record_batch()
        cols = {}
        for n in rb.schema.names:
            if n == "rerun.controls.RowId":
                continue
            c = rb.column(n)
            if pa.types.is_duration(c.type):  # robot_time: integer nanoseconds
                c = c.cast(pa.int64())
            cols[n] = c.to_pylist()
        ent = out.setdefault(ch.entity_path, {"static": ch.is_static, "rows": []})
        for i in range(ch.num_rows):
            ent["rows"].append({n: v[i] for n, v in cols.items()})
    for ent in out.values():
        ent["rows"].sort(key=lambda r: r.get("tick") or r.get("iteration") or 0)
    return out


def last(data, entity, column):
    rows = [r for r in data[entity]["rows"] if r.get(column) is not None]
    return rows[-1][column]


def tensor(cell) -> np.ndarray:
    """A logged 1-D tensor (BarChart values / abscissa) as an array."""
    t = cell[0]
    return np.asarray(t["buffer"]).reshape(t["shape"])


def user_entities(data) -> set[str]:
    return {e for e in data if not e.startswith("/__")}


# ----- a short noise-free rehearsal, every observer call recorded -----

class Tee:
    """Forwards to an observer and records every call (copies), to replay them later;
    blocks of ticks also tick by tick (``on_tick`` records, for lookups)."""

    def __init__(self, target):
        self.target = target
        self.calls = []
        self.ticks = []

    def on_ticks(self, first_tick, deltas, reference, current, laser_mm):
        self.calls.append(("on_ticks", (first_tick, deltas.copy(), reference.copy(),
                                        current.copy(), laser_mm.copy())))
        self.ticks += [(first_tick + i, current[i].copy()) for i in range(len(deltas))]
        self.target.on_ticks(first_tick, deltas, reference, current, laser_mm)

    def on_sample(self, index, qe, d_mm, plate):
        self.calls.append(("on_sample", (index, qe.copy(), d_mm, plate)))
        self.target.on_sample(index, qe, d_mm, plate)

    def on_reject(self, q_target, reason):
        self.calls.append(("on_reject", (None if q_target is None else q_target.copy(), reason)))
        self.target.on_reject(q_target, reason)

    def on_path(self, kind, q_start, q_goal, rows):
        self.calls.append(("on_path", (kind, q_start, q_goal, rows)))
        self.target.on_path(kind, q_start, q_goal, rows)


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


@pytest.fixture(scope="module")
def rehearsal(scene, tmp_path_factory):
    d = tmp_path_factory.mktemp("rehearsal")
    twin = twin_mod.Twin(scene, seed=3, options=twin_mod.TwinOptions.exact())
    world = collision.CollisionWorld(scene, clearance_m=0.01)
    obs = sampling_observer(d / "twin.rrd", scene, twin=twin, every=EVERY, series_every=EVERY,
                            chunk_ticks=1000)  # several bulk sends in a short run
    tee = Tee(obs)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot, tee)
    settings = RunSettings(scene="thesis_final", samples=N_SAMPLES, seed=3)
    stats = SamplingRun(drv, scene, settings, d / "RUN.tsv", world, background=True).run()
    obs.close()
    assert stats.status == "complete" and obs.error is None
    return {"path": obs.path, "calls": tee.calls, "ticks": tee.ticks, "stats": stats,
            "twin": twin,
            "out": d / "RUN.tsv", "dir": d, "data": read_rrd(obs.path), "n_ticks": drv.ticks}


@pytest.fixture(scope="module")
def replayed(scene, rehearsal):
    """The rehearsal's counts and readings fed through the same logger as a real run."""
    obs = sampling_observer(rehearsal["dir"] / "real.rrd", scene, twin=None, every=EVERY,
                            series_every=EVERY)
    for name, args in rehearsal["calls"]:
        getattr(obs, name)(*args)
    obs.close()
    assert obs.error is None
    return {"path": obs.path, "data": read_rrd(obs.path), "obs": obs}


EXPECTED = (["/cell/plates/plate", "/cell/stands/plate_stand", "/cell/floor", "/robot/tool",
             "/robot/tool/laser_head", "/robot/tool/flange_adapter", "/laser/beam", "/laser/hit",
             "/samples/points", "/rejected/collision", "/rejected/laser", "/rejected/unreachable",
             "/series/laser_mm", "/series/model_error_mm", "/events", "/run/info"]
            + [f"/robot/link_{i}" for i in range(7)]
            + ["/series/steps", "/series/joint_deg"])


def test_rehearsal_recording_has_the_documented_entity_tree(rehearsal):
    data = rehearsal["data"]
    missing = [e for e in EXPECTED if e not in data]
    assert not missing, missing
    reader = RrdReader(str(rehearsal["path"]))
    assert len(reader.blueprints()) == 1  # the default blueprint is in the file
    link = data["/robot/link_3"]["rows"]
    assert {"tick", "robot_time", "Transform3D:translation",
            "Transform3D:quaternion"} <= set(link[0])
    # the meshes are static, the motion is not
    assert data["/robot/link_3/elbow"]["static"] and not data["/robot/link_3"]["static"]


def test_samples_logged_equal_the_samples_in_the_run(scene, rehearsal):
    data = rehearsal["data"]
    s = read_samples(rehearsal["out"])
    assert len(s) == rehearsal["stats"].samples == N_SAMPLES
    pts = np.array(last(data, "/samples/points", "Points3D:positions"))
    assert pts.shape == (N_SAMPLES, 3)
    assert len(data["/series/model_error_mm"]["rows"]) == N_SAMPLES
    # colour value: the model error with the nominal parameters [mm]
    err = np.array(last(data, "/samples/points", "error_mm")).ravel()
    expect = (predict(scene.robot, s.qe, nominal_params(scene)) - s.d_mm * 1e-3) * 1e3
    # atol: the file's 1e-6 mm resolution of d_mm (the recording used the unrounded value)
    np.testing.assert_allclose(err, expect, atol=1e-6)


def test_hit_points_lie_on_the_true_plate(rehearsal):
    from planecal.present.rerun.sampling import SAMPLE_RADIUS_M
    data = rehearsal["data"]
    n_t = rehearsal["twin"].truth.planes[0]
    exact = np.column_stack([np.ravel(last(data, "/samples/points", f"hit_{c}_m"))
                             for c in "xyz"])
    dist = np.abs(exact @ n_t - 1.0) / np.linalg.norm(n_t)
    print(f"sample hit points: max distance to the true plane {dist.max():.2e} m")
    assert exact.shape == (N_SAMPLES, 3) and dist.max() < 1e-6, dist.max()
    # the spheres drawn sit on the face: centres one radius off it, on the sensor's side
    pts = np.array(last(data, "/samples/points", "Points3D:positions"))
    signed = (pts @ n_t - 1.0) / np.linalg.norm(n_t)  # + along n~ (the face looks along +n~)
    np.testing.assert_allclose(signed, SAMPLE_RADIUS_M, atol=1e-6)  # float32 positions
    hits = np.array([p for r in data["/laser/hit"]["rows"]
                     for p in (r.get("Points3D:positions") or [])])
    assert len(hits) > N_SAMPLES  # every sample tick plus the readings on logged ticks
    dist = np.abs(hits @ n_t - 1.0) / np.linalg.norm(n_t)
    assert dist.max() < 1e-6, dist.max()


def test_motion_is_downsampled_and_series_hold_the_steps(rehearsal):
    data = rehearsal["data"]
    ticks = np.array([r["tick"] for r in data["/robot/link_1"]["rows"]])
    sample_ticks = {r["tick"] for r in data["/series/model_error_mm"]["rows"]}
    assert len(sample_ticks) == N_SAMPLES and min(sample_ticks) > 0
    assert sample_ticks <= set(ticks.tolist())  # the robot's pose at every sample
    odd = [t for t in ticks if t % EVERY and t not in sample_ticks and t > 1]
    assert not odd
    assert len(ticks) <= rehearsal["n_ticks"] // EVERY + N_SAMPLES + 2
    steps = np.array([r["Scalars:scalars"] for r in data["/series/steps"]["rows"]
                      if r.get("Scalars:scalars")])
    assert steps.shape[1] == 6 and 0 < np.abs(steps).max() <= 51
    laser = [r for r in data["/series/laser_mm"]["rows"] if r["Scalars:scalars"]]
    assert all(65 <= r["Scalars:scalars"][0] <= 95 for r in laser)
    rt = data["/robot/link_1"]["rows"][-1]
    assert rt["robot_time"] == rt["tick"] * 10_000_000  # ns: 10 ms ticks


def test_joint_series_are_one_row_of_six_named_scalars_a_tick(rehearsal):
    # issue 33: a 150-sample --rrd was 37 MB, a third of it the twelve joint series, each
    # row carrying its own row id and two time stamps; one entity per group (q1..q6 as the
    # row's six scalars, named as the legend showed them) writes those once per tick
    data = rehearsal["data"]
    assert not [e for e in data if e.startswith(("/series/steps/", "/series/joint_deg/"))]
    for path in ("/series/steps", "/series/joint_deg"):
        rows = [r for r in data[path]["rows"] if r.get("Scalars:scalars")]
        assert rows and all(len(r["Scalars:scalars"]) == 6 for r in rows)
        assert last(data, path, "SeriesLines:names") == [f"q{j}" for j in range(1, 7)]
    ticks = [r["tick"] for r in data["/series/joint_deg"]["rows"] if r.get("Scalars:scalars")]
    link = [r["tick"] for r in data["/robot/link_1"]["rows"]]
    assert len(ticks) == len(set(ticks)) and set(ticks) <= set(link) | {0}
    size = sum(ch.to_record_batch().nbytes for ch in RrdReader(str(rehearsal["path"])).store()
               .stream() if ch.entity_path.startswith("/series/") and not ch.is_static)
    # 6 scalars (48 B), a row id (16 B) and two time stamps (16 B) a row; twelve entities
    # of one scalar each took 12 * 40 B
    assert size / len(ticks) < 2 * 110, size / len(ticks)


def test_real_replay_has_the_same_entity_tree(rehearsal, replayed):
    twin_tree = user_entities(rehearsal["data"])
    real_tree = user_entities(replayed["data"])
    assert twin_tree == real_tree
    pts = np.array(last(replayed["data"], "/samples/points", "Points3D:positions"))
    assert pts.shape == (N_SAMPLES, 3)
    assert replayed["obs"].kinematics == "nominal"
    # nominal kinematics: the same samples miss the true plate by millimetres
    n_t = rehearsal["twin"].truth.planes[0]
    assert np.max(np.abs(pts @ n_t - 1.0) / np.linalg.norm(n_t)) > 1e-4
    info = last(replayed["data"], "/run/info", "TextDocument:text")[0]
    assert "real run" in info and "nominal" in info


def test_fit_recording_histograms_match_the_optimizer(scene, rehearsal, tmp_path):
    from planecal.estimation.calibrate import CalibrationSettings, calibrate_samples
    s = read_samples(rehearsal["out"])
    cal = calibrate_samples(scene.robot, s, nominal_params(scene))
    res = cal.result
    path = log_fit_to_file(tmp_path, cal, s, scene)
    assert path.parent == tmp_path and path.name.startswith("calibrate-thesis_final-")
    data = read_rrd(path)
    for entity, values in (("/fit/hist/error_before", res.initial_residuals_m * 1e3),
                           ("/fit/hist/error_after", res.residuals_m * 1e3),
                           ("/fit/hist/distance", s.d_mm)):
        counts, edges = np.histogram(values, bins=HIST_BINS)
        row = data[entity]["rows"][-1]
        np.testing.assert_array_equal(tensor(row["BarChart:values"]), counts)
        np.testing.assert_allclose(np.ravel(row["bin_edges_mm"]), edges)
        np.testing.assert_allclose(tensor(row["BarChart:abscissa"]),
                                   0.5 * (edges[1:] + edges[:-1]))
        assert data[entity]["static"]
    rms = data["/fit/rms_mm"]["rows"]
    assert [r["iteration"] for r in rms] == [h.iteration for h in res.history]
    np.testing.assert_allclose([r["Scalars:scalars"][0] for r in rms],
                               [h.rms_m * 1e3 for h in res.history])
    mx = [r["Scalars:scalars"][0] for r in data["/fit/max_mm"]["rows"]]
    np.testing.assert_allclose(mx, [h.max_m * 1e3 for h in res.history])
    table = data["/fit/parameters"]["rows"][-1]["TextDocument:text"][0]
    for name in res.names:
        assert f"| {name} |" in table
    assert "fixed" in table  # delta1, delta6
    ident_text = data["/fit/identifiability"]["rows"][-1]["TextDocument:text"][0]
    assert "Identifiability" in ident_text and "variance factor" not in ident_text
    assert len(last(data, "/samples/points", "Points3D:positions")) == len(s)
    # a weighted fit says so, with its variance factor
    from planecal.estimation.fit import FitOptions
    from planecal.estimation.noise import repeatability_sigma
    from planecal.present.calibration import document
    from planecal.present.rerun.fit import identifiability_markdown
    wcal = calibrate_samples(scene.robot, s, nominal_params(scene), CalibrationSettings(
        options=FitOptions(joint_sigma_rad=repeatability_sigma(scene.robot))))
    f = wcal.result.identifiability.variance_factor
    assert f"variance factor {f:.3g}" in identifiability_markdown(document(wcal))


def test_cli_rehearse_and_calibrate_write_recordings_into_a_directory(tmp_path, capsys):
    rec_dir = tmp_path / "rec"
    rec_dir.mkdir()
    out = tmp_path / "run.tsv"
    code = cli.main(["rehearse", "--out", str(out), "--samples", "15", "--exact", "--seed", "4",
                     "--errors", "ideal", "--foreground", "--rrd", str(rec_dir)])
    assert code == 0
    files = list(rec_dir.glob("rehearse-thesis_final-*.rrd"))
    assert len(files) == 1
    data = read_rrd(files[0])
    assert len(last(data, "/samples/points", "Points3D:positions")) == 15
    capsys.readouterr()
    assert cli.main(["calibrate", str(out), "--rrd", str(rec_dir)]) == 0
    printed = capsys.readouterr().out
    fits = list(rec_dir.glob("calibrate-thesis_final-*.rrd"))
    assert len(fits) == 1 and f"recording written to {fits[0]}" in printed



def test_sample_command_over_the_emulators_records_the_same_tree(rehearsal, tmp_path, capsys):
    """`planecal sample --rrd` (the real-cell command, FD11 UDP + laser pty emulated by a
    twin) writes a recording with the rehearsal's entity tree, nominal kinematics."""
    import json

    from planecal.links.emulators import Emulators

    twin = twin_mod.Twin("thesis_final", seed=2)
    rrd = tmp_path / "real.rrd"
    with Emulators(twin, rt_port=0, reply_port=None) as emu:
        code = cli.main(sample_argv(emu.fd11.rt_port, emu.laser.port, tmp_path / "RUN.tsv",
                                    "--samples", "3", "--rrd", str(rrd)))
    assert code == 0
    assert json.loads(capsys.readouterr().out)["rrd"] == str(rrd)
    data = read_rrd(rrd)
    assert user_entities(data) == user_entities(rehearsal["data"])
    assert len(last(data, "/samples/points", "Points3D:positions")) == 3
    assert "real run" in last(data, "/run/info", "TextDocument:text")[0]


# ----- files -----

def test_recording_path_names_and_errors(tmp_path, monkeypatch):
    from datetime import datetime
    monkeypatch.chdir(tmp_path)
    now = datetime(2026, 1, 2, 3, 4, 5)
    p = recording_path(None, "rehearse", "thesis_final", now)
    assert p == Path("recordings/rehearse-thesis_final-20260102-030405.rrd")
    assert Path("recordings").is_dir()
    p.write_bytes(b"")
    assert recording_path("auto", "rehearse", "thesis_final", now).name.endswith("030405-2.rrd")
    assert recording_path(str(tmp_path), "sample", "s", now).parent == tmp_path
    assert recording_path("new/", "calibrate", "s", now).parent == Path("new")
    assert recording_path("x", "calibrate", "s", now) == Path("x.rrd")
    Path("a").mkdir()
    assert recording_path("a/b.rrd", "c", "s", now) == Path("a/b.rrd")
    with pytest.raises(InputError, match="does not exist"):
        recording_path("nowhere/run.rrd", "rehearse", "s", now)


def test_observer_options_are_checked(scene, tmp_path):
    rec = open_recording(tmp_path / "x.rrd")
    try:
        with pytest.raises(InputError, match="every"):
            SamplingObserver(rec, scene, every=0)
        with pytest.raises(InputError, match="needs the twin"):
            SamplingObserver(rec, scene, kinematics="truth")
    finally:
        rec.disconnect()
    assert reject_kind("collision (path): laser_head - plate") == "collision"
    assert reject_kind("laser: gave up: 400 out-of-range reads in a row") == "laser"
    assert reject_kind("unreachable: no IK solution within limits") == "unreachable"


# ----- planecal view (never spawns a viewer) -----

def test_view_missing_or_bad_file_exits_2(tmp_path, capsys):
    assert cli.main(["view", str(tmp_path / "none.rrd")]) == 2
    assert "no such recording" in capsys.readouterr().err
    bad = tmp_path / "bad.rrd"
    bad.write_text("hello")
    assert cli.main(["view", str(bad)]) == 2
    (tmp_path / "empty").mkdir()
    assert cli.main(["view", str(tmp_path / "empty")]) == 2  # no recordings in it
    assert "no .rrd recording" in capsys.readouterr().err


def test_view_without_display_prints_how(rehearsal, monkeypatch, capsys):
    import subprocess

    from planecal.commands import view

    def no_spawn(*a, **k):
        raise AssertionError("a viewer was spawned")

    monkeypatch.setattr(subprocess, "Popen", no_spawn)
    monkeypatch.setattr(view, "find_viewer", lambda: "/opt/rerun")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(view.sys, "platform", "linux")
    assert cli.main(["view", str(rehearsal["path"])]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and "no display" in out[0] and "--web" in out[0]
    monkeypatch.setattr(view, "find_viewer", lambda: None)
    assert cli.main(["view", str(rehearsal["path"])]) == 1
    assert "pip install rerun-sdk" in capsys.readouterr().out
    # with a display the viewer would be started on the file (faked here)
    calls = []
    monkeypatch.setattr(view, "find_viewer", lambda: "/opt/rerun")
    monkeypatch.setenv("DISPLAY", ":0")
    class FakeViewer:
        def __init__(self, cmd, **kw):
            calls.append(cmd)

        def wait(self, timeout=None):
            return 0

    monkeypatch.setattr(subprocess, "Popen", FakeViewer)
    assert cli.main(["view", str(rehearsal["path"])]) == 0
    assert calls == [["/opt/rerun", str(rehearsal["path"])]]
    assert cli.main(["view", "--web", str(rehearsal["path"])]) == 0
    assert calls[-1] == ["/opt/rerun", str(rehearsal["path"]), "--serve-web", "--bind", "127.0.0.1"]


def test_view_summary_lists_the_entity_tree(rehearsal, capsys):
    assert cli.main(["view", "--summary", str(rehearsal["path"])]) == 0
    lines = capsys.readouterr().out.splitlines()
    entities = {ln.split("\t")[0] for ln in lines}
    assert set(EXPECTED) <= entities
    views = [ln.split("\t")[1:] for ln in lines if ln.startswith("view:\t")]
    assert ["3D", "cell: rehearsal on the twin", "/"] in views
    assert ["TextDocument", "run info and legend", "/run/info"] in views


def test_cell_entities_follow_the_scene(tmp_path):
    """Every plate, stand and obstacle of the scene is in the tree (real-run observer)."""
    for name, expect in (("three_plates", ["/cell/plates/plate_a", "/cell/plates/plate_b",
                                           "/cell/plates/plate_c"]),
                         ("obstacle_test", ["/cell/plates/plate", "/cell/obstacles/fin"])):
        sc = load_scene(name)
        obs = sampling_observer(tmp_path / f"{name}.rrd", sc)
        obs.close()
        data = read_rrd(obs.path)
        assert set(expect) <= set(data), name
        assert "/cell/floor" in data and "/robot/tool/laser_head" in data


def test_a_logging_error_is_reported_and_does_not_stop_the_run(scene, tmp_path, capsys):
    obs = sampling_observer(tmp_path / "e.rrd", scene, chunk_ticks=10)

    def broken(*a):
        raise ValueError("boom")

    obs._log_motion = broken
    base = scene.robot.home_counts
    for k in range(1, 35):  # three bulk sends fail in the sender thread
        obs.on_ticks(k, np.zeros((1, 6), np.int64), base, base[None], np.full(1, np.nan))
    obs.on_sample(0, base, 80.0, 0)  # logged directly, still works
    obs.close()
    assert isinstance(obs.error, ValueError)
    assert "rerun logging: ValueError: boom" in capsys.readouterr().err
    data = read_rrd(obs.path)
    assert len(last(data, "/samples/points", "Points3D:positions")) == 1


def test_logged_tool_frame_is_the_kinematics_at_that_tick(scene, rehearsal):
    """/robot/tool at a sample's tick = frame 6 of the twin's truth kinematics for the
    counts of that tick (translation + quaternion, float32)."""
    from scipy.spatial.transform import Rotation

    from planecal.model.encoder import counts_to_joints
    from planecal.model.kinematics import link_frames

    data = rehearsal["data"]
    tick = max(r["tick"] for r in data["/series/model_error_mm"]["rows"])
    cur = next(c for t, c in rehearsal["ticks"] if t == tick)
    F = link_frames(scene.robot.kinematics.with_offsets(rehearsal["twin"].truth.joint_offsets), counts_to_joints(scene.robot, cur))[6]
    row = next(r for r in data["/robot/tool"]["rows"] if r["tick"] == tick)
    np.testing.assert_allclose(np.ravel(row["Transform3D:translation"]), F[:3, 3], atol=1e-6)
    R = Rotation.from_quat(np.ravel(row["Transform3D:quaternion"])).as_matrix()
    np.testing.assert_allclose(R, F[:3, :3], atol=1e-6)


def test_matrix_to_quaternion_handles_half_turns():
    from scipy.spatial.transform import Rotation

    from planecal.present.rerun.sampling import matrix_to_quaternion

    rng = np.random.default_rng(0)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    rots = [Rotation.random(200, random_state=1), Rotation.from_rotvec(axes * np.pi),
            Rotation.from_euler("x", [[180], [90], [0]], degrees=True)]
    for rot in rots:
        M = rot.as_matrix()
        q = matrix_to_quaternion(M)
        np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), M, atol=1e-12)
