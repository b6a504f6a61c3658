"""Monte Carlo on the twin: repeated runs with fresh poses and noise, one calibration each,
compared with the truth and with the Cramer-Rao bound.

One run (``run_one``, a pure function of (settings, run index)) samples, calibrates from
the scene's nominal parameters and evaluates, at the truth and on the run's own samples,
the covariances of ``studies.common.covariances``. Sampling modes:

* ``twin`` (default): the rehearsal machinery without the tick-by-tick motion: the
  sampling run's own ``Planner`` (pose draw, IK, collision check of the target and of the
  straight joint path from the previous pose, with the run's random stream), the twin put
  at rest at the planned counts (``Twin.set_counts``: a repeatability draw, as when the
  robot settles at the end of a move) and the laser read through ``read_stable`` (100
  readings). Poses, rejections, counts and readings are those of ``planecal rehearse``
  with the same seeds (tests/test_studies_montecarlo.py checks it sample for sample);
  it only skips simulating the ticks of each move (the servo always settles exactly on
  the commanded counts, so the sample is the same).
* ``rehearse``: the full ``SamplingRun`` on the twin, tick by tick (slow; for checking).
* ``synthetic``: the analytic model (``planecal.twin.synthetic``'s poses, no collision check:
  a slightly different pose distribution) with the twin's noise model added in numpy:
  Gaussian joint repeatability, buffer-mean laser noise and, optionally, the encoder's
  quantisation (uniform +-0.5 count per actuator). For fast tests.

World: the twin's error profile (``errors``: ``ideal`` or ``realistic`` or a profile file,
``twin.profile``) and a seed make a world (``world_for``): the hidden truth (the cell's
offsets, sensor pose and plates, and in a realistic world the robot's true geometry and its
gear phases) and the twin's options (the joint errors the tick adds, the laser). The
settings' noise fields override the profile's (None: the profile's). By default one world
for all runs, drawn from ``truth_seed`` (bias is a property of the estimator at a truth);
``vary_truth`` draws one per run. Run k uses seed ``seed + k`` for its poses and noise. In
a world whose joint errors depend on the path (backlash, thermal growth) the ``twin`` mode
drives the ticks of each move (``sampling.collect.DriveAcquirer``, as ``rehearse``): a
jump to rest would leave every joint's backlash on the flank it started on.

The Cramer-Rao bound and the chi-square describe the noise (repeatability, quantisation,
laser noise). A realistic world also has errors the fit's model does not (geometry,
compliance, gear error, backlash, laser linearity): its residuals exceed the noise, and the
offsets absorb part of those errors, differently for every set of poses. The analysis
reports that as it is (``analyze``: ``world``, ``mismatch``); it does not widen the bound.

Summary (``analyze``) per free parameter: bias, empirical std, and, as the RMS over runs
of each run's value: the white-noise bound ``mean(v) (J^T J)^-1``, the sandwich (the true
covariance of the unweighted fit under the noise model), the Cramer-Rao bound
``(J^T V^-1 J)^-1`` and the std the fit reports. Chi-square: per run
T = e^T C^-1 e over the identifiable free joint offsets with C the fit's reported
covariance (and, separately, with the sandwich); T ~ chi2(k) if the reported covariance is
honest: the mean must be within 3 standard errors of k and a KS test against chi2(k)
must not reject at 1 %.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import asdict, dataclass, replace

import numpy as np

from planecal.model.cell import predict_with_jacobian
from planecal.base.errors import InputError
from planecal.estimation.fit import noise_variance
from planecal.model.layout import ParamLayout, level1_layout
from planecal.studies.common import (BUFFER_LEN, Progress, cached_profile, cached_scene,
                                     cached_world, covariances, parallel_map, table)

MODES = ("twin", "rehearse", "synthetic")
FORMAT = "planecal-montecarlo/1"
TARGET_RATIO = 0.15  # issue 6: empirical spread within 15 % of the bound
TARGET_BIAS = 0.2  # bias under a fifth of the bound



@dataclass(frozen=True)
class MCSettings:
    scene: str = "thesis_final"
    samples: int = 150
    runs: int = 20
    seed: int = 1000
    mode: str = "twin"
    truth_seed: int = 0
    vary_truth: bool = False
    offsets_all: bool = False  # truth with delta1, delta6 != 0 too
    errors: str = "ideal"  # the twin's error profile (the command's default: realistic)
    laser_noise_mm: float | None = None  # None: the profile's (0.001 mm in both)
    repeatability_mm: float | None = None  # None: the profile's (ideal: the robot's 0.07 mm)
    quantization: bool = False  # synthetic mode: add quantisation (a profile's: its own)
    free: tuple | None = None  # parameter names; None: all but delta1, delta6
    clearance_m: float = 0.01
    poses: tuple | None = None  # fixed encoder counts (planning study): replayed in order
    weighted: bool = False  # fit by weighted least squares with the noise model (fit.py)
    roll_deg: float | None = None  # the pose draw's roll about the beam; None: the default
    ik_choice: str | None = None  # the pose draw's IK branch choice; None: the default

    def check(self) -> None:
        if self.mode not in MODES:
            raise InputError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.samples < 20:
            raise InputError(f"--samples must be at least 20, got {self.samples}")
        if self.runs < 2:
            raise InputError(f"--runs must be at least 2, got {self.runs}")
        if self.seed < 0 or self.truth_seed < 0:
            raise InputError("seeds must be >= 0")
        if (self.laser_noise_mm or 0) < 0 or (self.repeatability_mm or 0) < 0:
            raise InputError("noise levels must be >= 0")
        if self.mode == "synthetic" and self.errors != "ideal":
            raise InputError(f"--errors {self.errors}: the synthetic mode is the analytic "
                             "model with the ideal world's noise; the other worlds need the "
                             "twin (--mode twin or rehearse), or give --errors ideal")
        opts = mc_options(self)  # the profile, read (InputError if it cannot be)
        if opts.laser_noise_mm == 0 and joint_sigma(cached_scene(self.scene).robot, self) == 0 \
                and not (opts.quantization or self.quantization):
            raise InputError("laser noise and repeatability are both 0: no noise to study")
        if self.weighted and self.quantization:
            raise InputError("--weighted with --quantization: the weighted fit's noise model "
                             "(repeatability + sensor) has no quantisation term")
        if self.roll_deg is not None and not 0.0 <= self.roll_deg <= 180.0:
            raise InputError(f"--roll-deg must be in [0, 180], got {self.roll_deg}")
        if (self.roll_deg is not None or self.ik_choice is not None) \
                and self.mode == "synthetic":
            raise InputError("--roll-deg and --ik-choice set the sampling run's pose draw; "
                             "the synthetic mode draws its own poses")
        if self.quantization and self.mode != "synthetic":
            raise InputError("--quantization adds encoder quantisation to the synthetic mode; "
                             "the twin's comes from its error profile (realistic has it)")


def mc_options(st: MCSettings, base=None):
    """The twin's options: ``base`` (default: the profile's) with the settings' noise
    overrides."""
    opts = cached_profile(st.scene, st.errors).options() if base is None else base
    kw = {}
    if st.laser_noise_mm is not None:
        kw["laser_noise_mm"] = st.laser_noise_mm
    if st.repeatability_mm is not None:
        kw["repeatability_mm"] = st.repeatability_mm
    return replace(opts, **kw)


def world_for(st: MCSettings, k: int):
    """Run k's world: (``twin.truth.Truth``, ``TwinOptions``) drawn from the profile
    (``twin.profile.draw_world``); ``offsets_all`` also draws delta1 and delta6 where the
    profile keeps them 0, within the largest of its bounds."""
    from planecal.twin.profile import draw_world
    from planecal.twin.truth import draw_truth
    seed = st.seed + k if st.vary_truth else st.truth_seed
    scene, profile = cached_scene(st.scene), cached_profile(st.scene, st.errors)
    world, opts = draw_world(scene, seed, profile)
    if st.offsets_all:
        tol = profile.tolerances()
        b = tol.offset_bounds()
        if np.any(b == 0):
            b = np.where(b > 0, b, b.max())
            world = replace(world, params=draw_truth(scene, seed,
                                                     replace(tol, offset_rad=tuple(b))))
    return world, mc_options(st, opts)


# The error sources of a world, by family (what ``without`` switches off): the ones the
# fit's model does not have, and the noise.
SOURCES = {
    "geometry": "geometry other than the joint offsets (link lengths and offsets, twists, "
                "base and flange frames)",
    "compliance": "gravity compliance (J2, J3)",
    "gear": "gear transmission error",
    "backlash": "backlash",
    "noise": "repeatability and encoder quantisation",
    "laser_linearity": "laser linearity",
    "thermal": "thermal growth",
}
SHORT = {"geometry": "link lengths, twists and frames", "compliance": "joint compliance",
         "gear": "gear error", "backlash": "backlash", "noise": "repeatability, quantisation",
         "laser_linearity": "laser linearity", "thermal": "thermal growth"}
MISMATCH = ("geometry", "compliance", "gear", "backlash", "laser_linearity", "thermal")


def sources_on(robot, world, options) -> list[str]:
    """The families of ``SOURCES`` present in a world (``Truth``, ``TwinOptions``)."""
    from planecal.model.kinematics import from_robot
    kin = getattr(world, "kinematics", None)
    nom = from_robot(robot)
    geometry = kin is not None and not all(
        np.array_equal(getattr(kin, f), getattr(nom, f))
        for f in ("alpha", "a", "beta", "theta", "d", "base", "flange"))
    rep = robot.repeatability_m if options.repeatability_mm is None \
        else options.repeatability_mm * 1e-3
    on = {"geometry": geometry,
          "compliance": options.stiffness_nm_per_rad is not None
          and any(k is not None for k in options.stiffness_nm_per_rad),
          "gear": any(a > 0 for _, a, _ in options.gear),
          "backlash": options.backlash_rad is not None and bool(np.any(options.backlash_rad)),
          "noise": rep > 0 or options.quantization,
          "laser_linearity": options.laser_linearity_mm > 0,
          "thermal": options.thermal is not None}
    return [k for k in SOURCES if on[k]]


def without(world, options, off):
    """The world (``Truth``, ``TwinOptions``) with the families in ``off`` switched off
    (``SOURCES``; the cell's offsets, sensor pose and plates stay)."""
    from planecal.twin.truth import Truth
    if not isinstance(world, Truth):
        world = Truth(world)
    kw = {}
    for f in off:
        if f not in SOURCES:
            raise InputError(f"error source {f!r}: one of {', '.join(SOURCES)}")
        if f == "geometry":
            world = replace(world, kinematics=None)
        elif f == "compliance":
            kw["stiffness_nm_per_rad"] = None
        elif f == "gear":
            kw["gear"] = ()
            world = replace(world, gear_phases=())
        elif f == "backlash":
            kw.update(backlash_rad=None, backlash_preload_nm=None)
        elif f == "noise":
            kw.update(repeatability_mm=0.0, quantization=False)
        elif f == "laser_linearity":
            kw["laser_linearity_mm"] = 0.0
        else:
            kw["thermal"] = None
    return world, replace(options, **kw)


def path_dependent(options) -> bool:
    """Joint errors that depend on how the robot got there (backlash by the direction of
    the last motion, thermal growth over robot time): a jump to rest cannot show them."""
    return bool((options.backlash_rad is not None and np.any(np.asarray(options.backlash_rad)))
                or options.thermal is not None)


def layout_for(name: str) -> ParamLayout:
    """The parameter layout of a study on scene ``name`` (one n~ per plate)."""
    return level1_layout(len(cached_scene(name).plates))


def truth_for(st: MCSettings, k: int):
    """Run k's cell truth (a ``CellParams``: what the offsets are compared with)."""
    return world_for(st, k)[0].params


def joint_sigma(robot, st: MCSettings) -> float:
    """The repeatability's std per joint [rad] of the settings' world."""
    from planecal.model.robot import repeatability_sigma
    mm = mc_options(st).repeatability_mm
    rep = robot.repeatability_m if mm is None else mm * 1e-3
    return repeatability_sigma(robot, rep) if rep > 0 else 0.0


# ----- sampling -----------------------------------------------------------------------------

def _twin_and_settings(scene, world, st: MCSettings, seed: int, options=None):
    """The run's twin in ``world`` (a ``Truth``, or a ``CellParams``: robot.json's
    geometry) with ``options`` (default: the settings' profile and noise), and its
    sampling settings."""
    from planecal.sampling.run import RunSettings
    from planecal.twin import Twin

    twin = Twin(scene, truth=world, seed=seed,
                options=mc_options(st) if options is None else options)
    rs = RunSettings.for_scene(scene, samples=st.samples, seed=seed)
    rs.clearance_m = st.clearance_m
    if st.roll_deg is not None:
        rs.pose.roll_deg = st.roll_deg
    if st.ik_choice is not None:
        rs.pose.ik_choice = st.ik_choice
    return twin, rs


def _collect(scene, planner, twin, rs, seed: int):
    """The collect core with the twin set at rest at each target (``RestAcquirer``), or,
    where the twin's joint errors depend on the path, driven there tick by tick
    (``DriveAcquirer``, as ``rehearse``): (qe, d_m, plate, rejected dict); RuntimeError
    when the run gives up."""
    from planecal.model.encoder import counts_to_joints
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.collect import (Cursor, DriveAcquirer, MemoryRecorder,
                                           RestAcquirer, Tally, collect)
    from planecal.sampling.driver import Driver

    rec, tally = MemoryRecorder(), Tally()
    cursor = Cursor(counts_to_joints(scene.robot, twin.current_counts),
                    np.random.default_rng(seed).bit_generator.state)
    if path_dependent(twin.options):
        drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
        drv.start()
        acq = DriveAcquirer(drv, rs.laser, rs.nominal_step_counts, rs.dwell_ticks)
    else:
        acq = RestAcquirer(twin, rs.laser)
    collect(planner, acq, rec, rs.samples, cursor, tally, rs.max_attempts)
    if tally.status != "complete":
        raise RuntimeError(f"run with seed {seed}: {tally.reason}")
    qe, d, plate = rec.arrays()
    return qe, d, plate, dict(tally.rejected)


def twin_samples(scene, world, st: MCSettings, seed: int, options=None):
    """The ``twin`` mode (module docstring) in ``world`` (a ``Truth`` from ``world_for`` or
    ``twin.profile.draw_world``, or a ``CellParams``) with ``options`` (default: the
    settings' profile and noise): (qe, d_m, plate, rejected dict)."""
    from planecal.sampling.planner import Planner

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    return _collect(scene, Planner(scene, rs.pose, cached_world(st.scene, st.clearance_m)), twin,
                    rs, seed)


def pose_list_samples(scene, world, st: MCSettings, seed: int, options=None):
    """A planned pose list measured on the twin as ``rehearse --poses`` visits it (each
    pose checked from the last; a blocked one later), set at rest at each pose (driven
    there where the joint errors depend on the path)."""
    from planecal.sampling.planner import ListPlanner

    twin, rs = _twin_and_settings(scene, world, st, seed, options)
    counts = np.array([c for c, _ in st.poses], np.int64)
    plates = np.array([k for _, k in st.poses], int)
    rs.samples = len(counts)
    planner = ListPlanner(scene, counts, plates, cached_world(st.scene, st.clearance_m))
    return _collect(scene, planner, twin, rs, seed)


def rehearse_samples(scene, world, st: MCSettings, seed: int, options=None):
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
    return s.qe, s.d_mm * 1e-3, s.plate, dict(stats.rejected)


def synthetic_noisy_samples(scene, truth, st: MCSettings, seed: int):
    """Analytic model with the twin's noise model (module docstring)."""
    from planecal.model.cell import plane_distance, sensor_in_base
    from planecal.model.encoder import counts_to_joints
    from planecal.twin.synthetic import synthetic_samples

    rng = np.random.default_rng(seed)
    robot = scene.robot
    qe, _, plate = synthetic_samples(scene, truth, st.samples, rng)
    q = counts_to_joints(robot, qe)
    s = joint_sigma(robot, st)
    if s > 0:
        q = q + rng.normal(0.0, s, q.shape)
    if st.quantization:
        x = rng.uniform(-0.5, 0.5, q.shape) / robot.gains
        q = q + x @ robot.coupling.T
    o_b, z_b = sensor_in_base(robot, q, truth)
    d = plane_distance(truth.planes[plate], o_b, z_b)
    d = d + rng.normal(0.0, mc_options(st).laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN), len(d))
    return qe, d, plate, {"collision": 0, "laser": 0, "unreachable": 0}


# ----- one run --------------------------------------------------------------------------------

def sample_variance(robot, J_delta, joint_sigma_rad: float, distance_sigma_m: float,
                    quantization: bool) -> np.ndarray:
    """Each sample's distance noise variance (``studies.common``'s model): repeatability
    through the offsets' Jacobian ``J_delta``, the laser's buffer mean, and with
    ``quantization`` the motors' uniform +-1/2 count (through the wrist coupling)."""
    v = noise_variance(J_delta, joint_sigma_rad, distance_sigma_m)
    if quantization:
        Jx = J_delta @ robot.coupling  # dd/dx (actuator angles)
        v = v + np.sum(Jx ** 2 / (12.0 * robot.gains ** 2), axis=1)
    return v


def run_one(job) -> dict:
    """One Monte Carlo run: job = (settings, k). Pure function of (settings, k)."""
    from planecal.estimation.fit import FitOptions, Problem, solve, uncertainty
    from planecal.model.scene import nominal_params

    st, k = job
    scene = cached_scene(st.scene)
    robot = scene.robot
    seed = st.seed + k
    world, opts = world_for(st, k)
    truth = world.params
    try:
        if st.poses is not None:
            qe, d, plate, rejected = pose_list_samples(scene, world, st, seed, opts)
        elif st.mode == "twin":
            qe, d, plate, rejected = twin_samples(scene, world, st, seed, opts)
        elif st.mode == "rehearse":
            qe, d, plate, rejected = rehearse_samples(scene, world, st, seed, opts)
        else:
            qe, d, plate, rejected = synthetic_noisy_samples(scene, truth, st, seed)
    except RuntimeError as e:  # the run gave up (e.g. 500 poses rejected in a row)
        return {"k": k, "seed": seed, "failed": str(e)}
    layout = layout_for(st.scene)
    s = joint_sigma(robot, st)
    sample_sigma = opts.laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN)
    weights = {"joint_sigma_rad": s, "distance_sigma_m": max(sample_sigma, 1e-9)} \
        if st.weighted else {}
    fit = solve(Problem.from_arrays(robot, qe, d, nominal_params(scene), plate, free=st.free,
                                    options=FitOptions(**weights), layout=layout))
    free = fit.free
    # noise model and bounds at the truth, on this run's samples
    _, J = predict_with_jacobian(robot, qe, truth, plate, layout)
    v = sample_variance(robot, J[:, layout.slice("joint_offsets")], s, sample_sigma,
                        st.quantization or (opts.quantization and st.mode != "synthetic"))
    cov = covariances(J[:, free], v)
    # identifiability with every parameter free, at the truth
    all_free = np.ones(len(layout), bool)
    ident_all, _, _ = uncertainty(J, np.sqrt(v), layout, all_free)
    err = fit.params.to_vector(layout)[free] - truth.to_vector(layout)[free]
    return {
        "k": k, "seed": seed, "samples": int(len(d)), "rejected": rejected,
        "err": err, "reported_cov": fit.covariance.matrix, "reported_std": fit.covariance.stds,
        "white_var": np.diag(cov["white"]), "sandwich_var": np.diag(cov["sandwich"]),
        "crb_var": np.diag(cov["crb"]), "sandwich_cov": cov["sandwich"],
        "crb_cov": cov["crb"],
        "sigma_model_mm": float(np.sqrt(np.mean(v)) * 1e3),
        "sigma_fit_mm": float(fit.sigma_m * 1e3), "rms_mm": fit.rms_mm(),
        "max_residual_mm": float(np.abs(fit.residuals_m).max() * 1e3),
        "converged": bool(fit.converged), "iterations": int(fit.iterations),
        "not_identifiable": fit.identifiability.not_identifiable,
        "not_identifiable_all_free": ident_all.not_identifiable,
        "truth": truth.to_vector(layout)[free],
    }


def run_many(st: MCSettings, engine=1, quiet: bool = False, label: str | None = None,
             results=None, resume: bool = False):
    """The runs of ``st`` in run order, through ``engine`` (``studies.common.engine_for``:
    an open ``Engine``, or a job count); run k is ``run_one((st, k))`` on whichever worker,
    its seed ``st.seed + k``. ``results``: the JSON-lines file each run is written to as it
    completes (key k, header the settings); ``resume`` runs only the k not in it yet."""
    st.check()
    prog = Progress(label or f"montecarlo {st.scene} N={st.samples}", st.runs, quiet=quiet)
    return parallel_map(run_one, [(st, k) for k in range(st.runs)], engine, prog,
                        key=_run_key, results=results, resume=resume,
                        header={"format": FORMAT, "settings": asdict(st)})


def _run_key(item) -> int:
    return item[1]


# ----- analysis ---------------------------------------------------------------------------------

def _chi2(errs, covs, idx):
    from scipy import stats
    T = []
    for e, C in zip(errs, covs):
        Ci = C[np.ix_(idx, idx)]
        if not np.all(np.isfinite(Ci)):
            continue
        ei = e[idx]
        T.append(float(ei @ np.linalg.solve(Ci, ei)))
    T = np.array(T)
    kdim = len(idx)
    values = T.tolist()
    R = len(T)
    if R < 2 or kdim == 0:
        return None
    se = np.sqrt(2 * kdim / R)
    ks = stats.kstest(T, "chi2", args=(kdim,))
    q95 = stats.chi2.ppf(0.95, kdim)
    ok = bool(abs(T.mean() - kdim) < 3 * se and ks.pvalue > 0.01)
    return {"dof": kdim, "runs": R, "mean": float(T.mean()), "expected": kdim,
            "standard_error": float(se), "ks_pvalue": float(ks.pvalue),
            "share_below_chi2_95": float(np.mean(T < q95)), "passes": ok, "values": values}


def analyze(runs: list[dict], st: MCSettings) -> dict:
    layout = layout_for(st.scene)
    names = layout.names
    fnames = layout.names_of(layout.free_from_names(st.free))
    failed = [{"seed": r["seed"], "reason": r["failed"]} for r in runs if "failed" in r]
    runs = [r for r in runs if "failed" not in r]
    if len(runs) < 2:
        raise InputError(f"only {len(runs)} of {len(runs) + len(failed)} runs completed")
    R = len(runs)
    E = np.array([r["err"] for r in runs])
    bias = E.mean(0)
    emp = E.std(0, ddof=1)

    def rms(key):
        return np.sqrt(np.mean([r[key] for r in runs], axis=0))
    white, sand, crb = rms("white_var"), rms("sandwich_var"), rms("crb_var")
    # errors normalised by each run's own bound: std 1 if the bound holds run by run; its
    # standard error stays 1/sqrt(2(R-1)) however much the designs (and bounds) vary
    Z = E / np.sqrt([r["crb_var"] for r in runs])
    # the fit reports no std (NaN) for a parameter it finds not identifiable in that run;
    # in a world with model mismatch its residual sigma is larger and a weak parameter
    # (phi_z) exceeds its practical limit in every run: no std to average (NaN, counted)
    rep2 = np.array([np.asarray(r["reported_std"], float) ** 2 for r in runs])
    n_rep = np.isfinite(rep2).sum(0)
    rep = np.full(rep2.shape[1], np.nan)
    has = n_rep > 0
    rep[has] = np.sqrt(np.nansum(rep2[:, has], axis=0) / n_rep[has])
    rel_se = 1.0 / np.sqrt(2 * (R - 1))  # relative standard error of a std from R runs
    params = {}
    for i, n in enumerate(fnames):
        params[n] = {
            "bias": float(bias[i]), "empirical_std": float(emp[i]),
            "crb_white_std": float(white[i]), "sandwich_std": float(sand[i]),
            "crb_std": float(crb[i]), "reported_std": float(rep[i]),
            "reported_in_runs": int(n_rep[i]),
            "ratio_emp_to_crb_white": float(emp[i] / white[i]),
            "ratio_emp_to_sandwich": float(emp[i] / sand[i]),
            "ratio_emp_to_crb": float(emp[i] / crb[i]),
            "normalized_std": float(Z[:, i].std(ddof=1)),
            "ratio_emp_to_reported": float(emp[i] / rep[i]),
            "bias_over_crb": float(abs(bias[i]) / crb[i]),
            "bias_t": float(bias[i] / (emp[i] / np.sqrt(R))),
        }
    offsets = layout.group("joint_offsets").names
    off = [i for i, n in enumerate(fnames) if n in offsets
           and all(n not in r["not_identifiable"] for r in runs)]
    errs = [r["err"] for r in runs]
    chi_rep = _chi2(errs, [r["reported_cov"] for r in runs], off)
    # the sandwich is the unweighted estimator's covariance: no check of a weighted fit
    chi_sand = None if st.weighted else _chi2(errs, [r["sandwich_cov"] for r in runs], off)
    chi_all = _chi2(errs, [r["reported_cov"] for r in runs],
                    [i for i, n in enumerate(fnames)
                     if all(n not in r["not_identifiable"] for r in runs)])
    offs = [fnames[i] for i in off]
    within = {n: abs(params[n]["ratio_emp_to_crb"] - 1) <= TARGET_RATIO for n in offs}
    within_white = {n: abs(params[n]["ratio_emp_to_crb_white"] - 1) <= TARGET_RATIO for n in offs}
    honest = {n: abs(params[n]["ratio_emp_to_reported"] - 1) <= TARGET_RATIO for n in offs}
    small_bias = {n: params[n]["bias_over_crb"] < TARGET_BIAS for n in offs}
    rej = {k: int(sum(r["rejected"].get(k, 0) for r in runs)) for k in ("collision", "laser", "unreachable")}
    return {
        "format": FORMAT, "world": _world_summary(st, runs),
        "settings": _settings_dict(st), "runs": R, "free": fnames, "params": params,
        "offsets": offs,
        "relative_standard_error_of_std": rel_se,
        "chi2_offsets_reported": chi_rep, "chi2_offsets_sandwich": chi_sand,
        "chi2_all_reported": chi_all,
        "verdict": {
            "efficient_within_15pct_of_crb": within,
            "within_15pct_of_white_crb": within_white,
            "reported_std_within_15pct": honest,
            "bias_under_fifth_of_crb": small_bias,
            "chi2_passes": None if chi_rep is None else chi_rep["passes"],
        },
        "sigma_model_mm": float(np.mean([r["sigma_model_mm"] for r in runs])),
        "sigma_fit_mm": float(np.mean([r["sigma_fit_mm"] for r in runs])),
        "not_converged": int(sum(not r["converged"] for r in runs)),
        "rejected_total": rej,
        "not_identifiable_all_free": sorted({n for r in runs for n in r["not_identifiable_all_free"]},
                                            key=names.index),
        "samples_per_run": float(np.mean([r["samples"] for r in runs])),
        "failed_runs": failed,
        "run_errors": E.tolist(),
        "run_crb_std": np.sqrt([r["crb_var"] for r in runs]).tolist(),
    }


def _world_summary(st: MCSettings, runs: list[dict]) -> dict:
    """The world the runs sampled in (profile, its error sources, the effective noise) and
    how far the fit's residuals exceed the noise (the model mismatch)."""
    scene = cached_scene(st.scene)
    opts = mc_options(st)
    if st.mode == "synthetic":
        on = ["noise"]
    else:
        on = sources_on(scene.robot, world_for(st, 0)[0], opts)
    rep = opts.repeatability_mm
    sig_model = float(np.mean([r["sigma_model_mm"] for r in runs]))
    sig_fit = float(np.mean([r["sigma_fit_mm"] for r in runs]))
    mx = np.array([r["max_residual_mm"] for r in runs])
    return {"errors": str(st.errors), "profile": str(cached_profile(st.scene, st.errors).path),
            "sources": on, "model_mismatch": [f for f in on if f in MISMATCH],
            "laser_noise_mm": opts.laser_noise_mm,
            "repeatability_mm": scene.robot.repeatability_m * 1e3 if rep is None else rep,
            "quantization": bool(st.quantization or (opts.quantization
                                                     and st.mode != "synthetic")),
            "sigma_fit_over_model": sig_fit / sig_model if sig_model > 0 else float("inf"),
            "max_residual_mm": {"median": float(np.median(mx)), "min": float(mx.min()),
                                "max": float(mx.max())}}


def _settings_dict(st: MCSettings) -> dict:
    d = asdict(st)
    d["poses"] = None if st.poses is None else len(st.poses)
    return d


def slope_study(st: MCSettings, sample_counts: list[int], engine=1, quiet=False,
                results=None, resume: bool = False) -> dict:
    """Empirical and CR spread of the offsets vs the number of samples, and the log-log
    slope (N^-1/2 expected) fitted over ``sample_counts``. ``results(n)``: the results
    file of the point with n samples (``run_many``)."""
    rows = []
    for n in sample_counts:
        s = replace(st, samples=n)
        res = analyze(run_many(s, engine, quiet, label=f"slope N={n}",
                               results=None if results is None else results(n),
                               resume=resume), s)
        rows.append({"samples": n, **{p: {"empirical_std": res["params"][p]["empirical_std"],
                                          "crb_std": res["params"][p]["crb_std"]}
                                      for p in res["offsets"]}})
    offs = [k for k in rows[0] if k != "samples"]
    logn = np.log([r["samples"] for r in rows])
    slopes = {}
    for p in offs:
        ye = np.log([r[p]["empirical_std"] for r in rows])
        yc = np.log([r[p]["crb_std"] for r in rows])
        slopes[p] = {"empirical": float(np.polyfit(logn, ye, 1)[0]),
                     "crb": float(np.polyfit(logn, yc, 1)[0])}
    return {"scene": st.scene, "sample_counts": list(sample_counts), "runs_per_point": st.runs,
            "rows": rows, "slopes": slopes}


def format_montecarlo(res: dict) -> str:
    st = res["settings"]
    layout = layout_for(st["scene"])
    w = res["world"]
    out = [f"Monte Carlo: scene {st['scene']}, mode {st['mode']}, {res['runs']} runs of "
           f"{res['samples_per_run']:.0f} samples; {w['errors']} world, truth "
           + ("drawn per run" if st["vary_truth"] else f"fixed (seed {st['truth_seed']})")
           + f"; noise: laser {w['laser_noise_mm']:g} mm per reading, repeatability "
           + f"{w['repeatability_mm']:g} mm"
           + (", encoder quantisation" if w["quantization"] else "")
           + ("; fit weighted by the noise model" if st.get("weighted") else
              "; fit unweighted"),
           f"noise model rms per sample {res['sigma_model_mm'] * 1e3:.2f} um, fit sigma "
           f"{res['sigma_fit_mm'] * 1e3:.2f} um; a std from {res['runs']} runs is known to "
           f"+-{res['relative_standard_error_of_std']:.0%} (1 s.e.)", ""]
    rows = []
    for n, p in res["params"].items():
        k, unit = layout.display(n)
        rows.append([n, unit, f"{p['bias'] * k:+.3g}", f"{p['empirical_std'] * k:.4g}",
                     f"{p['crb_std'] * k:.4g}", f"{p['crb_white_std'] * k:.4g}",
                     f"{p['sandwich_std'] * k:.4g}", f"{p['reported_std'] * k:.4g}",
                     f"{p['ratio_emp_to_crb']:.3f}", f"{p['ratio_emp_to_crb_white']:.3f}",
                     f"{p['ratio_emp_to_sandwich']:.3f}", f"{p['ratio_emp_to_reported']:.3f}",
                     f"{p['normalized_std']:.3f}", f"{p['bias_over_crb']:.3f}"])
    out.append(table(["param", "unit", "bias", "emp_std", "CRB", "CRB_white", "sandwich",
                      "reported", "emp/CRB", "emp/white", "emp/sandw", "emp/rep", "std(e/CRB)",
                      "|bias|/CRB"], rows))
    out.append("emp/X: empirical std over the RMS of the runs' X; std(e/CRB): std of the errors "
               "each divided by its own run's bound (robust to designs of unequal strength)")
    if st.get("weighted"):
        out.append("sandwich: the unweighted fit's covariance, for comparison (the errors "
                   "and 'reported' are the weighted fit's)")
    out.append("")
    for key, what in (("chi2_offsets_reported", "offsets, fit's reported covariance"),
                      ("chi2_offsets_sandwich", "offsets, sandwich covariance"),
                      ("chi2_all_reported", "all free parameters, reported covariance")):
        c = res[key]
        if c:
            out.append(f"chi-square ({what}): mean {c['mean']:.2f} for {c['dof']} dof "
                       f"(+-{c['standard_error']:.2f}), KS p {c['ks_pvalue']:.3f}, "
                       f"{c['share_below_chi2_95']:.0%} below the 95 % quantile -> "
                       + ("PASS" if c["passes"] else "FAIL"))
    v = res["verdict"]
    out.append("")
    out.append("offsets within 15 % of the Cramer-Rao bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["efficient_within_15pct_of_crb"].items()))
    out.append("offsets within 15 % of the white-noise bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["within_15pct_of_white_crb"].items()))
    out.append("reported std within 15 % of the spread: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["reported_std_within_15pct"].items()))
    out.append("bias under a fifth of the bound: "
               + ", ".join(f"{n} {'yes' if ok else 'NO'}" for n, ok in v["bias_under_fifth_of_crb"].items()))
    unreported = [n for n, p in res["params"].items() if p.get("reported_in_runs", 1) == 0]
    if unreported:
        out.append("no std reported in any run (the fit found it not identifiable at its "
                   "residual level): " + ", ".join(unreported))
    if res["not_identifiable_all_free"]:
        out.append("with every parameter free, not identifiable: "
                   + ", ".join(res["not_identifiable_all_free"]))
    out += _format_mismatch(res)
    r = res["rejected_total"]
    out.append(f"rejected poses over all runs: collision {r['collision']}, laser {r['laser']}, "
               f"unreachable {r['unreachable']}; fits not converged: {res['not_converged']}")
    for f in res.get("failed_runs", []):
        out.append(f"run with seed {f['seed']} left out: {f['reason']}")
    return "\n".join(out)


def _format_mismatch(res: dict) -> list[str]:
    """What the world's errors beyond the noise do to the comparison with the bound."""
    w = res["world"]
    mx = w["max_residual_mm"]
    out = ["", f"max model error after calibration (largest |residual| of a run): median "
               f"{mx['median']:.3f} mm ({mx['min']:.3f}-{mx['max']:.3f}); the real MC70 "
               f"(seed Table 9): 0.102-0.188 mm on sets of 30-257 samples"]
    if not w["model_mismatch"]:
        out.append("the world's only errors are the noise the bound describes: the spread "
                   "should meet the bound and the chi-square pass")
        return out
    offs = res["offsets"]
    emp = [res["params"][n]["ratio_emp_to_crb"] for n in offs]
    bias = [res["params"][n]["bias_over_crb"] for n in offs]
    c = res["chi2_offsets_reported"]
    out.append(
        "model mismatch: this world has errors the fit's model does not ("
        + ", ".join(SOURCES[f] for f in w["model_mismatch"]) + "). The fit's residual sigma "
        f"is {w['sigma_fit_over_model']:.1f}x the noise model's; the offsets absorb the rest. "
        f"Their spread over runs is {min(emp):.1f}-{max(emp):.1f}x the Cramer-Rao bound and "
        f"their bias {min(bias):.1f}-{max(bias):.1f}x it"
        + (f"; chi-square mean {c['mean']:.0f} for {c['dof']} dof" if c else "")
        + ". The bound and the reported std describe the noise only, not the mismatch: "
        "against the truth they are too small, as they are on a real robot.")
    return out


def format_slope(sl: dict) -> str:
    offs = list(sl["slopes"])
    layout = layout_for(sl["scene"])
    unit = layout.display(offs[0])[1] if offs else "urad"
    rows = []
    for r in sl["rows"]:
        row = [str(r["samples"])]
        for p in offs:
            k, _ = layout.display(p)
            row.append(f"{r[p]['empirical_std'] * k:.3g} / {r[p]['crb_std'] * k:.3g}")
        rows.append(row)
    rows.append(["slope"] + [f"{sl['slopes'][p]['empirical']:+.3f} / {sl['slopes'][p]['crb']:+.3f}"
                             for p in offs])
    return (f"spread vs samples ({sl['runs_per_point']} runs per point), empirical / CRB [{unit}]; "
            f"expected slope -0.5\n" + table(["samples"] + offs, rows))
