"""The sampling-run observer: one logger for twin rehearsals and real runs.

Per tick the loop hands over (tick, delta, reference, current, laser); the observer only
keeps a reference to them in a list (well under 1 us). Every ``chunk_ticks`` ticks (4096
on the twin, 1000 = 10 s on the real cell) and at ``close()`` the buffered ticks go to a
sender thread that converts them in bulk -- kinematics vectorised over the ticks, every
entity sent with one ``rr.send_columns`` call -- so the tick loop never waits for a bulk
send (at most for the GIL). An error there is reported by ``close()`` on stderr (and kept
in ``.error``); it never stops the run. Motion (robot frames,
beam, hit) is logged every ``every`` ticks plus the first tick and each sample's tick;
the series (step counts, joint angles) every ``series_every`` ticks; every laser
reading is logged. Samples and rejections are logged as they happen.

Kinematics: the twin's hidden truth (offsets, sensor pose, planes) when a twin is given
(``kinematics="truth"``), else the scene's nominal values -- the only ones a real run has.
The colour (model error) of a sample always uses ``params`` (default: the scene's
nominal values), so a rehearsal and a real run are coloured alike. Joint angles come from
the counts through the nominal encoder model (``counts_to_joints``). The twin's random
joint errors (repeatability, compliance, backlash) are not in the logged kinematics.
"""
from __future__ import annotations

import os
import queue
import sys
import threading

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import beam_direction, predict, sensor_in_base
from planecal.model.encoder import counts_to_joints
from planecal.base.errors import InputError
from planecal.model.kinematics import link_frames
from planecal.present.rerun.common import (BEAM_NONE_RGBA, BEAM_RADIUS_M, BEAM_RGBA, HIT_RADIUS_M,
                                       HIT_RGBA, REJECT_RGBA, _rr, close_recording,
                                       hit_columns, lifted, log_cell, log_robot_meshes,
                                       matrix_to_quaternion, open_recording,
                                       plate_face_normal, recording_path, sequential_colors)
from planecal.present.rerun.sampling_blueprint import sampling_blueprint
from planecal.sampling.collect import REJECT_KINDS
from planecal.sampling.observer import NullObserver

DEFAULT_EVERY = 5
DEFAULT_CHUNK_TICKS = 4096  # twin: ~0.1 s of wall time
REAL_CHUNK_TICKS = 1000  # real cell: 10 s; the recording is never far behind
N_JOINTS = 6
SAMPLE_RADIUS_M = 0.004
ALL_SAMPLES_RADIUS_M = 0.0025  # /samples/all: the whole run's samples, static (at close)
REJECT_LENGTH_M = 0.08  # length of the arrow marking a rejected pose (along the beam)

TICK_ENTITIES = ([f"/robot/link_{i}" for i in range(1, N_JOINTS + 1)]
                 + ["/robot/tool", "/laser/beam", "/laser/hit"])
# one entity per joint group, six scalars a row (named q1..q6): a row's id and two time
# stamps are written once for the six joints, not six times (a third of the file's size)
JOINT_SERIES = ["/series/steps", "/series/joint_deg"]
SERIES_ENTITIES = JOINT_SERIES + ["/series/laser_mm", "/series/model_error_mm"]
EVENT_ENTITIES = ["/samples/points"] + [f"/rejected/{k}" for k in REJECT_KINDS] + ["/events"]


def reject_kind(reason: str) -> str:
    """'collision', 'laser' or 'unreachable' from a run's rejection reason text."""
    head = reason.split(":", 1)[0].strip().split(" ", 1)[0].lower()
    return head if head in REJECT_KINDS else "unreachable"


def _env_int(name: str, default: int) -> int:
    v = os.environ.get(name)
    if v is None or not v.strip():
        return default
    try:
        return int(v)
    except ValueError:
        raise InputError(f"{name}: must be an integer, got {v!r}") from None


class SamplingObserver(NullObserver):
    """An ``Observer`` (``planecal.sampling.observer``) writing a Rerun recording.

    ``rec``: an open RecordingStream (``open_recording``); ``close()`` finishes it.
    ``twin``: the twin, for its hidden truth (kinematics) and start pose; None for a real
    run. ``params``: parameters that colour the samples by model error (default nominal).
    ``every``: motion downsampling (ticks); ``series_every``: series downsampling;
    ``chunk_ticks``: ticks buffered before a bulk send. The arrays handed to ``on_ticks``
    are kept by reference until the next bulk send (the links return fresh arrays)."""

    def __init__(self, rec, scene, *, twin=None, params: CellParams | None = None,
                 kinematics: str = "auto", every: int = DEFAULT_EVERY,
                 series_every: int = DEFAULT_EVERY,
                 chunk_ticks: int | None = None, background: bool = True, path=None,
                 source: str | None = None, drop_when_behind: bool = False):
        from planecal.model.scene import nominal_params

        if chunk_ticks is None:
            chunk_ticks = DEFAULT_CHUNK_TICKS if twin is not None else REAL_CHUNK_TICKS
        for name, v in (("every", every), ("series_every", series_every),
                        ("chunk_ticks", chunk_ticks)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise InputError(f"rerun logging: {name} must be a positive integer, got {v!r}")
        if kinematics == "auto":
            kinematics = "truth" if twin is not None else "nominal"
        if kinematics not in ("truth", "nominal"):
            raise InputError(f"rerun logging: kinematics must be 'truth', 'nominal' or 'auto', "
                             f"got {kinematics!r}")
        if kinematics == "truth" and twin is None:
            raise InputError("rerun logging: kinematics 'truth' needs the twin")
        self.rec = rec
        self.rr = _rr()
        self.scene = scene
        self.robot = scene.robot
        self.path = path
        self.source = source or ("twin" if twin is not None else "real")
        self.kinematics = kinematics
        nominal = nominal_params(scene)
        self.kin = twin.truth if kinematics == "truth" else nominal
        self.model = params.copy() if params is not None else nominal
        self.params_given = params is not None
        self.every = int(every)
        self.series_every = int(series_every)
        self.chunk_ticks = int(chunk_ticks)
        self.tick_s = float(self.robot.tick_s)
        self.tick_ns = int(round(self.tick_s * 1e9))  # robot_time in whole nanoseconds
        self._buf: list = []  # blocks of ticks (first tick, deltas, counts, readings)
        self._buffered = 0
        self._force: set[int] = set()
        self._prev_delta = np.zeros(N_JOINTS, np.int64)
        self._first = True
        self._last_tick = 0
        self._zf = beam_direction(self.kin.phi_y, self.kin.phi_z)
        self._beam_none_m = float(scene.laser_range_mm[1]) * 1e-3
        self._samples_p: list[np.ndarray] = []
        self._samples_e: list[float] = []
        self._samples_n: list[np.ndarray] = []
        self._samples_plate: list[int] = []
        self._samples_index: list[int] = []
        self._rejected = {k: ([], [], []) for k in REJECT_KINDS}  # origins, vectors, reasons
        self.rejections = {k: 0 for k in REJECT_KINDS}
        self.ticks_seen = 0
        self.ticks_logged = 0
        self.live = None  # where a live view is served (``sampling_observer`` sets it)
        self.drop_when_behind = bool(drop_when_behind and background)
        self.dropped_ticks = self.dropped_events = 0
        self._resync: np.ndarray | None = None  # the last delta of a dropped chunk
        self._closed = False
        self.error: Exception | None = None
        self._static(twin)
        self._queue = self._worker = None
        if background:  # a live view queues events too, and flushes the static cell now
            self._queue = queue.Queue(maxsize=64 if self.drop_when_behind else 4)
            self._worker = threading.Thread(target=self._work, name="planecal-rerun",
                                            daemon=True)
            self._worker.start()
        if self.drop_when_behind:
            self._warm()
            rec.flush()  # the static cell through rerun's batcher before the first tick

    def _warm(self) -> None:
        """Run the sender's kinematics once before the first tick: a first call loads
        numba's compiled kernels, holding the interpreter for tens of milliseconds."""
        qe = np.asarray(self.robot.qe0, np.int64)[None]
        q = counts_to_joints(self.robot, qe)
        sensor_in_base(self.robot, q, self.kin)
        predict(self.robot, qe, self.model, np.zeros(1, int))
        matrix_to_quaternion(link_frames(self.robot.kinematics, q)[:, 1:, :3, :3])

    # ----- set-up -----
    def _static(self, twin) -> None:
        rr, rec = self.rr, self.rec
        log_cell(rec, self.scene, self.kin.planes if self.kinematics == "truth" else None)
        log_robot_meshes(rec, self.scene, self.kin)
        self._info()
        # every dynamic entity exists from tick 0, so all runs have the same entity tree
        self._time(0)
        rec.log("/laser/beam", rr.Arrows3D(vectors=np.zeros((0, 3))))
        rec.log("/laser/hit", rr.Points3D(np.zeros((0, 3))))
        rec.log("/laser/hit", rr.Points3D.from_fields(colors=[HIT_RGBA], radii=[HIT_RADIUS_M]),
                static=True)  # style only; the positions are temporal
        rec.log("/samples/points", rr.Points3D(np.zeros((0, 3))))
        for path in JOINT_SERIES:
            rec.log(path, rr.SeriesLines(names=[f"q{j}" for j in range(1, N_JOINTS + 1)]),
                    static=True)
        for k in REJECT_KINDS:
            rec.log(f"/rejected/{k}", rr.Arrows3D(vectors=np.zeros((0, 3))))
        rec.log("/events", rr.TextLog(f"recording a {self.source} run on scene "
                                      f"{self.scene.name} ({self.kinematics} kinematics)",
                                      level="INFO"))
        if twin is not None:  # the pose before the first tick
            self._log_motion(np.array([0]), np.asarray(twin.current_counts, np.int64)[None],
                             np.array([np.nan]))

    def _info(self, final: str = "") -> None:
        k = self.kin
        txt = (f"# {self.source} run, scene `{self.scene.name}`\n\n"
               f"* kinematics: **{self.kinematics}** "
               + ("(the twin's hidden truth: offsets, sensor pose, planes)"
                  if self.kinematics == "truth" else "(the scene's nominal values)") + "\n"
               f"* joint offsets [mrad]: {np.array2string(k.joint_offsets * 1e3, precision=4)}\n"
               f"* **sample colour** = order of acquisition: first sample dark blue, then "
               f"purple, orange, last (so far) yellow. Spheres sit on the plate face "
               f"(exact hit points: `hit_x_m`, `hit_y_m`, `hit_z_m`)\n"
               f"* small dots (`/samples/all`, written at the end): every sample of the run; "
               f"big spheres (`/samples/points`): the samples taken up to the time cursor\n"
               f"* **beam** green (grey: no reading), hit point light green\n"
               f"* **rejections** (start hidden; tick `/rejected` on in the blueprint panel): "
               f"collision red, laser orange, unreachable purple\n"
               f"* model error (series, hover): predicted - measured distance with "
               f"{'the given' if self.params_given else 'the nominal'} parameters\n"
               f"* motion logged every {self.every} ticks (+ first tick and sample ticks); "
               f"series every {self.series_every} tick(s); tick = {self.tick_s * 1e3:g} ms\n"
               + final)
        self.rec.log("/run/info", self.rr.TextDocument(txt, media_type="text/markdown"),
                     static=True)

    def _time(self, tick: int) -> None:
        self.rec.set_time("tick", sequence=int(tick))
        self.rec.set_time("robot_time", duration=np.timedelta64(int(tick) * self.tick_ns, "ns"))

    # ----- Observer -----
    def on_ticks(self, first_tick, deltas, reference, current, laser_mm):
        # the last block stays buffered until the next one: a sample's tick, marked by
        # on_sample after its block, is still there to be logged with it
        if self._buffered >= self.chunk_ticks:
            self._submit()
        n = len(deltas)
        self._buf.append((first_tick, deltas, current, laser_mm))
        self._buffered += n
        self._last_tick = first_tick + n - 1

    def _event(self, fn, *args) -> None:
        """Log an event here, or (a live view of the real cell) hand it to the sender: the
        real-time loop only queues it, dropped (and counted) if the queue is full."""
        if not self.drop_when_behind:
            fn(*args)
            return
        try:
            self._queue.put_nowait(("event", fn, args))
        except queue.Full:
            self.dropped_events += 1

    def on_sample(self, index, qe, d_mm, plate):
        self._force.add(self._last_tick)
        self._event(self._sample, index, np.array(qe, np.int64), d_mm, plate, self._last_tick)

    def _sample(self, index, qe, d_mm, plate, tick):
        rr, rec = self.rr, self.rec
        qe = np.asarray(qe, np.int64).reshape(1, N_JOINTS)
        plate = int(plate or 0)
        d_m = float(d_mm) * 1e-3
        q = counts_to_joints(self.robot, qe)
        o_b, z_b = sensor_in_base(self.robot, q, self.kin)
        p = (o_b + d_m * z_b)[0]
        pl = min(plate, self.model.n_planes - 1)
        err_mm = float((predict(self.robot, qe, self.model, np.array([pl]))[0] - d_m) * 1e3)
        self._samples_p.append(p)
        self._samples_n.append(plate_face_normal(
            self.scene, min(plate, len(self.scene.plates) - 1),
            self.kin.planes if self.kinematics == "truth" else None))
        self._samples_e.append(err_mm)
        self._samples_plate.append(plate)
        self._samples_index.append(int(index))
        self._time(tick)
        self._log_samples()
        rec.log("/series/model_error_mm", rr.Scalars(err_mm))
        rec.log("/events", rr.TextLog(f"sample {index}: {d_mm:.4f} mm on plate {plate + 1}, "
                                      f"model error {err_mm:+.4f} mm", level="INFO"))

    def _log_samples(self) -> None:
        rr = self.rr
        e = np.array(self._samples_e)
        k = np.arange(len(e))
        self.rec.log("/samples/points",
                     rr.Points3D(lifted(self._samples_p, self._samples_n, SAMPLE_RADIUS_M),
                                 colors=sequential_colors(k, 0, max(len(e) - 1, 1)),
                                 radii=SAMPLE_RADIUS_M, show_labels=False,
                                 labels=[f"sample {i}: {v:+.4f} mm" for i, v in
                                         zip(self._samples_index, self._samples_e)]),
                     rr.AnyValues(error_mm=e, sample=np.array(self._samples_index),
                                  plate=np.array(self._samples_plate),
                                  **hit_columns(np.array(self._samples_p))))

    def on_reject(self, q_target, reason):
        self._event(self._reject, None if q_target is None else np.array(q_target, float),
                    reason, self._last_tick)

    def _reject(self, q_target, reason, tick):
        rr, rec = self.rr, self.rec
        kind = reject_kind(reason)
        self.rejections[kind] += 1
        self._time(tick)
        if q_target is not None:
            o_b, z_b = sensor_in_base(self.robot, np.asarray(q_target, float)[None], self.kin)
            origins, vectors, reasons = self._rejected[kind]
            origins.append(o_b[0])
            vectors.append(z_b[0] * REJECT_LENGTH_M)
            reasons.append(reason)
            rec.log(f"/rejected/{kind}",  # the reason shows on hover (labels hidden)
                    rr.Arrows3D(origins=np.array(origins), vectors=np.array(vectors),
                                colors=REJECT_RGBA[kind], radii=BEAM_RADIUS_M,
                                labels=reasons, show_labels=False))
        rec.log("/events", rr.TextLog(f"rejected ({kind}): {reason}", level="WARN"))

    def on_path(self, kind, q_start, q_goal, rows):
        if kind != "sample":
            self._event(self._move, kind, len(rows), self._last_tick)

    def _move(self, kind, ticks, tick):
        self._time(tick)
        self.rec.log("/events", self.rr.TextLog(f"move ({kind}): {ticks} ticks", level="INFO"))

    # ----- bulk sends -----
    def _submit(self) -> None:
        """Hand the buffered ticks to the sender thread (or send them here)."""
        buf = self._buf
        if not buf:
            return
        self._buf, self._buffered = [], 0
        last = buf[-1][0] + len(buf[-1][1]) - 1
        force = np.fromiter(self._force, np.int64, len(self._force))
        self._force = {k for k in self._force if k > last}
        first, self._first = self._first, False
        prev, self._resync = self._resync, None
        if self._queue is None:
            self._flush(buf, force, first, prev)
        elif not self.drop_when_behind:
            self._queue.put(("ticks", self._flush, (buf, force, first, prev)))  # may wait
        else:
            try:
                self._queue.put_nowait(("ticks", self._flush, (buf, force, first, prev)))
            except queue.Full:  # the real-time loop never waits for the viewer
                self.dropped_ticks += sum(len(r[1]) for r in buf)
                self._resync = np.asarray(buf[-1][1][-1], np.int64)

    def _work(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                return
            if self.error is None:
                try:
                    item[1](*item[2])
                except Exception as e:  # reported by close(); the run goes on
                    self.error = e

    def _flush(self, buf, force, first, prev=None) -> None:
        if prev is not None:  # after a dropped chunk: steps from the delta it ended at
            self._prev_delta = prev
        t = np.concatenate([np.arange(r[0], r[0] + len(r[1]), dtype=np.int64) for r in buf])
        delta = np.concatenate([r[1] for r in buf]).astype(np.int64, copy=False)
        cur = np.concatenate([r[2] for r in buf]).astype(np.int64, copy=False)
        laser = np.concatenate([r[3] for r in buf]).astype(float, copy=False)
        self.ticks_seen += len(t)
        steps = np.diff(delta, axis=0, prepend=self._prev_delta[None])
        self._prev_delta = delta[-1].copy()
        self._log_series(t, steps, cur, laser)
        m = (t % self.every) == 0
        m[0] |= first
        if len(force):
            m |= np.isin(t, force)
        self._log_motion(t[m], cur[m], laser[m])

    def _indexes(self, t):
        rr = self.rr
        return [rr.TimeColumn("tick", sequence=t),
                rr.TimeColumn("robot_time", duration=(t * self.tick_ns).astype("timedelta64[ns]"))]

    def _log_series(self, t, steps, cur, laser) -> None:
        rr, rec = self.rr, self.rec
        s = (t % self.series_every) == 0 if self.series_every > 1 else slice(None)
        ts = t[s]
        if len(ts):
            idx = self._indexes(ts)
            qdeg = np.rad2deg(counts_to_joints(self.robot, cur[s]))
            st = steps[s]
            for path, v in zip(JOINT_SERIES, (st.astype(float), qdeg)):
                rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(scalars=v))
        ok = np.isfinite(laser)
        if ok.any():
            rec.send_columns("/series/laser_mm", indexes=self._indexes(t[ok]),
                             columns=rr.Scalars.columns(scalars=laser[ok]))

    def _log_motion(self, t, cur, laser) -> None:
        if not len(t):
            return
        rr, rec = self.rr, self.rec
        self.ticks_logged += len(t)
        q = counts_to_joints(self.robot, cur)
        F = link_frames(self.robot.kinematics.with_offsets(self.kin.joint_offsets), q)
        idx = self._indexes(t)
        # quaternions (x, y, z, w): rerun converts them 80x faster than 3x3 matrices
        quat = matrix_to_quaternion(F[:, 1:, :3, :3])
        for b in range(1, N_JOINTS + 1):
            rec.send_columns(f"/robot/link_{b}", indexes=idx,
                             columns=rr.Transform3D.columns(translation=F[:, b, :3, 3],
                                                            quaternion=quat[:, b - 1]))
        F6 = F[:, N_JOINTS]
        rec.send_columns("/robot/tool", indexes=idx,
                         columns=rr.Transform3D.columns(translation=F6[:, :3, 3],
                                                        quaternion=quat[:, N_JOINTS - 1]))
        R = F6[:, :3, :3]
        o_b = R @ self.kin.sensor_origin + F6[:, :3, 3]
        z_b = R @ self._zf
        has = np.isfinite(laser)
        d = np.where(has, laser * 1e-3, self._beam_none_m)
        colors = np.where(has[:, None], np.array(BEAM_RGBA), np.array(BEAM_NONE_RGBA))
        rec.send_columns("/laser/beam", indexes=idx,
                         columns=rr.Arrows3D.columns(origins=o_b, vectors=z_b * d[:, None],
                                                     colors=colors.astype(np.uint8),
                                                     radii=np.full(len(t), BEAM_RADIUS_M)))
        hits = (o_b + d[:, None] * z_b)[has]
        rec.send_columns("/laser/hit", indexes=idx,
                         columns=rr.Points3D.columns(positions=hits.reshape(-1, 3))
                         .partition(has.astype(np.int64)))

    # ----- end -----
    def close(self) -> None:
        """Send what is buffered, note the totals in /run/info, finish the file."""
        if self._closed:
            return
        self._closed = True
        try:
            self._submit()
            if self._worker is not None:
                self._queue.put(None)
                self._worker.join()
            if self.error is not None:
                print(f"rerun logging: {type(self.error).__name__}: {self.error} "
                      f"(the recording {self.path or ''} lacks some motion)", file=sys.stderr)
            e = np.array(self._samples_e)
            if e.size:  # the whole run at any time cursor: small dots under the big spheres
                self.rec.log("/samples/all", self.rr.Points3D(
                    lifted(self._samples_p, self._samples_n, ALL_SAMPLES_RADIUS_M),
                    colors=sequential_colors(np.arange(len(e)), 0, max(len(e) - 1, 1)),
                    radii=ALL_SAMPLES_RADIUS_M), static=True)
            rms = f"{np.sqrt(np.mean(e ** 2)):.4f} mm" if e.size else "-"
            self._info(f"* samples: **{len(e)}**, model error RMS {rms}\n"
                       f"* rejected: {', '.join(f'{k} {v}' for k, v in self.rejections.items())}\n"
                       f"* ticks: {self.ticks_seen} (motion logged at {self.ticks_logged})\n"
                       + (f"* live view: {self.dropped_ticks} ticks and {self.dropped_events} "
                          "events dropped while the sender was behind (the real-time loop "
                          "never waits)\n" if self.dropped_ticks or self.dropped_events
                          else ""))
        finally:
            close_recording(self.rec)


def sampling_observer(path, scene, twin=None, *, command: str | None = None, live=None,
                      **options):
    """The observer of ``planecal rehearse`` / ``sample`` ``--rrd`` and ``--live``.
    ``path`` goes through ``recording_path`` (a directory or "auto" gives a generated
    name; None with ``live``: no file); ``.path`` is the file written. ``live``: a
    ``live.LiveOptions`` to serve the stream (``.live``: where), a real run's observer
    then dropping what its sender cannot keep up with. ``options``: see
    ``SamplingObserver``; ``every`` and ``series_every`` default to
    $PLANECAL_RERUN_EVERY / $PLANECAL_RERUN_SERIES_EVERY."""
    command = command or ("rehearse" if twin is not None else "sample")
    p = None if path is None and live else recording_path(path, command, scene.name)
    options.setdefault("every", _env_int("PLANECAL_RERUN_EVERY", DEFAULT_EVERY))
    options.setdefault("series_every", _env_int("PLANECAL_RERUN_SERIES_EVERY", DEFAULT_EVERY))
    bp, name = sampling_blueprint(scene, "real" if twin is None else "rehearsal"), \
        f"{command} {scene.name}"
    view = None
    if live:
        from planecal.present.rerun.live import open_live
        rec, view = open_live(bp, name, live, p)
        options.setdefault("drop_when_behind", twin is None)
    else:
        rec = open_recording(p, bp, name=name)
    try:
        obs = SamplingObserver(rec, scene, twin=twin, path=p, **options)
    except BaseException:
        close_recording(rec)
        raise
    obs.live = view
    return obs
