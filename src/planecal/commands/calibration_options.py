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


def fit_options(args, robot):
    """FitOptions from ``add_fit_arguments``' flags (``jobs.settings.fit_options``)."""
    from planecal.jobs.settings import fit_options as options
    return options(robot, max_iter=args.max_iter, improvement_limit=args.improvement_limit,
                   outlier_sigma=args.outlier_sigma, method=args.method,
                   scale=not args.no_scale, weighted=args.weighted,
                   repeatability_mm=args.repeatability_mm,
                   distance_sigma_um=args.distance_sigma_um)


def calibration_settings(args, robot=None, options=None, scene=None):
    """The ``CalibrationSettings`` of the flags (``jobs.settings.calibration_settings``).
    ``options``: the fit's (``fit_options`` on a command that has them); otherwise the
    defaults, with --weighted the repeatability noise model of ``robot`` (None: a study
    sets its world's noise per run). With ``scene``, --free's names are checked against
    the level's parameters on its plates before any work."""
    from planecal.jobs.settings import calibration_settings as settings
    return settings(level=args.level, compliance=args.compliance, free=args.free,
                    geometry_prior=args.geometry_prior, free_scale=args.free_scale,
                    weighted=args.weighted, robot=robot, options=options, scene=scene)
