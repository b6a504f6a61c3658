"""The digital twin: the robot behind an FD11 real-time link and the ZS-LD80 laser, in
process, on a virtual clock (one tick = 10 ms of robot time; no wall-clock sleeps).

FD11 semantics (appendix C): the reference counts are fixed at start (the robot's
counts then); each tick the host sends ``delta`` and the controller commands
``reference + delta``; consecutive deltas that differ by more than ``trip_step_counts``
(60) on a joint trip an encoder-jump error and brake the robot (``EncoderJumpError``;
the twin then refuses further ticks).

One tick, one implementation (``ticks``: compiled with numba; the same source run by the
interpreter is the reference the tests hold it to): the trip check, the servo, the rest
logic, every joint-side error source and the laser model. ``run(deltas)`` runs many
ticks in one call (the sampling loop hands it whole moves); ``exchange(delta)`` is one
tick and ``read()`` one laser reading at the current state: ``run(D)`` equals
``exchange`` + ``read`` per row bit for bit. The beams are cast by MuJoCo
(``beam.BeamCaster``: kinematics and ``mj_ray`` for all the joint rows of a call in one
``mujoco.batch`` call) only for the ticks that read the laser.

State and truth: the twin holds integer encoder counts. The joint angles MuJoCo sees are
the tick's joint rows, ``qpos = q(counts) + delta_true + joint errors``
(``ticks.joint_row``); the model's bodies carry the nominal DH (``mjcf``), so MuJoCo's
link frames equal ``kinematics.link_frames(robot.kinematics.with_offsets(delta_true), q)``
with the errors off. The
laser site and the plates sit at the truth's sensor pose and planes. With noise and joint
errors off, ``read()`` equals ``measurement.predict(robot, counts, truth, plate) * 1000``
(mm).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_in_range, joints_to_counts
from planecal.base.errors import InputError
from planecal.model.scene import Scene, load_scene
from planecal.twin import ticks as T
from planecal.twin.beam import BeamCaster
from planecal.twin.errors import EPS_BLOCK, gravity_model
from planecal.twin.options import TwinOptions
from planecal.twin.laser import LaserNoise, seen_mask
from planecal.twin.mjcf import (FLANGE_SITE, LASER_SITE, TOOL_BODY, link_body_name,
                                 plate_geom_names, scene_spec)
from planecal.twin.truth import resolve_truth


class EncoderJumpError(RuntimeError):
    """The commanded counts jumped more than the FD11 allows in one tick: robot braked."""


@dataclass
class Hit:
    distance_m: float | None
    geom: int
    name: str | None
    plate: int | None  # index into scene.plates, None if not a plate


_COMPILED: list = []


def _compiled_ticks():
    """The compiled tick, made once per process; the reference (with a warning) if
    numba cannot compile here (e.g. no writable cache directory)."""
    if not _COMPILED:
        try:
            t = T.compiled()
        except (ImportError, RuntimeError, OSError) as e:
            warnings.warn(f"twin: the compiled tick is not available ({e}); the twin runs "
                          "the plain-Python reference (same numbers, much slower)",
                          RuntimeWarning, stacklevel=3)
            t = T.REFERENCE
        _COMPILED.append(t)
    return _COMPILED[0]


class Twin:
    """In-process robot link and laser over a MuJoCo model.

    Twin(scene="thesis_final" | Scene | path, truth=None | CellParams | path | "nominal",
         seed=0, options=TwinOptions(), start_counts=None, reference_ticks=False)

    ``truth`` None draws the hidden truth from ``seed`` (``truth.draw_truth``).
    ``start_counts`` default: the scene's calibration position (nominal encoder model),
    else its home counts. The reference counts of the FD11 link are these.
    ``reference_ticks``: run the plain-Python tick instead of the compiled one (same
    numbers; for checking the compiled one).

    Robot link and laser: ``run(deltas, read=True)`` (a whole move), ``exchange(delta)``
    (one tick), ``read()``, ``close()``. Tests and tools: ``set_counts(counts)`` (jump
    there, at rest), ``hit()`` (true distance, geom, plate), ``flange_pose()``,
    ``sensor_pose()``, ``qpos``, ``to_xml()``. State: ``ticks``, ``robot_time_s``,
    ``current_counts``, ``reference_counts``, ``commanded_counts``. For others (collision
    cross-checks, Rerun): ``model``, ``data`` (MjModel/MjData at the current state),
    ``spec``, ``laser_site``, ``flange_site``, ``tool_body``. ``truth``: the hidden
    truth, never for calibration.
    """

    def __init__(self, scene: Scene | str | Path = "thesis_final", truth=None, seed: int = 0,
                 options: TwinOptions | None = None, start_counts=None, *,
                 reference_ticks: bool = False):
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError(f"twin: seed must be a non-negative integer, got {seed!r}")
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.robot = robot = self.scene.robot
        self.options = opt = options or TwinOptions()
        self.seed = seed
        self._world = world = resolve_truth(self.scene, truth, seed)
        self._truth = world.params
        start = self._start_counts(start_counts)
        cal_qpos = None
        if self.scene.calibration_q is not None:
            cal_qpos = self.scene.calibration_q + self._truth.joint_offsets
        self.spec = scene_spec(self.scene, self._truth, calibration_qpos=cal_qpos,
                               kin=world.kinematics, payload=opt.payload)
        self.model = self.spec.compile()
        self._data = mujoco.MjData(self.model)
        self._data_synced = False
        self._aside: mujoco.MjData | None = None  # ``site_poses_at``'s own
        self.laser_site = self.model.site(LASER_SITE).id
        self.flange_site = self.model.site(FLANGE_SITE).id
        self.tool_body = self.model.body(TOOL_BODY).id
        self._plate_of_geom = {self.model.geom(name).id: i
                               for i, name in enumerate(plate_geom_names(self.scene))}
        self._beam = BeamCaster(self.model, self.laser_site, seen_mask(), self.tool_body)
        self._t = T.REFERENCE if reference_ticks else _compiled_ticks()
        # the noise streams: laser, repeatability, quantisation (spawned in that order, so
        # adding a stream leaves the others' draws unchanged)
        noise_seed = opt.noise_seed if opt.noise_seed is not None else (seed * 7919 + 1)
        rng_laser, self._rng_eps, self._rng_u = (
            np.random.default_rng(s) for s in np.random.SeedSequence(noise_seed).spawn(3))
        self._laser = LaserNoise(self.scene.laser_range_mm, opt.laser_noise_mm,
                                 opt.laser_quantum_mm, rng_laser, opt.laser_linearity_mm,
                                 world.laser_phases)
        self.errors = errors = opt.joint_errors(robot, world.gear_phases)
        self._sigma = errors.sigma(robot)
        if opt.servo == "lag" and not opt.tau_s > 0:
            raise InputError(f"twin: servo time constant must be > 0, got {opt.tau_s!r}")
        # the tick's state (``ticks``: S int64, F float64) and world W
        S, F = np.zeros(T.NS, np.int64), np.zeros(T.NF)
        S[T.CUR:T.CUR + 6] = S[T.CMD:T.CMD + 6] = S[T.REF:T.REF + 6] = start
        S[T.QE0:T.QE0 + 6] = robot.qe0.astype(np.int64)
        S[T.AT_REST] = 1
        S[T.TRIP] = robot.trip_step_counts if opt.check_steps else -1
        S[T.IDEAL] = opt.servo == "ideal"
        S[T.FLAGS] = errors.flags() & ~(0 if self._sigma > 0 else T.REPEAT)
        gain = 1.0 - float(np.exp(-robot.tick_s / opt.tau_s)) if opt.servo == "lag" else 1.0
        F[T.Y:T.Y + 6] = start.astype(float)
        F[T.GAIN], F[T.KEEP] = gain, 1.0 - gain
        F[T.DELTA:T.DELTA + 6] = self._truth.joint_offsets
        # q_j = sum_k M[j,k] (counts_k - qe0_k), M = C diag(1/g), qe0 nominal (the
        # controller's)
        F[T.M:T.M + 36] = (robot.coupling / robot.gains[None, :]).ravel()
        errors.fill(F)
        self._S, self._F = S, F
        links = [self.model.body(link_body_name(i + 1)).id for i in range(robot.n_joints)]
        self._links = links
        self._W = (errors.harmonics(),) + gravity_model(self.model, links, self.tool_body)
        self._link_pos0 = self.model.body_pos[links].copy()  # the links at the start's heat
        self._growth = 0.0
        self._eps_block = np.zeros((0, 6))
        self._u_block = np.zeros((0, 6))
        self._stop = np.zeros(3, np.int64)
        self._ticks = 0
        self._tripped = False
        self._ws_Q = np.empty((256, 6))  # workspaces: joint rows, row per tick
        self._ws_row = np.empty(256, np.int64)
        self._settle()  # the robot starts at rest: this rest's draws
        self._t.refresh(S, F, self._W, self._ws_Q[0])
        self._beam_stale = True  # the beam of the current joint row is not cast yet
        self._dist, self._geom = -1.0, -1

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

    def _refill(self, block: int) -> None:
        """Draw the next block of the stream a tick found used up."""
        if block == T.BLOCK_EPS:
            self._eps_block = self._rng_eps.normal(0.0, self._sigma, (EPS_BLOCK, 6))
            self._S[T.EPS_NEXT] = 0
        elif block == T.BLOCK_U:
            self._u_block = self._rng_u.uniform(-0.5, 0.5, (EPS_BLOCK, 6))
            self._S[T.U_NEXT] = 0
        else:
            self._laser.refill()

    def _settle(self) -> None:
        """This rest's draws (a jump to counts, the start)."""
        while (need := self._t.settle(self._S, self._F, self._eps_block, self._u_block)) >= 0:
            self._refill(need)

    # ----- robot link -----
    def exchange(self, delta) -> tuple[np.ndarray, np.ndarray]:
        """One 10 ms tick: command reference + delta; returns (reference, current) counts
        as new int64[6] arrays."""
        _, cur, _ = self.run(_as_counts(delta, "delta")[None], read=False)
        return self.reference_counts, cur[0]

    def run(self, deltas, read: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Many ticks at once: for each row of ``deltas`` (N, 6) one tick, and with
        ``read`` one laser reading. Returns (reference int64[6], current counts
        int64[N, 6], readings float[N] in mm, NaN where the laser gives none or
        ``read`` is False). An encoder jump runs the ticks before it, then raises
        EncoderJumpError."""
        if self._tripped:
            raise EncoderJumpError("twin: the robot braked after an encoder jump; make a new Twin")
        D = deltas if (deltas.__class__ is np.ndarray and deltas.dtype == _INT64
                       and deltas.ndim == 2 and deltas.shape[1] == 6
                       and deltas.flags.c_contiguous) else _as_count_rows(deltas)
        n = len(D)
        if self.options.thermal is not None:
            self._warm()
        S, F, t = self._S, self._F, self._t
        if len(self._ws_Q) < n + 1:
            self._ws_Q = np.empty((max(n + 1, 2 * len(self._ws_Q)), 6))
            self._ws_row = np.empty(len(self._ws_Q), np.int64)
        Q, row_of = self._ws_Q, self._ws_row[:n]
        k0 = 0
        if read and self._beam_stale:  # the state before the call shows as row 0
            Q[0] = F[T.QNOW:T.QNOW + 6]
            k0 = 1
        cur = np.empty((n, 6), np.int64)
        i, k, stop = 0, k0, self._stop
        while True:
            k = t.advance(D, i, S, F, self._W, self._eps_block, self._u_block, cur,
                          row_of, Q, k, stop, read)
            if stop[0] != T.NEED_BLOCK:
                break
            self._refill(int(stop[2]))
            i = int(stop[1])
        m = int(stop[1])  # the ticks run (all but a tripping one and after)
        self._ticks += m
        readings = np.full(m, np.nan)
        if read and m:
            if k:
                dist, geom = self._beam.cast(Q[:k])
                prev = self._dist
                self._dist, self._geom = float(dist[k - 1]), int(geom[k - 1])
                self._beam_stale = False
            else:
                dist, prev = _NO_DIST, self._dist
            noise, laser = self._laser.noise_mm > 0.0, self._laser
            i = 0
            while True:
                laser.left = t.laser(row_of[:m], dist, prev, i, laser.block, laser.left,
                                     noise, laser.quantum_mm, laser.lo, laser.hi, laser.lin,
                                     readings, stop)
                if stop[0] != T.NEED_BLOCK:
                    break
                laser.refill()
                i = int(stop[1])
        elif k > k0:
            self._beam_stale = True
        if k > k0:
            self._data_synced = False
        if m < n:
            self._tripped = True
            raise EncoderJumpError(f"twin: delta jumped by more than "
                                   f"{self.robot.trip_step_counts} counts at row {m}")
        return self.reference_counts, cur, readings

    THERMAL_STEP_M = 1e-6  # the links' growth is applied in steps of 1 um (longest chain)

    def growth(self, robot_time_s: float | None = None) -> float:
        """The links' relative growth at a robot time (default now): expansion x rise x
        (1 - exp(-t / tau)) (0 without the thermal option)."""
        if self.options.thermal is None:
            return 0.0
        k, rise, tau = self.options.thermal
        t = self.robot_time_s if robot_time_s is None else robot_time_s
        return float(k * rise * (1.0 - np.exp(-t / tau)))

    def _warm(self) -> None:
        """Scale the links' translations (a, d of every joint: the body positions) by the
        growth at the start of this call, when it has moved a step (``THERMAL_STEP_M`` over
        the arm's length) since the last update; the beam caster and the gravity model
        follow. A call's ticks share one heat (a move lasts seconds; the rise, an hour)."""
        g = self.growth()
        reach = float(np.linalg.norm(self._link_pos0, axis=1).sum())
        if abs(g - self._growth) * reach < self.THERMAL_STEP_M:
            return
        self._growth = g
        self.model.body_pos[self._links] = self._link_pos0 * (1.0 + g)
        self._beam = BeamCaster(self.model, self.laser_site, seen_mask(), self.tool_body)
        self._W = self._W[:1] + gravity_model(self.model, self._links, self.tool_body)
        self._t.refresh(self._S, self._F, self._W, self._ws_Q[0])
        self._beam_stale = True
        self._data_synced = False

    # ----- laser -----
    def read(self) -> float | None:
        """Laser reading [mm] at the current state; None out of range or no hit."""
        self._cast_now()
        out = np.empty(1)
        laser, stop = self._laser, self._stop
        while True:
            laser.left = self._t.laser(_ROW_PREV, _NO_DIST, self._dist, 0, laser.block,
                                       laser.left, laser.noise_mm > 0.0, laser.quantum_mm,
                                       laser.lo, laser.hi, laser.lin, out, stop)
            if stop[0] != T.NEED_BLOCK:
                break
            laser.refill()
        v = float(out[0])
        return None if v != v else v

    def close(self) -> None:
        pass

    def _cast_now(self) -> None:
        if self._beam_stale:
            dist, geom = self._beam.cast(self._F[None, T.QNOW:T.QNOW + 6])
            self._dist, self._geom = float(dist[0]), int(geom[0])
            self._beam_stale = False

    # ----- state -----
    def set_counts(self, counts) -> None:
        """Put the robot at ``counts`` at once, at rest (tests, studies; not something the
        FD11 can do). The reference counts stay; the next delta must be within a trip
        step of ``counts - reference``. The backlash keeps its direction."""
        c = _as_counts(counts, "counts")
        if not counts_in_range(self.robot, c):
            raise InputError(f"twin: counts {c.tolist()} outside the encoder range")
        S, F = self._S, self._F
        S[T.CUR:T.CUR + 6] = S[T.CMD:T.CMD + 6] = c
        F[T.Y:T.Y + 6] = c.astype(float)
        S[T.AT_REST] = 1
        self._settle()
        self._t.refresh(S, F, self._W, self._ws_Q[0])
        self._beam_stale = True
        self._data_synced = False

    def hit(self) -> Hit:
        """What the beam hits now: true distance [m] (no noise, no window), geom, plate."""
        self._cast_now()
        g = self._geom
        return Hit(None if self._dist < 0 else self._dist, g,
                   None if g < 0 else self.model.geom(g).name, self._plate_of_geom.get(g))

    @property
    def data(self) -> mujoco.MjData:
        """MjData at the current state (qpos and kinematics)."""
        if not self._data_synced:
            self._data.qpos[:] = self._F[T.QNOW:T.QNOW + 6]
            mujoco.mj_kinematics(self.model, self._data)
            self._data_synced = True
        return self._data

    @property
    def ticks(self) -> int:
        return self._ticks

    @property
    def robot_time_s(self) -> float:
        return self._ticks * self.robot.tick_s

    @property
    def current_counts(self) -> np.ndarray:
        return self._S[T.CUR:T.CUR + 6].copy()

    @property
    def reference_counts(self) -> np.ndarray:
        return self._S[T.REF:T.REF + 6].copy()

    @property
    def commanded_counts(self) -> np.ndarray:
        return self._S[T.CMD:T.CMD + 6].copy()

    @property
    def truth(self) -> CellParams:
        """The hidden truth (a copy). Calibration code must not read it."""
        return self._truth.copy()

    @property
    def true_kinematics(self):
        """The true robot's geometry (``kinematics.Kinematics``; None: robot.json's)."""
        return self._world.kinematics

    @property
    def world(self):
        """The twin's world (``twin.truth.Truth``: cell, true geometry, phases). Calibration
        code must not read it."""
        return self._world

    @property
    def qpos(self) -> np.ndarray:
        """The true joint angles q + delta (+ joint errors) in MuJoCo, rad."""
        return self._F[T.QNOW:T.QNOW + 6].copy()

    def flange_pose(self) -> np.ndarray:
        return self._site_pose(self.flange_site)

    def sensor_pose(self) -> np.ndarray:
        """True sensor frame in the base frame (z = beam)."""
        return self._site_pose(self.laser_site)

    # ----- the twin's own deterministic map (``twin.oracle``: the floor of validate) -----
    def joint_map(self, counts, direction=None) -> np.ndarray:
        """The joint row (qpos, rad) the tick computes at ``counts`` (6,) -- fractional
        counts allowed -- without what depends on the rest (repeatability, the motors'
        sub-count draw): the true offsets, gear error and compliance of this world, by the
        tick's own ``joint_row``; with ``direction`` (6,) in -1, 0, +1 (each joint's last
        motion into the pose) the backlash on the flank it leaves (a joint held by gravity
        on the flank its torque pushes it to), without it no backlash."""
        c = np.asarray(counts, float)
        whole = np.floor(c)
        S, F = self._S.copy(), self._F.copy()
        S[T.CUR:T.CUR + 6] = whole.astype(np.int64)
        F[T.U:T.U + 6] = c - whole  # the sub-count position: fractional counts
        off = T.REPEAT if direction is not None else T.REPEAT | T.BACKLASH | T.PRELOADED
        if direction is not None:
            S[T.DIR:T.DIR + 6] = np.sign(np.asarray(direction)).astype(np.int64)
        S[T.FLAGS] = (S[T.FLAGS] | T.QUANT) & ~off
        out = np.empty(6)
        self._t.refresh(S, F, self._W, out)
        return out

    def site_poses_at(self, qpos) -> tuple[np.ndarray, np.ndarray]:
        """(flange, sensor) 4x4 in the base frame at joint row ``qpos``: MuJoCo's sites on
        an MjData of their own (the twin's state is untouched)."""
        if self._aside is None:
            self._aside = mujoco.MjData(self.model)
        d = self._aside
        d.qpos[:] = qpos
        mujoco.mj_kinematics(self.model, d)
        return self._site_pose(self.flange_site, d), self._site_pose(self.laser_site, d)

    def _site_pose(self, sid: int, d=None) -> np.ndarray:
        d = self.data if d is None else d
        P = np.eye(4)
        P[:3, :3] = np.reshape(d.site_xmat[sid], (3, 3))
        P[:3, 3] = d.site_xpos[sid]
        return P

    def to_xml(self) -> str:
        """The twin's scene (truth poses) as MJCF text for a viewer."""
        from planecal.twin.mjcf import to_xml_exact
        return to_xml_exact(self.spec)


_INT64 = np.dtype(np.int64)
_NO_DIST = np.zeros(0)
_ROW_PREV = np.full(1, -1, np.int64)


def _as_count_rows(v) -> np.ndarray:
    a = np.asarray(v)
    if a.ndim != 2 or a.shape[1] != 6:
        raise InputError(f"twin: deltas must be an (N, 6) array of integer counts, got shape {a.shape}")
    if a.dtype.kind not in "iu":
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or np.any(a != np.rint(a)):
            raise InputError("twin: deltas must be integers")
    return np.ascontiguousarray(a, np.int64)


def _as_counts(v, what: str) -> np.ndarray:
    a = np.asarray(v)
    if a.shape != (6,):
        raise InputError(f"twin: {what} must be 6 integer counts, got shape {a.shape}")
    if a.dtype.kind not in "iu":
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)) or np.any(a != np.rint(a)):
            raise InputError(f"twin: {what} must be integers, got {a.tolist()}")
    return a.astype(np.int64)
