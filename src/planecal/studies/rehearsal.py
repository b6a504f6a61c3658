"""A rehearsal on the twin as the studies run one: its settings (scene, samples, seeds,
world, noise overrides, pose draw) and the sampling modes. Monte Carlo runs many of them
(``studies.montecarlo``); the Python API's ``rehearse`` runs one; validation, planning and
the sweep sample through them.

Sampling modes:

* ``twin`` (default): the rehearsal machinery without the tick-by-tick motion: the
  sampling run's own ``Planner`` (pose draw, IK, collision check of the target and of the
  straight joint path from the previous pose, with the run's random stream), the twin put
  at rest at the planned counts (``Twin.set_counts``: a repeatability draw, as when the
  robot settles at the end of a move) and the laser read through ``read_stable`` (100
  readings). Poses, rejections, counts and readings are those of ``planecal rehearse``
  with the same seeds (tests/test_studies_montecarlo.py checks it sample for sample);
  it only skips simulating the ticks of each move (the servo always settles exactly on
  the commanded counts, so the sample is the same). In a world whose joint errors depend
  on the path (backlash, thermal growth) it drives the ticks of each move
  (``sampling.collect.DriveAcquirer``, as ``rehearse``): a jump to rest would leave every
  joint's backlash on the flank it started on.
* ``rehearse``: the full ``SamplingRun`` on the twin, tick by tick (slow; for checking).
* ``synthetic``: the analytic model (``planecal.twin.synthetic``'s poses, no collision
  check: a slightly different pose distribution) with the twin's noise model added in
  numpy (``estimation.noise``): Gaussian joint repeatability, buffer-mean laser noise and,
  optionally, the encoder's quantisation (uniform +-0.5 count per actuator). For fast tests.

Every mode gives the samples as (qe, d_m, plate, direction, rejected): ``direction`` (N, 6)
int8 is each sample's approach direction (``sampling.approach``): recorded where the twin
is driven tick by tick, 0 (unknown) where it is set at rest or the model measures.

World: the twin's error profile (``errors``: ``ideal`` or ``realistic`` or a profile file)
and a seed make a world (``twin.world.study_world``). The settings' noise fields override
the profile's (None: the profile's). By default one world for every run k, drawn from
``truth_seed``; ``vary_truth`` draws one per run (seed + k). Run k uses seed ``seed + k``
for its poses and noise.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.noise import repeatability_sigma, sample_sigma_m
from planecal.studies.common import cached_profile, cached_scene, cached_world
from planecal.twin.world import path_dependent, study_world, with_noise

MODES = ("twin", "rehearse", "synthetic")


@dataclass(frozen=True)
class RehearsalSettings:
    scene: str = "thesis_final"
    samples: int = 150
    seed: int = 1000
    mode: str = "twin"
    truth_seed: int = 0
    vary_truth: bool = False
    offsets_all: bool = False  # truth with delta1, delta6 != 0 too
    errors: str = "ideal"  # the twin's error profile (the commands' default: realistic)
    laser_noise_mm: float | None = None  # None: the profile's (0.001 mm in both)
    repeatability_mm: float | None = None  # None: the profile's (ideal: the robot's 0.07 mm)
    quantization: bool = False  # synthetic mode: add quantisation (a profile's: its own)
    clearance_m: float = 0.01
    poses: tuple | None = None  # fixed encoder counts (planning study): replayed in order
    roll_deg: float | None = None  # the pose draw's roll about the beam; None: the default
    ik_choice: str | None = None  # the pose draw's IK branch choice; None: the default
    robot_minutes: float | None = None  # the run's robot-time budget (``collect.Budget``)

    def check(self) -> None:
        if self.mode not in MODES:
            raise InputError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.samples < 20:
            raise InputError(f"--samples must be at least 20, got {self.samples}")
        if self.seed < 0 or self.truth_seed < 0:
            raise InputError("seeds must be >= 0")
        if (self.laser_noise_mm or 0) < 0 or (self.repeatability_mm or 0) < 0:
            raise InputError("noise levels must be >= 0")
        if self.mode == "synthetic" and self.errors != "ideal":
            raise InputError(f"--errors {self.errors}: the synthetic mode is the analytic "
                             "model with the ideal world's noise; the other worlds need the "
                             "twin (--mode twin or rehearse), or give --errors ideal")
        opts = self.options()  # the profile, read (InputError if it cannot be)
        if opts.laser_noise_mm == 0 and self.joint_sigma() == 0 \
                and not (opts.quantization or self.quantization):
            raise InputError("laser noise and repeatability are both 0: no noise to study")
        if self.roll_deg is not None and not 0.0 <= self.roll_deg <= 180.0:
            raise InputError(f"--roll-deg must be in [0, 180], got {self.roll_deg}")
        if (self.roll_deg is not None or self.ik_choice is not None) \
                and self.mode == "synthetic":
            raise InputError("--roll-deg and --ik-choice set the sampling run's pose draw; "
                             "the synthetic mode draws its own poses")
        if self.quantization and self.mode != "synthetic":
            raise InputError("--quantization adds encoder quantisation to the synthetic mode; "
                             "the twin's comes from its error profile (realistic has it)")

    def options(self, base=None):
        """The twin's options: ``base`` (default: the profile's) with the noise overrides."""
        opts = cached_profile(self.scene, self.errors).options() if base is None else base
        return with_noise(opts, self.laser_noise_mm, self.repeatability_mm)

    def world(self, k: int):
        """Run k's world: (``twin.truth.Truth``, ``TwinOptions``) (module docstring)."""
        seed = self.seed + k if self.vary_truth else self.truth_seed
        world, opts = study_world(cached_scene(self.scene), cached_profile(self.scene, self.errors),
                                  seed, self.offsets_all)
        return world, self.options(opts)

    def joint_sigma(self) -> float:
        """The repeatability's std per joint [rad] of the settings' world."""
        robot = cached_scene(self.scene).robot
        mm = self.options().repeatability_mm
        rep = robot.repeatability_m if mm is None else mm * 1e-3
        return repeatability_sigma(robot, rep) if rep > 0 else 0.0

    def sample_sigma_m(self) -> float:
        """A sample's distance noise from the laser alone [m] (the buffer mean)."""
        return sample_sigma_m(self.options().laser_noise_mm)

    def quantized(self) -> bool:
        """Whether the samples carry the encoder's quantisation."""
        return bool(self.quantization or (self.options().quantization
                                          and self.mode != "synthetic"))


def sample_run(st: RehearsalSettings, k: int):
    """Run k of the settings: (qe, d_m, plate, direction, rejected dict, world, options);
    RuntimeError when the run gives up (e.g. 500 poses rejected in a row)."""
    scene = cached_scene(st.scene)
    seed = st.seed + k
    world, opts = st.world(k)
    if st.poses is not None:
        out = pose_list_samples(scene, world, st, seed, opts)
    elif st.mode == "twin":
        out = twin_samples(scene, world, st, seed, opts)
    elif st.mode == "rehearse":
        out = rehearse_samples(scene, world, st, seed, opts)
    else:
        out = synthetic_noisy_samples(scene, world.params, st, seed)
    return (*out, world, opts)


# ----- sampling -----------------------------------------------------------------------------

def _twin_and_settings(scene, world, st: RehearsalSettings, seed: int, options=None):
    """The run's twin in ``world`` (a ``Truth``, or a ``CellParams``: robot.json's
    geometry) with ``options`` (default: the settings' profile and noise), and its
    sampling settings."""
    from planecal.sampling.run import RunSettings
    from planecal.twin import Twin

    twin = Twin(scene, truth=world, seed=seed,
                options=st.options() if options is None else options)
    rs = RunSettings.for_scene(scene, samples=st.samples, seed=seed)
    rs.clearance_m = st.clearance_m
    if st.roll_deg is not None:
        rs.pose.roll_deg = st.roll_deg
    if st.ik_choice is not None:
        rs.pose.ik_choice = st.ik_choice
    rs.robot_minutes = st.robot_minutes
    return twin, rs


def _acquirer(scene, twin, rs):
    """The twin set at rest at each target (``RestAcquirer``), or, where its joint errors
    depend on the path, driven there tick by tick (``DriveAcquirer``, as ``rehearse``;
    its driver started: one per twin, every stage of a session goes through it)."""
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.collect import DriveAcquirer, RestAcquirer
    from planecal.sampling.driver import Driver
    if not path_dependent(twin.options):
        return RestAcquirer(twin, rs.laser)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
    drv.start()
    return DriveAcquirer(drv, rs.laser, rs.nominal_step_counts, rs.dwell_ticks)


def _collect(scene, planner, twin, rs, seed: int, timed: bool = False, acq=None,
             spent_s: float = 0.0):
    """The collect core through ``acq`` (default: a new ``_acquirer``): (qe, d_m, plate,
    direction, rejected dict), and with ``timed`` the robot time it took
    (``robot_time``); RuntimeError when the run gives up. ``rs.robot_minutes``: the
    session's budget, of which earlier stages spent ``spent_s``."""
    from planecal.model.encoder import counts_to_joints
    from planecal.sampling.collect import Budget, Cursor, MemoryRecorder, Tally, collect
    from planecal.sampling.tour import Clock

    rec, tally = MemoryRecorder(rs.samples), Tally()
    cursor = Cursor(counts_to_joints(scene.robot, twin.current_counts),
                    np.random.default_rng(seed).bit_generator.state)
    acq = _acquirer(scene, twin, rs) if acq is None else acq
    clock = Clock(acq, twin.current_counts, rs.nominal_step_counts, rs.dwell_ticks)
    tick = float(scene.robot.tick_s)
    budget = Budget.of(rs.robot_minutes, lambda: spent_s + clock.ticks * tick, clock,
                       rs.laser.max_reads, tick)
    collect(planner, clock, rec, rs.samples, cursor, tally, rs.max_attempts, budget=budget)
    if tally.status != "complete":
        raise RuntimeError(f"run with seed {seed}: {tally.reason}")
    out = (*rec.arrays(), dict(tally.rejected))
    return (*out, robot_time(clock, scene.robot)) if timed else out


def robot_time(clock, robot) -> dict:
    """What a collection's ``tour.Clock`` counted, in seconds of robot time: the whole,
    the travel (the moves' legs), the laser's reads and the moves (accepted samples and
    laser rejections: the robot went there)."""
    tick = float(robot.tick_s)
    return {"robot_time_s": clock.ticks * tick, "travel_s": clock.travel_ticks * tick,
            "read_s": clock.read_ticks * tick, "moves": clock.moves}


def twin_samples(scene, world, st: RehearsalSettings, seed: int, options=None,
                 timed: bool = False):
    """The ``twin`` mode (module docstring) in ``world`` (a ``Truth`` from ``world_for`` or
    ``twin.profile.draw_world``, or a ``CellParams``) with ``options`` (default: the
    settings' profile and noise): (qe, d_m, plate, direction, rejected dict), with
    ``timed`` its robot time too (``robot_time``)."""
    from planecal.sampling.planner import Planner

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    return _collect(scene, Planner(scene, rs.pose, cached_world(st.scene, st.clearance_m)), twin,
                    rs, seed, timed)


def pose_list(poses) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(counts (n, 6), plates (n,), approach (n,)) of a settings' ``poses``: entries
    (counts, plate) or (counts, plate, approach side: -1, 0, +1)."""
    counts = np.array([p[0] for p in poses], np.int64).reshape(-1, 6)
    plates = np.array([p[1] for p in poses], int)
    approach = np.array([p[2] if len(p) > 2 else 0 for p in poses], np.int8)
    return counts, plates, approach


def pose_list_samples(scene, world, st: RehearsalSettings, seed: int, options=None,
                      timed: bool = False):
    """A planned pose list measured on the twin as ``rehearse --poses`` visits it (each
    pose checked from the last; a blocked one later; each approached from its side),
    set at rest at each pose (driven there where the joint errors depend on the path)."""
    from planecal.sampling.planner import ListPlanner

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    counts, plates, approach = pose_list(st.poses)
    rs.samples = len(counts)
    planner = ListPlanner(scene, counts, plates, cached_world(st.scene, st.clearance_m),
                          approach=approach)
    return _collect(scene, planner, twin, rs, seed, timed)


def rehearse_samples(scene, world, st: RehearsalSettings, seed: int, options=None):
    """The full sampling run, tick by tick (``planecal rehearse`` without the CLI)."""
    from planecal.links.base import AlwaysEnabled
    from planecal.io.samples import read_samples
    from planecal.sampling.driver import Driver
    from planecal.sampling.run import SamplingRun

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "run.tsv")
        drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
        stats = SamplingRun(drv, scene, rs, out, cached_world(st.scene, st.clearance_m)).run()
        if stats.status != "complete":
            raise RuntimeError(f"rehearsal with seed {seed}: {stats.status} ({stats.reason})")
        s = read_samples(out)
    return s.qe, s.d_mm * 1e-3, s.plate, s.direction, dict(stats.rejected)


def synthetic_noisy_samples(scene, truth, st: RehearsalSettings, seed: int):
    """Analytic model with the twin's noise model (module docstring)."""
    from planecal.model.measurement import plane_distance, sensor_in_base
    from planecal.model.encoder import counts_to_joints
    from planecal.twin.synthetic import synthetic_samples

    rng = np.random.default_rng(seed)
    robot = scene.robot
    qe, _, plate = synthetic_samples(scene, truth, st.samples, rng)
    q = counts_to_joints(robot, qe)
    s = st.joint_sigma()
    if s > 0:
        q = q + rng.normal(0.0, s, q.shape)
    if st.quantization:
        x = rng.uniform(-0.5, 0.5, q.shape) / robot.gains
        q = q + x @ robot.coupling.T
    o_b, z_b = sensor_in_base(robot, q, truth)
    d = plane_distance(truth.planes[plate], o_b, z_b)
    d = d + rng.normal(0.0, sample_sigma_m(st.options().laser_noise_mm), len(d))
    return (qe, d, plate, np.zeros(qe.shape, np.int8),
            {"collision": 0, "laser": 0, "unreachable": 0})


def rehearse_planned(scene, counts, plates, out, twin, checker, seed: int = 0):
    """A sampling run on ``twin`` through the planned poses (``ListPlanner``)."""
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.driver import Driver
    from planecal.sampling.planner import ListPlanner
    from planecal.sampling.run import RunSettings, SamplingRun

    rs = RunSettings(scene=str(scene.path), samples=len(counts), seed=seed)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
    return SamplingRun(drv, scene, rs, out, checker,
                       planner=ListPlanner(scene, counts, plates, checker)).run()


AIM_LEVEL = "offsets"  # what the first run's calibration aims a pose list with


def staged_samples(scene, world, st: RehearsalSettings, seed: int, options=None,
                   timed: bool = False, aim_samples: int = 30):
    """A pose list made from the nominal cell as a user runs it on a new cell: a first
    random run of ``aim_samples`` (``twin_samples``' planner), calibrated at level
    ``AIM_LEVEL`` (the cell: sensor pose, plates, offsets), aims the list
    (``poses.aim_counts``), which then runs (``pose_list_samples``' planner) from where
    the first left the robot: one session on one twin. The samples of both (a calibration
    takes them all), with ``timed`` the robot time of both; RuntimeError when either
    gives up."""
    from planecal.estimation.calibrate import CalibrationSettings, calibrate
    from planecal.model.scene import nominal_params
    from planecal.sampling.planner import ListPlanner, Planner
    from planecal.sampling.poses import CommandModel, aim_counts

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    checker = cached_world(st.scene, st.clearance_m)
    rs.samples = aim_samples
    acq = _acquirer(scene, twin, rs)
    first = _collect(scene, Planner(scene, rs.pose, checker), twin, rs, seed, True, acq)
    qe, d, plate, direction = first[:4]
    try:
        cal = calibrate(scene.robot, qe, d, nominal_params(scene), plate,
                        CalibrationSettings(level=AIM_LEVEL), direction, scene.references)
    except InputError as e:  # too few to calibrate the cell: the option that set them
        cut = (f" (the first {len(qe)} within the budget of {rs.robot_minutes:g} robot "
               "minutes)" if rs.robot_minutes is not None and len(qe) < aim_samples else "")
        raise InputError(f"--aim-samples {aim_samples}: the first run's calibration at "
                         f"level {AIM_LEVEL} on {scene.name}{cut}: {e}") from None
    counts, plates, approach = pose_list(st.poses)
    aimed, _ = aim_counts(scene, counts, plates, None,
                          CommandModel(cal.params, scene.robot.qe0.copy()))
    rs.samples = len(aimed)
    second = _collect(scene, ListPlanner(scene, aimed, plates, checker, approach=approach),
                      twin, rs, seed + 1, True, acq, first[5]["robot_time_s"])
    out = tuple(np.concatenate([a, b]) for a, b in zip(first[:4], second[:4]))
    rejected = {k: first[4].get(k, 0) + second[4].get(k, 0) for k in {*first[4], *second[4]}}
    robot = {k: first[5][k] + second[5][k] for k in first[5]}
    robot["aim_samples"] = int(len(qe))
    return (*out, rejected, robot) if timed else (*out, rejected)
