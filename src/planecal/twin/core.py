"""The digital twin: the robot behind an FD11 real-time link and the ZS-LD80 laser, in
process, on a virtual clock (one ``exchange`` = one 10 ms tick; no wall-clock sleeps).

FD11 semantics (appendix C): the reference counts are fixed at start (the robot's
counts then); each tick the host sends ``delta`` and the controller commands
``reference + delta``; consecutive deltas that differ by more than ``trip_step_counts``
(60) on a joint trip an encoder-jump error and brake the robot (``EncoderJumpError``;
the twin then refuses further ticks).

State and truth: the twin holds integer encoder counts (int64). The joint angles are
``counts_to_joints(robot, counts)`` (nominal qe0, the coupling C) and the true joint
offsets are added in MuJoCo's qpos, ``qpos = q + delta_true (+ joint errors)``; the model's
bodies carry the nominal DH (``mjcf``), so MuJoCo's link frames equal
``robot.fk_frames(robot, q, delta_true)``. The laser site and the plates sit at the
truth's sensor pose and planes. With noise and joint errors off, ``read()`` equals
``cell.predict(robot, counts, truth, plate) * 1000`` (mm).

Kinematics and the ray are recomputed lazily, only when the counts (or joint errors)
changed since the last reading: a robot at rest costs a laser-noise draw per reading.
``Twin.run(deltas)`` does many ticks (exchange + read each) in one call: the tick loop
compiled (``ticks``, numba: FD11 trip check, servo, rest and repeatability logic, counts
-> joints, laser model) and the beams of all its moving ticks cast in one MuJoCo call
(``beam``: MuJoCo kinematics + ``mj_ray`` per tick in C, ~1 us with a hit, intersecting
in the laser's frame). Against the per-tick loop: the same counts, joint states and
random streams bit for bit, readings to ~1e-12 mm (the caster's frame). ``_run_ref`` is
the same in numpy and the bindings; with the same caster it gives ``run``'s readings bit
for bit (the reference the tests hold ``run`` to, and the path with compliance or
backlash on).
scripts/bench_twin.py measures the throughput.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np

from planecal.cell import CellParams
from planecal.encoder import counts_in_range, joints_to_counts
from planecal.errors import InputError
from planecal.scene import Scene, load_scene
from planecal.twin.beam import BeamCaster
from planecal.twin.laser import LaserModel, RayCaster
from planecal.twin.mjcf import (FLANGE_SITE, LASER_SITE, TOOL_BODY, plate_geom_names,
                                 scene_spec)
from planecal.twin.servo import JointErrors, Servo
from planecal.twin.truth import resolve_truth


class EncoderJumpError(RuntimeError):
    """The commanded counts jumped more than the FD11 allows in one tick: robot braked."""


@dataclass(frozen=True)
class TwinOptions:
    """Behaviour of the twin. ``exact()`` turns every error source off.

    servo: 'ideal' or 'lag' (first order, ``tau_s``); laser_noise_mm: Gaussian std of a
    reading; repeatability_mm: None = the robot's (robot.json), 0 = off;
    stiffness_nm_per_rad: (k2, k3) joint 2/3 stiffness for gravity compliance, None = off;
    backlash_rad: (6,) backlash, None = off; noise_seed: seed of the noise streams
    (None: derived from the truth seed); check_steps: trip on FD11 encoder jumps."""
    servo: str = "lag"
    tau_s: float = 0.03
    laser_noise_mm: float = 0.001
    laser_quantum_mm: float | None = None
    repeatability_mm: float | None = None
    stiffness_nm_per_rad: tuple | None = None
    backlash_rad: tuple | None = None
    noise_seed: int | None = None
    check_steps: bool = True

    def __post_init__(self):
        if self.servo not in ("ideal", "lag"):
            raise InputError(f"twin: servo must be 'ideal' or 'lag', got {self.servo!r}")
        for name in ("tau_s", "laser_noise_mm", "laser_quantum_mm", "repeatability_mm"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0 and (v > 0 or name != "tau_s")):
                raise InputError(f"twin: {name} must be a finite number >= 0"
                                 f"{' (> 0)' if name == 'tau_s' else ''}, got {v!r}")

    @classmethod
    def exact(cls, **kw) -> "TwinOptions":
        base = cls(servo="ideal", laser_noise_mm=0.0, repeatability_mm=0.0)
        return replace(base, **kw)


@dataclass
class Hit:
    distance_m: float | None
    geom: int
    name: str | None
    plate: int | None  # index into scene.plates, None if not a plate


def _add_settled_errors(Q: np.ndarray, cuts: list, errors) -> None:
    """Add each repeatability perturbation to the rows from its settle tick on: rows
    cuts[i]..cuts[i+1] get the perturbation drawn at the i-th settle (none drawn for i=0)."""
    for i in range(len(cuts) - 1):
        if i:
            errors.on_settle()
        Q[cuts[i]:cuts[i + 1]] += errors.eps


class Twin:
    """In-process robot link (``RobotLink``) and laser (``Laser``) over a MuJoCo model.

    Twin(scene="thesis_final" | Scene | path, truth=None | CellParams | path | "nominal",
         seed=0, options=TwinOptions(), start_counts=None)

    ``truth`` None draws the hidden truth from ``seed`` (``truth.draw_truth``).
    ``start_counts`` default: the scene's calibration position (nominal encoder model),
    else its home counts. The reference counts of the FD11 link are these.

    RobotLink / Laser: ``exchange(delta)`` (one tick), ``read()``, ``close()``.
    More ticks at once: ``run(deltas)`` (``prepare_run()`` builds its caster ahead).
    Tests and tools: ``set_counts(counts)`` (jump there, at rest), ``hit()`` (true
    distance, geom, plate), ``flange_pose()``, ``sensor_pose()``, ``qpos``, ``to_xml()``.
    State: ``ticks``, ``robot_time_s``,
    ``current_counts``, ``reference_counts``, ``commanded_counts``. For others (collision
    cross-checks, Rerun): ``model``, ``data`` (MjModel/MjData, last kinematics: call
    ``hit()`` or ``read()`` first), ``spec``, ``laser_site``, ``flange_site``,
    ``tool_body``. ``truth`` / ``true_params``: the hidden truth, never for calibration.

    ``batch_rays`` (class default True): ``run`` runs its ticks in the compiled loop
    (``ticks``) and casts the beams of all its moving ticks in one MuJoCo call
    (``beam.BeamCaster``: kinematics and ``mj_ray`` per tick in C); False, or a model the
    caster doesn't cover, or compliance / backlash on, or numba unavailable (a warning):
    ``_run_ref`` with one
    ``mj_kinematics`` + ``mj_ray`` per moving tick through the bindings (same counts and
    random streams, readings equal to ~1e-12 mm: tests/test_twin_batch.py).
    """

    batch_rays: bool = True

    def __init__(self, scene: Scene | str | Path = "thesis_final", truth=None, seed: int = 0,
                 options: TwinOptions | None = None, start_counts=None):
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError(f"twin: seed must be a non-negative integer, got {seed!r}")
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.robot = self.scene.robot
        self.options = options or TwinOptions()
        self.seed = seed
        self._truth = resolve_truth(self.scene, truth, seed)
        robot = self.robot
        start = self._start_counts(start_counts)
        cal_qpos = None
        if self.scene.calibration_q is not None:
            cal_qpos = self.scene.calibration_q + self._truth.joint_offsets
        self.spec = scene_spec(self.scene, self._truth, calibration_qpos=cal_qpos)
        self.model = self.spec.compile()
        self._data = mujoco.MjData(self.model)
        self.laser_site = self.model.site(LASER_SITE).id
        self.flange_site = self.model.site(FLANGE_SITE).id
        self.tool_body = self.model.body(TOOL_BODY).id
        self._plate_of_geom = {self.model.geom(name).id: i
                               for i, name in enumerate(plate_geom_names(self.scene))}
        self._ray = RayCaster(self.model, self._data, self.laser_site, self.tool_body)
        self._beam: BeamCaster | None | bool = None  # run's batch path, made on first use
        opt = self.options
        noise_seed = opt.noise_seed if opt.noise_seed is not None else (seed * 7919 + 1)
        ss = np.random.SeedSequence(noise_seed)
        rng_laser, rng_joint = (np.random.default_rng(s) for s in ss.spawn(2))
        self._laser = LaserModel(self.scene.laser_range_mm, opt.laser_noise_mm,
                                 opt.laser_quantum_mm, rng_laser)
        rep_m = robot.repeatability_m if opt.repeatability_mm is None else opt.repeatability_mm * 1e-3
        self._errors = JointErrors(robot, rng_joint, rep_m, opt.stiffness_nm_per_rad,
                                   opt.backlash_rad)
        try:
            self._servo = Servo(start, opt.servo, opt.tau_s, robot.tick_s)
        except ValueError as e:
            raise InputError(f"twin: {e}") from None
        # q_j = sum_k M[j,k] (counts_k - qe0_k), M = C diag(1/g), qe0 nominal (the
        # controller's); kept as Python (k, M[j,k]) lists for the per-tick path
        M = self._M = robot.coupling / robot.gains[None, :]
        self._M_rows = [[(k, float(M[j, k])) for k in range(6) if M[j, k] != 0.0]
                        for j in range(6)]
        self._qe0 = [int(v) for v in robot.qe0]
        self._qe0_arr = robot.qe0.astype(np.int64)
        self._delta_true_arr = self._truth.joint_offsets.copy()
        self._delta_true = [float(v) for v in self._truth.joint_offsets]
        self._reference = [int(v) for v in start]
        self._reference_arr = np.array(start, np.int64)
        self._reference_arr.flags.writeable = False
        self._last_delta = [0] * 6
        self._commanded = list(self._reference)
        self._trip = robot.trip_step_counts
        self._check = self.options.check_steps
        self._ticks = 0
        self._at_rest = True
        self._tripped = False
        self._dirty = True
        self._errors_active = self._errors.active
        # run's batch path: no compliance, no backlash (else exchange + read per tick)
        self._plain = self._errors.stiffness is None and self._errors.backlash is None
        self._S = self._F = None  # its state arrays (``ticks``), made at the first run
        self._stop = np.zeros(2, np.int64)
        self._ws_Q = np.empty((256, 6))  # its workspaces: joint rows, row per tick
        self._ws_row = np.empty(256, np.int64)
        self._qpos = self._data.qpos  # views into MjData's buffers (stable)
        self._stale_q = None  # qpos the MjData should show after a batch run (lazy)
        self._dist: float | None = None
        self._geom = -1
        self._errors.on_settle()  # the robot starts at rest
        self._update()

    # ----- construction helpers -----
    def _start_counts(self, start_counts) -> np.ndarray:
        robot, scene = self.robot, self.scene
        if start_counts is None:
            if scene.calibration_q is not None:
                start = joints_to_counts(robot, scene.calibration_q)
            else:
                start = scene.home_counts
        else:
            start = _as_counts(start_counts, "start_counts")
        if not counts_in_range(robot, start):
            raise InputError(f"twin: start counts {start.tolist()} outside the "
                             f"{robot.encoder_bits}-bit encoder range")
        return np.array(start, np.int64)

    # ----- RobotLink -----
    def exchange(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """One 10 ms tick: command reference + delta; returns (reference, current) counts
        as new int64[6] arrays."""
        if self._tripped:
            raise EncoderJumpError("twin: the robot braked after an encoder jump; make a new Twin")
        if delta.__class__ is np.ndarray and delta.dtype == _INT64 and delta.shape == (6,):
            d = delta.tolist()
        else:
            d = _as_counts(delta, "delta").tolist()
        if self._check:
            trip = self._trip
            for a, b in zip(d, self._last_delta):
                if a - b > trip or b - a > trip:
                    self._tripped = True
                    raise EncoderJumpError(
                        f"twin: delta changed by {abs(a - b)} counts in one tick "
                        f"(trip at {trip})")
        self._last_delta = d
        cmd = [r + x for r, x in zip(self._reference, d)]
        holding = cmd == self._commanded
        self._commanded = cmd
        servo = self._servo
        before = servo.current
        if servo.step(cmd):
            self._dirty = True
            if self._errors.backlash is not None:
                self._errors.on_move(np.subtract(servo.current, before))
        at_rest = holding and servo.current == cmd
        if at_rest and not self._at_rest and self._errors.sigma > 0:  # came to rest
            self._errors.on_settle()
            self._dirty = True
        self._at_rest = at_rest
        self._ticks += 1
        return self._reference_arr.copy(), np.array(servo.current, np.int64)

    def run(self, deltas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Many ticks at once: for each row of ``deltas`` (N, 6) one ``exchange`` then one
        ``read``. Returns (reference int64[6], current counts int64[N, 6], readings
        float[N] in mm with NaN where read() gives None). Same counts and random streams
        as the loop, bit for bit, readings to ~1e-12 mm; ~20x faster (a compiled tick
        loop, the beams of all moving ticks in one MuJoCo call).
        An encoder jump runs the ticks before it, then raises EncoderJumpError."""
        if self._tripped:
            raise EncoderJumpError("twin: the robot braked after an encoder jump; make a new Twin")
        if (deltas.__class__ is np.ndarray and deltas.dtype == _INT64 and deltas.ndim == 2
                and deltas.shape[1] == 6):
            D = deltas
        else:
            D = _as_count_rows(deltas)
        if not (self.batch_rays and self._plain) or _ticks() is None:
            return self._run_ref(D)
        beam = self._beam
        if beam is None:
            beam = self._beam_caster()
        if not beam:
            return self._run_ref(D)
        return self._run_batch(D, beam)

    def _run_batch(self, D, beam):
        """``run`` with the compiled tick loop (``ticks``) and the batch caster (no
        compliance, no backlash; trip checks on or off): the same results and state as
        ``_run_ref`` with the caster, bit for bit (tests/test_twin_batch.py)."""
        ticks = _ticks()
        if self._S is None:
            self._S, self._F = self._tick_state(ticks)
        if not (D.flags.c_contiguous and D.flags.writeable):
            D = np.require(D, requirements="CW")  # one compiled version, not one per layout
        n = len(D)
        S, F, stop = self._S, self._F, self._stop
        servo, errors, laser = self._servo, self._errors, self._laser
        S[0:6] = servo.current
        S[6:12] = self._commanded
        S[ticks.AT_REST] = self._at_rest
        S[ticks.DIRTY] = self._dirty
        e0 = S[ticks.EPS_NEXT] = errors._next
        if not servo.ideal:
            F[0:6] = servo.y
        F[ticks.EPS:ticks.EPS + 6] = errors.eps
        if len(self._ws_Q) < n:
            self._ws_Q = np.empty((max(n, 2 * len(self._ws_Q)), 6))
            self._ws_row = np.empty(len(self._ws_Q), np.int64)
        Q, row_of = self._ws_Q, self._ws_row[:n]
        cur = np.empty((n, 6), np.int64)
        i = k = 0
        drew = False
        while True:
            k = ticks.advance(D, i, S, F, errors._eps_block, cur, row_of, Q, k, stop)
            if stop[0] != ticks.NEED_EPS:
                break
            errors.draw_block()  # at the settle that needs it, as on_settle does
            S[ticks.EPS_NEXT] = e0 = 0
            i, drew = int(stop[1]), True
        m = int(stop[1])  # the ticks run (all but a tripping one and after)
        servo.current = S[0:6].tolist()
        if not servo.ideal:
            servo.y = F[0:6].tolist()
            servo._zi = None
        self._commanded = S[6:12].tolist()
        self._at_rest = bool(S[ticks.AT_REST])
        if drew or S[ticks.EPS_NEXT] != e0:
            errors._next = int(S[ticks.EPS_NEXT])
            errors.eps = F[ticks.EPS:ticks.EPS + 6].copy()
        prev = -1.0 if self._dist is None else self._dist
        if k:
            dist, geom = beam.cast_last(Q[:k])
            last = float(dist[k - 1])
            self._dist, self._geom = (None, -1) if last < 0 else (last, geom)
            self._dirty = False
            self._stale_q = Q[k - 1].copy()  # MjData follows lazily (``data``, poses)
        else:
            dist = _NO_DIST
        readings = np.empty(m)
        noise, quantum = laser.noise_mm > 0.0, float(laser.quantum_mm or 0.0)
        i = 0
        while True:
            laser._left = ticks.laser(row_of[:m], dist, prev, i, laser._block, laser._left,
                                      noise, quantum, laser.lo, laser.hi,
                                      readings, stop)
            if stop[0] != ticks.NEED_EPS:
                break
            laser._refill()
            i = int(stop[1])
        self._ticks += m
        if m:
            self._last_delta = D[m - 1].tolist()
        if m < n:
            self._tripped = True
            raise EncoderJumpError(f"twin: delta jumped by more than {self._trip} counts "
                                   f"at row {m}")
        return self._reference_arr.copy(), cur, readings

    def _tick_state(self, ticks):
        """The constant part of ``ticks``' state arrays (the rest is set per ``run``)."""
        S, F = np.zeros(ticks.NS, np.int64), np.zeros(ticks.NF)
        S[ticks.REF:ticks.REF + 6] = self._reference
        S[ticks.QE0:ticks.QE0 + 6] = self._qe0
        S[ticks.TRIP] = self._trip if self._check else -1
        S[ticks.IDEAL] = self._servo.ideal
        S[ticks.SIGMA] = self._errors.sigma > 0
        F[ticks.GAIN], F[ticks.KEEP] = self._servo.gain, self._servo.keep
        F[ticks.DELTA:ticks.DELTA + 6] = self._delta_true
        F[ticks.M:ticks.M + 36] = self._M.ravel()
        return S, F

    def _run_ref(self, D) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``run``'s reference (the general path: the only one without the batch caster
        or numba, or with compliance / backlash)."""
        if self._tripped:
            raise EncoderJumpError("twin: the robot braked after an encoder jump; make a new Twin")
        D = _as_count_rows(D)
        errors = self._errors
        if errors.stiffness is not None or errors.backlash is not None:
            return self._run_loop(D)
        n = len(D)
        # the commands with the last one in front (it is reference + the last delta): the
        # steps for the trip check and the holds in one subtraction
        C = np.empty((n + 1, 6), np.int64)
        C[0] = self._commanded
        np.add(self._reference_arr, D, out=C[1:])
        trip_at = None
        if self._check and n:
            steps = np.abs(C[1:] - C[:-1])
            if steps.max() > self._trip:
                trip_at = n = int(np.flatnonzero(steps.max(axis=1) > self._trip)[0])
                C = C[:n + 1]
        if n:
            cmd = C[1:]
            P = np.empty((n + 1, 6), np.int64)  # the counts, the last ones in front
            P[0] = self._servo.current
            cur = self._servo.run(cmd, out=P[1:])
            # rows compared whole (48-byte void views): ~2x cheaper than (a != b).any(1)
            Cv, Pv = C.view(_ROW).ravel(), P.view(_ROW).ravel()
            changed = Pv[1:] != Pv[:-1]
            at_rest = (Pv[1:] == Cv[1:]) & (Cv[1:] == Cv[:-1])
            settle = None  # ticks at which the robot comes to rest (new perturbation)
            if errors.sigma > 0:
                settle = at_rest.copy()
                settle[1:] &= ~at_rest[:-1]
                if self._at_rest:
                    settle[0] = False
            beam = self._beam_caster() if self.batch_rays else None
            if beam is not None:
                dists = self._dists_batch(beam, cur, changed, settle)
            else:
                if settle is None:
                    settle = np.zeros(n, bool)
                Q = self._joint_rows(cur)
                if errors.sigma > 0:
                    Q += errors.eps
                dists = self._dists_loop(Q, changed, settle)
            readings = self._laser.readings(dists)
            self._at_rest = bool(at_rest[-1])
            self._last_delta = D[n - 1].tolist()
            self._commanded = cmd[-1].tolist()
            self._ticks += n
        else:
            cur, readings = np.zeros((0, 6), np.int64), np.zeros(0)
        if trip_at is not None:
            self._tripped = True
            raise EncoderJumpError(f"twin: delta jumped by more than {self._trip} counts "
                                   f"at row {trip_at}")
        return self._reference_arr.copy(), cur, readings

    def prepare_run(self) -> bool:
        """Build ``run``'s batch caster now (a few ms, else at the first ``run``); True if
        ``run`` will use it."""
        return self._beam_caster() is not None

    def _beam_caster(self) -> BeamCaster | None:
        if self._beam is None:
            self._beam = BeamCaster.build(self.model, self.laser_site, self._ray.mask,
                                          self.tool_body, self._beam_agrees) or False
        return self._beam or None

    def _beam_agrees(self, beam: BeamCaster) -> bool:
        """The caster's beams = mj_kinematics + mj_ray (1e-9 m, same geom) at the current
        state and a few states around it."""
        data = mujoco.MjData(self.model)
        ray = RayCaster(self.model, data, self.laser_site, self.tool_body)
        rng = np.random.default_rng(0)
        q0 = np.array(self._qpos)
        Q = np.vstack([q0, q0 + rng.normal(0.0, 0.3, (7, len(q0)))])
        dist, geom = beam.cast(Q)
        for q, d, g in zip(Q, dist, geom):
            data.qpos[:] = q
            mujoco.mj_kinematics(self.model, data)
            want, want_g = ray.cast()
            if (want is None) != (d < 0) or (want is not None and (
                    abs(want - d) > 1e-9 or want_g != g)):
                return False
        return True

    def _dists_batch(self, beam, cur, changed, settle) -> np.ndarray:
        """True distance per tick (NaN or -1: no hit), the batch way: the beams of every tick
        whose state changed (counts moved, a settle, or stale kinematics at tick 0) in
        one MuJoCo call (``BeamCaster``); the other ticks repeat the last value. Draws the
        settle perturbations in tick order, like the loop."""
        errors = self._errors
        recompute = changed if settle is None else changed | settle
        if self._dirty:
            recompute[0] = True
        idx = recompute.nonzero()[0]
        n, k = len(cur), len(idx)
        prev = np.nan if self._dist is None else self._dist
        if not k:
            return np.full(n, prev)
        head = idx[-1] == k - 1  # the usual: ticks 0..k-1 move, then holds
        Q = self._joint_rows(cur[:k] if head else cur[idx])
        if errors.sigma > 0:
            at = settle.nonzero()[0]
            if at.size:  # each perturbation from its settle tick on (few per run)
                pos = at if head else np.searchsorted(idx, at)  # settle ticks recompute
                _add_settled_errors(Q, [0, *pos.tolist(), k], errors)
            else:
                Q += errors.eps
        dist, geom = beam.cast(Q, last_geom_only=True)
        last = float(dist[-1])
        self._dist, self._geom = (None, -1) if last < 0 else (last, geom)
        self._dirty = False
        self._stale_q = Q[-1]  # MjData follows lazily (``data``, ``qpos``, poses)
        # dist: the caster's buffer (valid until its next cast), -1 for no hit, which
        # LaserModel.readings takes like NaN
        if k == n:
            return dist
        if head:
            out = np.empty(n)
            out[:k] = dist
            out[k:] = dist[-1]
            return out
        # tick i: the last recomputed value at or before i (prev before the first)
        return np.concatenate(((prev,), dist))[np.cumsum(recompute)]

    def _dists_loop(self, Q, changed, settle) -> np.ndarray:
        """True distance per tick (NaN: no hit), one MuJoCo kinematics + mj_ray per tick
        whose state changed (the reference for ``_dists_batch``)."""
        errors = self._errors
        n = len(Q)
        dists = np.empty(n)
        self._sync_data()
        qpos, model, data = self._qpos, self.model, self._data
        ray, pnt, zcol = mujoco.mj_ray, self._ray._pnt, self._ray._mat[2::3]
        mask, exclude, geomid = self._ray.mask, self._ray.exclude_body, self._ray.geomid
        kinematics = mujoco.mj_kinematics
        dirty = self._dirty
        dist = -1.0 if self._dist is None else self._dist
        events = np.flatnonzero(changed | settle).tolist() + [n]
        settle_l = settle.tolist()
        i = 0
        for e in events:  # ticks i..e-1: nothing changes; tick e: counts move or settle
            if i < e:
                if dirty:
                    qpos[:] = Q[i]
                    kinematics(model, data)
                    dist = ray(model, data, pnt, zcol, mask, 1, exclude, geomid)
                    dirty = False
                dists[i:e] = dist if dist >= 0 else np.nan
            if e == n:
                break
            if settle_l[e]:
                old = errors.eps
                errors.on_settle()
                Q[e:] += errors.eps - old
            qpos[:] = Q[e]
            kinematics(model, data)
            dist = ray(model, data, pnt, zcol, mask, 1, exclude, geomid)
            dirty = False
            dists[e] = dist if dist >= 0 else np.nan
            i = e + 1
        dist = None if dist < 0 else dist
        self._geom = int(geomid[0]) if dist is not None else -1
        self._dirty, self._dist = dirty, dist
        return dists

    def _run_loop(self, D):
        cur = np.empty_like(D)
        readings = np.full(len(D), np.nan)
        for i, d in enumerate(D):
            _, cur[i] = self.exchange(d)
            r = self.read()
            if r is not None:
                readings[i] = r
        return self._reference_arr.copy(), cur, readings

    # ----- Laser -----
    def read(self) -> float | None:
        """Laser reading [mm] at the current state; None out of range or no hit."""
        if self._dirty:
            self._update()
        return self._laser.reading(self._dist)

    def close(self) -> None:
        pass

    # ----- state -----
    def _joint_angles(self) -> list:
        """q (encoder side, no offsets) from the current counts, Python floats."""
        x = [c - z for c, z in zip(self._servo.current, self._qe0)]
        q = []
        for row in self._M_rows:
            acc = 0.0
            for k, m in row:
                acc += m * x[k]
            q.append(acc)
        return q

    def _joint_rows(self, counts: np.ndarray) -> np.ndarray:
        """``_joint_angles`` + the true offsets for rows of counts (K, 6), the same
        arithmetic in the same order (a BLAS product would differ in the last bits)."""
        x = np.subtract(counts, self._qe0_arr, dtype=float)
        Q = np.zeros(x.shape)
        for j, row in enumerate(self._M_rows):
            for k, m in row:
                Q[:, j] += m * x[:, k]
        Q += self._delta_true_arr
        return Q

    def _update(self) -> None:
        q = self._joint_angles()
        if self._errors_active:
            extra = self._errors.extra(np.array(q), np.array(self._delta_true))
            self._qpos[:] = [a + b + c for a, b, c in zip(q, self._delta_true, extra)]
        else:
            self._qpos[:] = [a + b for a, b in zip(q, self._delta_true)]
        mujoco.mj_kinematics(self.model, self._data)
        self._stale_q = None
        self._dist, self._geom = self._ray.cast()
        self._dirty = False

    def _sync_data(self) -> None:
        """Bring MjData to the last state a batch run computed (qpos + kinematics)."""
        if self._stale_q is not None:
            self._qpos[:] = self._stale_q
            mujoco.mj_kinematics(self.model, self._data)
            self._stale_q = None

    @property
    def data(self) -> mujoco.MjData:
        """MjData at the last computed state (call ``hit()`` or ``read()`` first)."""
        self._sync_data()
        return self._data

    def set_counts(self, counts) -> None:
        """Put the robot at ``counts`` at once, at rest (tests, benchmarks, fast sampling;
        not something the FD11 can do). The reference counts stay; the next delta must be
        within a trip step of ``counts - reference``."""
        c = _as_counts(counts, "counts")
        if not counts_in_range(self.robot, c):
            raise InputError(f"twin: counts {c.tolist()} outside the encoder range")
        self._servo.set(c)
        self._commanded = c.tolist()
        self._last_delta = (c - self._reference_arr).tolist()
        self._at_rest = True
        self._errors.on_settle()
        self._dirty = True

    def hit(self) -> Hit:
        """What the beam hits now: true distance [m] (no noise, no window), geom, plate."""
        if self._dirty:
            self._update()
        g = self._geom
        return Hit(self._dist, g, None if g < 0 else self.model.geom(g).name,
                   self._plate_of_geom.get(g))

    @property
    def ticks(self) -> int:
        return self._ticks

    @property
    def robot_time_s(self) -> float:
        return self._ticks * self.robot.tick_s

    @property
    def current_counts(self) -> np.ndarray:
        return np.array(self._servo.current, np.int64)

    @property
    def reference_counts(self) -> np.ndarray:
        return self._reference_arr.copy()

    @property
    def commanded_counts(self) -> np.ndarray:
        return np.array(self._commanded, np.int64)

    @property
    def truth(self) -> CellParams:
        """The hidden truth (a copy). Calibration code must not read it."""
        return self._truth.copy()

    @property
    def true_params(self) -> CellParams:
        return self.truth

    @property
    def qpos(self) -> np.ndarray:
        """The true joint angles q + delta (+ joint errors) in MuJoCo, rad."""
        if self._dirty:
            self._update()
        return self.data.qpos.copy()

    def flange_pose(self) -> np.ndarray:
        return self._site_pose(self.flange_site)

    def sensor_pose(self) -> np.ndarray:
        """True sensor frame in the base frame (z = beam)."""
        return self._site_pose(self.laser_site)

    def _site_pose(self, sid: int) -> np.ndarray:
        if self._dirty:
            self._update()
        d = self.data
        return _pose(d.site_xmat[sid], d.site_xpos[sid])

    def to_xml(self) -> str:
        """The twin's scene (truth poses) as MJCF text for a viewer."""
        from planecal.twin.mjcf import to_xml_exact
        return to_xml_exact(self.spec)


_INT64 = np.dtype(np.int64)
_NO_DIST = np.zeros(0)
_TICKS = []


def _ticks():
    """The compiled tick loop (``twin.ticks``), imported at the first ``run`` (numba
    takes ~0.25 s to import); None, with a warning, if it can't be set up (numba missing,
    no writable cache directory): ``run`` then takes the reference path, same numbers."""
    if not _TICKS:
        try:
            from planecal.twin import ticks
        except (ImportError, RuntimeError, OSError) as e:
            import warnings
            warnings.warn(f"twin: the compiled tick loop is not available ({e}); "
                          "Twin.run takes the slower reference path", RuntimeWarning,
                          stacklevel=3)
            ticks = None
        _TICKS.append(ticks)
    return _TICKS[0]
_ROW = np.dtype("V48")  # one row of 6 int64 counts, compared as bytes


def _pose(xmat, xpos) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.reshape(xmat, (3, 3))
    T[:3, 3] = xpos
    return T


def _as_count_rows(v) -> np.ndarray:
    a = np.asarray(v)
    if a.ndim != 2 or a.shape[1] != 6:
        raise InputError(f"twin: deltas must be an (N, 6) array of integer counts, got shape {a.shape}")
    if a.dtype == _INT64:
        return a  # read only
    if a.dtype.kind not in "iu":
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or np.any(a != np.rint(a)):
            raise InputError("twin: deltas must be integers")
    return a.astype(np.int64)


def _as_counts(v, what: str) -> np.ndarray:
    a = np.asarray(v)
    if a.shape != (6,):
        raise InputError(f"twin: {what} must be 6 integer counts, got shape {a.shape}")
    if a.dtype.kind not in "iu":
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or np.any(a != np.rint(a)):
            raise InputError(f"twin: {what} must be integers, got {a.tolist()}")
    return a.astype(np.int64)
