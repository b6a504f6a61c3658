"""The calibration's options, the same on every command that calibrates (calibrate, demo,
bootstrap, montecarlo, validate, plan, layouts; sweep's spec has the same keys):

    --level offsets|full|nonkinematic|1|2|3   what is calibrated (planecal.model.levels)
    --compliance               also J2 and J3's joint compliance (level 3 has it always)
    --free NAMES               the candidates (default: the level's)
    --geometry-prior MM,MRAD   levels 2, 3: pull the joint geometry towards robot.json's
    --free-scale               levels 2, 3: also free the arm's scale
    --weighted                 weighted least squares with the noise model

``add_fit_arguments`` adds the solver's own options (calibrate and bootstrap).
``calibration_settings(args)`` turns them into the one ``CalibrationSettings``.
"""
from __future__ import annotations

import math

from planecal.base.errors import InputError
from planecal.commands.value_options import MAX_ITERATIONS, count


def add_calibration_arguments(p, weighted_help: str | None = None) -> None:
    from planecal.model.levels import ALIASES, LEVELS
    g = p.add_argument_group("what is calibrated (the same on every command that calibrates)")
    g.add_argument("--level", choices=list(LEVELS) + list(ALIASES), default="offsets",
                   help="offsets (the seed's level 1, default): joint offsets, sensor, planes; "
                        "full (level 2): the whole kinematic model, its identifiable base set "
                        "chosen from the samples; nonkinematic (level 3): the whole model "
                        "with compliance, each joint's gear harmonics and backlash (by the "
                        "samples' recorded approach direction, or the gravity torque)")
    g.add_argument("--compliance", action="store_true",
                   help="also fit the joint compliance of J2 and J3 (gravity torque from "
                        "robot.json's link masses; seed 5.4; part of level 3)")
    g.add_argument("--free", default=None, metavar="NAMES",
                   help="comma-separated parameters to fit (default: all but delta1, delta6 "
                        "and the arm's scale; at level full the candidates of the base set)")
    g.add_argument("--geometry-prior", metavar="MM,MRAD", default=None,
                   help="with --level full or nonkinematic: pull the joint geometry towards "
                        "robot.json's with "
                        "these stds (a maximum a posteriori fit; e.g. 0.5,0.5)")
    g.add_argument("--free-scale", action="store_true",
                   help="with --level full or nonkinematic: also free the arm's scale (its "
                        "two longest link "
                        "lengths), which a laser on planes reads only through its own gain")
    g.add_argument("--weighted", action="store_true",
                   help=weighted_help or "weighted least squares with the robot's "
                        "repeatability as the noise model (each sample's variance from its "
                        "pose)")


def add_fit_arguments(p) -> None:
    """The solver's options and the weighted fit's noise model."""
    g = p.add_argument_group("the fit")
    g.add_argument("--max-iter", type=count(MAX_ITERATIONS), default=30,
                   help="at most this many corrections (default %(default)s)")
    g.add_argument("--improvement-limit", type=float, default=1e-12,
                   help="stop when the mean absolute correction falls below this "
                        "(default %(default)g)")
    g.add_argument("--outlier-sigma", type=float, default=None,
                   help="drop samples whose error is more than K standard deviations from the "
                        "mean (the seed used 4); off by default")
    g.add_argument("--method", choices=["gn", "lm"], default="gn",
                   help="gn: Gauss-Newton with SVD pseudo-inverse (seed); lm: Levenberg-Marquardt")
    g.add_argument("--no-scale", action="store_true", help="no column scaling of the Jacobian")
    g.add_argument("--repeatability-mm", type=float, default=None,
                   help="with --weighted: the robot's repeatability, +- mm at the flange "
                        "(default: robot.json's)")
    g.add_argument("--distance-sigma-um", type=float, default=None,
                   help="with --weighted: std of a sample's distance from the sensor itself "
                        "(default 1 um)")


def _prior(text: str | None):
    if text is None:
        return None
    try:
        mm, mrad = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--geometry-prior: expected MM,MRAD (two numbers), got "
                         f"{text!r}") from None
    if not (math.isfinite(mm) and math.isfinite(mrad) and mm > 0 and mrad > 0):
        raise InputError(f"--geometry-prior: both stds must be > 0, got {text!r}")
    return mm * 1e-3, mrad * 1e-3


def _free(text: str | None):
    if text is None:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise InputError(f"--free: no parameter named in {text!r}")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"--free: {', '.join(dup)} named twice")
    return tuple(names)


def fit_options(args, robot):
    """FitOptions from ``add_fit_arguments``' flags, each checked; with --weighted the
    repeatability noise model of ``robot`` (or of --repeatability-mm)."""
    from planecal.estimation.fit import FitOptions

    if not (math.isfinite(args.improvement_limit) and args.improvement_limit >= 0):
        raise InputError(f"--improvement-limit must be a number >= 0, got "
                         f"{args.improvement_limit}")
    if args.outlier_sigma is not None and not (math.isfinite(args.outlier_sigma)
                                               and args.outlier_sigma > 0):
        raise InputError(f"--outlier-sigma must be a number > 0, got {args.outlier_sigma}")
    return FitOptions(max_iter=args.max_iter, improvement_limit=args.improvement_limit,
                      outlier_sigma=args.outlier_sigma, method=args.method,
                      scale=not args.no_scale,
                      **weighting(args.weighted, robot, args.repeatability_mm,
                                  args.distance_sigma_um))


def weighting(weighted: bool, robot, repeatability_mm: float | None = None,
              distance_sigma_um: float | None = None) -> dict:
    """FitOptions fields of --weighted: the robot's repeatability noise model (empty
    without it); ``robot`` None: a study that sets its world's noise per run."""
    if not weighted:
        for flag, v in (("--repeatability-mm", repeatability_mm),
                        ("--distance-sigma-um", distance_sigma_um)):
            if v is not None:
                raise InputError(f"{flag} needs --weighted")
        return {}
    if robot is None:
        return {}
    from planecal.estimation.noise import repeatability_sigma
    rep = repeatability_mm
    if rep is not None and not (math.isfinite(rep) and rep > 0):
        raise InputError(f"--repeatability-mm must be > 0, got {rep:g}")
    sd_um = 1.0 if distance_sigma_um is None else distance_sigma_um
    if not (math.isfinite(sd_um) and sd_um > 0):
        raise InputError(f"--distance-sigma-um must be > 0, got {sd_um:g}")
    r_m = robot.repeatability_m if rep is None else rep * 1e-3
    if not r_m > 0:
        raise InputError("--weighted: the robot description has no repeatability_mm; "
                         "give --repeatability-mm")
    return {"joint_sigma_rad": repeatability_sigma(robot, r_m), "distance_sigma_m": sd_um * 1e-6}


def calibration_settings(args, robot=None, options=None, scene=None):
    """The ``CalibrationSettings`` of the flags, checked (InputError naming the option).
    ``options``: the fit's (``fit_options`` on a command that has them); otherwise the
    defaults, with --weighted the repeatability noise model of ``robot`` (None: a study
    sets its world's noise per run). With ``scene``, --free's names are checked against
    the level's parameters on its plates before any work."""
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.estimation.fit import FitOptions

    if options is None:
        options = FitOptions(**weighting(args.weighted, robot))
    st = CalibrationSettings(level=args.level, compliance=args.compliance,
                             free=_free(args.free), geometry_prior=_prior(args.geometry_prior),
                             free_scale=args.free_scale, options=options)
    st.check()
    if scene is not None and st.free is not None:
        from planecal.model.levels import layout_for
        layout_for(scene.robot, len(scene.plates), st.level, st.compliance).free_mask(st.free)
    return st


def load_inputs(samples, scene_name, initial_path):
    """(samples, scene, initial parameters) of a calibration's inputs; the samples checked
    against the scene (laser window, plates)."""
    from planecal.io.params import load_params
    from planecal.io.samples import read_many
    from planecal.model.scene import load_scene, nominal_params

    scene = load_scene(scene_name)
    data = read_many(samples, scene)
    initial = load_params(initial_path) if initial_path else nominal_params(scene)
    if data.plate.max() >= initial.n_planes:
        raise InputError(f"samples refer to plate {data.plate.max() + 1} but the initial "
                         f"parameters hold {initial.n_planes} plane(s)")
    return data, scene, initial
