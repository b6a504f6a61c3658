"""planecal calibrate SAMPLES... [--initial P.json] [--out R.json] [--max-iter N]
[--improvement-limit X] [--outlier-sigma K] [--method gn|lm] [--free NAMES]
[--level offsets|full] [--compliance] [--geometry-prior MM,MRAD]
[--weighted [--repeatability-mm R] [--distance-sigma-um S]] [--rrd FILE]

--level offsets (default) is the seed's level 1 (joint offsets, sensor, planes), as it
always was. --level full calibrates the whole kinematic model (planecal.estimation.calibrate):
the parameters the samples can identify are chosen from their Jacobian (a pivoted QR,
planecal.estimation.identify), the others stay at their initial values and the report and the
result file name each with its reason. --compliance adds the joint compliance of J2 and
J3 (gravity torque from robot.json's link masses). --free overrides the candidates.

Several sample files may be given; a file's samples are on the plate named in its 8th
column, or on plate 1. Without --initial the default scene's nominal values (the thesis
cell's measured initial values) are the starting point. Readings outside the scene's laser
window are refused. --out is checked before the fit (not an input, a writable place, not
a file other than an earlier result unless --force) and records the inputs with their
SHA-256 (provenance).

Exit 0 when the fit converged and identified every free parameter; 1 when it did not (the
report and --out are still written, with the reason in one line); 2 on bad input.
"""
from __future__ import annotations

from dataclasses import asdict

import numpy as np

from planecal.estimation.calibrate import LEVELS, Calibration, calibrate_samples
from planecal.commands.report import add_report_argument, write_command_report
from planecal.base.errors import InputError, RunFailed
from planecal.estimation.fit import FitOptions, Problem, Result, solve
from planecal.formats.params import RESULT_FORMAT, provenance, result_document
from planecal.io.outputs import check_output
from planecal.io.params import kinematics_to_dict, load_params, params_to_dict, save_json
from planecal.io.samples import read_many
from planecal.model.scene import DEFAULT_SCENE, load_scene, nominal_params


def add_arguments(p):
    p.add_argument("samples", nargs="+", help="sample file(s), seed format (7.1.4)")
    p.add_argument("--initial", help="initial parameter file (JSON); default: the scene's nominal values")
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene for the nominal values and robot (default %(default)s)")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier result file")
    p.add_argument("--max-iter", type=int, default=30,
                   help="at most this many corrections (default %(default)s)")
    p.add_argument("--improvement-limit", type=float, default=1e-12,
                   help="stop when the mean absolute correction falls below this (default %(default)g)")
    p.add_argument("--outlier-sigma", type=float, default=None,
                   help="drop samples whose error is more than K standard deviations from the mean "
                        "(the seed used 4); off by default")
    p.add_argument("--method", choices=["gn", "lm"], default="gn",
                   help="gn: Gauss-Newton with SVD pseudo-inverse (seed); lm: Levenberg-Marquardt")
    p.add_argument("--no-scale", action="store_true", help="no column scaling of the Jacobian")
    p.add_argument("--free", help="comma-separated parameter names to fit (default: all but "
                   "delta1, delta6 at level offsets; at level full, the candidates of the "
                   "identifiable base set)")
    p.add_argument("--level", choices=LEVELS, default="offsets",
                   help="offsets: joint offsets, sensor, planes (seed level 1, default); full: "
                        "the whole kinematic model, its identifiable base set chosen from "
                        "the samples")
    p.add_argument("--geometry-prior", metavar="MM,MRAD", default=None,
                   help="with --level full: pull the joint geometry towards robot.json's with "
                        "these stds (a maximum a posteriori fit; e.g. 0.5,0.5): keeps the "
                        "weakly determined lengths from taking up unmodelled errors "
                        "(docs/STUDIES.md, Level 2)")
    p.add_argument("--free-scale", action="store_true",
                   help="with --level full: also free the arm's scale (its two longest link "
                        "lengths), which a laser on planes reads only through its own gain; "
                        "only with a length reference in the data")
    p.add_argument("--compliance", action="store_true",
                   help="also fit the joint compliance of J2 and J3 (gravity torque from "
                        "robot.json's link masses; seed 5.4)")
    p.add_argument("--weighted", action="store_true",
                   help="weighted least squares with the robot's repeatability as the noise "
                        "model (each sample's variance from its pose): honest std on several "
                        "plates; see planecal.estimation.fit")
    p.add_argument("--repeatability-mm", type=float, default=None,
                   help="with --weighted: the robot's repeatability, +- mm at the flange "
                        "(default: robot.json's)")
    p.add_argument("--distance-sigma-um", type=float, default=None,
                   help="with --weighted: std of a sample's distance from the sensor itself "
                        "(default 1 um)")
    add_report_argument(p)
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="write a Rerun recording of the fit (a file name, a directory, or "
                        "'auto' for recordings/calibrate-<scene>-<time>.rrd)")


def result_dict(res: Result, cal: Calibration | None = None) -> dict:
    """The result file: the parameter file's keys, ``std`` in the same shape (null where
    fixed or not identifiable), the fit's figures, ``identifiability``, ``free`` and
    ``covariance`` (the free parameters' names and matrix, null where not identifiable),
    ``level``, ``compliance``, ``base_set`` and ``excluded`` (level 2's selection: each
    parameter left out with its reason; null and [] at level offsets)."""
    out = params_to_dict(res.params)
    layout, std = res.layout, res.std

    def s(name):
        v = std[layout.index(name)]
        return None if not np.isfinite(v) else float(v)

    def ss(group):
        return [s(n) for n in group.names]
    out["std"] = {
        "joint_offsets_rad": ss(layout.group("joint_offsets")),
        "planes": [{"n_tilde": ss(g)} for g in layout.groups_of("plane")],
        "sensor": {"origin_m": ss(layout.group("sensor_origin")), "phi_y_rad": s("phi_y"),
                   "phi_z_rad": s("phi_z")},
    }
    if layout.groups_of("joint_geometry") or layout.groups_of("compliance"):
        g = np.full((6, 4), np.nan)
        for grp in layout.groups_of("joint_geometry"):
            g[grp.index] = std[layout.slice(grp.name)]
        base = std[layout.slice("base")] if layout.groups_of("base_frame") else np.full(6, np.nan)
        comp = (std[layout.slice("compliance")] if layout.groups_of("compliance")
                else np.full(6, np.nan))
        out["std"]["kinematics"] = kinematics_to_dict(g, base, comp)
        if "kinematics" not in out:  # every correction zero: still a level-2 result
            out["kinematics"] = kinematics_to_dict(res.params.geometry, res.params.base,
                                                   res.params.compliance)
    out["residual_rms_mm"] = res.rms_mm()
    out["residual_rms_initial_mm"] = res.rms_mm(initial=True)
    out["residual_max_mm"] = float(np.max(np.abs(res.residuals_m[res.used])) * 1e3)
    out["iterations"] = res.iterations
    out["converged"] = res.converged
    out["outliers"] = [int(i) for i in res.outliers]
    out["samples_used"] = int(res.used.sum())
    out["identifiability"] = res.identifiability.to_dict()
    out["free"] = layout.names_of(res.free)
    out["covariance"] = res.covariance.to_dict()
    out["history"] = [asdict(it) for it in res.history]
    out["initial"] = params_to_dict(res.initial)
    out.update(cal.to_dict() if cal is not None else
               {"level": "offsets", "compliance": False, "base_set": None, "excluded": [],
                "base_set_tolerance": None, "geometry_prior_m_rad": None})
    return out


def format_report(res: Result, n_zero: int = 0, cal: Calibration | None = None) -> str:
    lines = []
    layout = res.layout
    excluded = {e.parameter: e for e in (cal.excluded if cal is not None else [])}
    x0, x = res.initial.to_vector(layout), res.params.to_vector(layout)
    std = res.std
    ident = res.identifiability
    lines.append(f"{'parameter':<10} {'value':>14} {'std':>11} {'correction':>13}  unit")
    for i, (name, unit) in enumerate(zip(layout.names, layout.units)):
        if name in excluded:
            sd = "excluded"
        elif not res.free[i]:
            sd = "fixed"
        elif name in ident.not_identifiable:
            sd = "NOT IDENT."
        else:
            sd = f"{std[i]:.3e}"
        lines.append(f"{name:<10} {x[i]:>14.7g} {sd:>11} {x[i] - x0[i]:>13.4e}  {unit}")
    lines.append("")
    lines.append(f"samples used {int(res.used.sum())} of {len(res.used)}"
                 + (f", {n_zero} laser zeros skipped" if n_zero else ""))
    lines.append(f"residual RMS  before {res.rms_mm(True):.4f} mm   after {res.rms_mm():.4f} mm"
                 f"   max after {np.max(np.abs(res.residuals_m[res.used])) * 1e3:.4f} mm")
    lines.append(f"iterations {res.iterations}" + ("" if res.converged else " (not converged)"))
    lines.append("outliers " + (", ".join(str(i) for i in res.outliers) if res.outliers else "none"))
    if ident.weighted:
        lines.append(f"weighted by the repeatability noise model: variance factor "
                     f"{ident.variance_factor:.3g} (1: the model's noise level fits the "
                     f"residuals; the std include it)")
    lines.append(f"sigma {ident.sigma_mm:.4g} mm   scaled condition number "
                 f"{ident.condition_number_scaled:.4g}   O1 {ident.observability.O1:.3g}"
                 f"  O2 {ident.observability.O2:.3g}")
    if cal is not None and cal.base_set is not None:
        bs = cal.base_set
        lines.append(f"level {cal.level}{' + compliance' if cal.compliance else ''}: "
                     f"{len(bs.base)} of {len(bs.free)} candidate parameters identifiable "
                     f"from these samples (pivoted QR, |R_kk|/|R_00| >= {bs.tol:g})")
        for e in bs.excluded:
            lines.append(f"EXCLUDED {e.describe()}")
    for name in ident.no_effect:
        lines.append(f"WARNING no effect: {name} does not change any distance in this data")
    for pd in ident.poorly_determined:
        lines.append(f"WARNING not identifiable in practice: {pd.parameter} (std "
                     f"{pd.std:.3g} above {pd.limit:g}): the data barely depends on it")
    for d in ident.unidentifiable_directions:
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in d.items())
        lines.append(f"WARNING not identifiable: {', '.join(d)} move together without changing "
                     f"any distance (direction {mix})")
    for w in ident.weak_directions:
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in w.direction.items())
        lines.append(f"WARNING weakly identifiable (scaled singular value ratio "
                     f"{w.scaled_singular_ratio:.2e}): {mix}")
    for pr in ident.correlated_pairs:
        lines.append(f"WARNING strongly correlated: {pr.a} ~ {pr.b} (rho {pr.rho:+.4f})")
    for n in res.notes:
        lines.append(f"NOTE {n}")
    return "\n".join(lines)


def load_inputs(args):
    """(samples, scene, initial parameters) from SAMPLES..., --scene and --initial; the
    samples checked against the scene (laser window, plates)."""
    scene = load_scene(args.scene)
    samples = read_many(args.samples, scene)
    initial = load_params(args.initial) if args.initial else nominal_params(scene)
    if samples.plate.max() >= initial.n_planes:
        raise InputError(f"samples refer to plate {samples.plate.max() + 1} but the initial "
                         f"parameters hold {initial.n_planes} plane(s)")
    return samples, scene, initial


def weighting(args, robot) -> dict:
    """FitOptions fields of --weighted (empty without it)."""
    if not args.weighted:
        for flag, v in (("--repeatability-mm", args.repeatability_mm),
                        ("--distance-sigma-um", args.distance_sigma_um)):
            if v is not None:
                raise InputError(f"{flag} needs --weighted")
        return {}
    from planecal.model.robot import repeatability_sigma
    rep = args.repeatability_mm
    if rep is not None and not (np.isfinite(rep) and rep > 0):
        raise InputError(f"--repeatability-mm must be > 0, got {rep:g}")
    sd_um = 1.0 if args.distance_sigma_um is None else args.distance_sigma_um
    if not (np.isfinite(sd_um) and sd_um > 0):
        raise InputError(f"--distance-sigma-um must be > 0, got {sd_um:g}")
    r_m = robot.repeatability_m if rep is None else rep * 1e-3
    if not r_m > 0:
        raise InputError("--weighted: the robot description has no repeatability_mm; "
                         "give --repeatability-mm")
    return {"joint_sigma_rad": repeatability_sigma(robot, r_m),
            "distance_sigma_m": sd_um * 1e-6}


def build_problem(samples, scene, initial, free, options: FitOptions) -> Problem:
    """The fit's problem from the command's inputs; a problem that cannot be solved (too
    few samples for the free parameters, ...) is bad input."""
    try:
        return Problem.from_samples(scene.robot, samples, initial, free=free, options=options)
    except ValueError as e:
        raise InputError(str(e)) from None


def fit_options(args, robot) -> FitOptions:
    """FitOptions from the flags, each checked."""
    if args.max_iter < 1:
        raise InputError(f"--max-iter must be at least 1, got {args.max_iter}")
    if not (np.isfinite(args.improvement_limit) and args.improvement_limit >= 0):
        raise InputError(f"--improvement-limit must be a number >= 0, got {args.improvement_limit}")
    if args.outlier_sigma is not None and not (np.isfinite(args.outlier_sigma)
                                               and args.outlier_sigma > 0):
        raise InputError(f"--outlier-sigma must be a number > 0, got {args.outlier_sigma}")
    return FitOptions(max_iter=args.max_iter, improvement_limit=args.improvement_limit,
                      outlier_sigma=args.outlier_sigma, method=args.method,
                      scale=not args.no_scale, **weighting(args, robot))


def failure(res: Result) -> str | None:
    """Why a fit did not do its job (not converged, a free parameter not identifiable),
    or None."""
    if not res.converged:
        return (f"the fit did not converge in {res.iterations} iterations (--max-iter); its "
                f"parameters are not a calibration")
    bad = res.identifiability.not_identifiable
    if bad:
        return (f"the samples cannot identify {', '.join(bad)}: fix them (--free) or sample "
                "more varied poses")
    return None


def geometry_prior_arg(args):
    """--geometry-prior MM,MRAD -> (m, rad), checked; None without it."""
    if args.geometry_prior is None:
        return None
    if args.level != "full":
        raise InputError("--geometry-prior needs --level full")
    try:
        mm, mrad = (float(v) for v in args.geometry_prior.split(","))
    except ValueError:
        raise InputError(f"--geometry-prior: expected MM,MRAD (two numbers), got "
                         f"{args.geometry_prior!r}") from None
    if not (np.isfinite(mm) and np.isfinite(mrad) and mm > 0 and mrad > 0):
        raise InputError(f"--geometry-prior: both stds must be > 0, got {args.geometry_prior!r}")
    return mm * 1e-3, mrad * 1e-3


def run(args) -> int:
    inputs = [("samples", p) for p in args.samples] + (
        [("initial", args.initial)] if args.initial else [])
    out = None if not args.out else check_output(args.out, [p for _, p in inputs],
                                                 RESULT_FORMAT, args.force)
    samples, scene, initial = load_inputs(args)
    options = fit_options(args, scene.robot)
    cal = None
    prior = geometry_prior_arg(args)
    if args.free_scale and args.level != "full":
        raise InputError("--free-scale needs --level full")
    if args.level == "offsets" and not args.compliance:  # level 1, as it always was
        res = solve(build_problem(samples, scene, initial, args.free, options))
    else:
        try:
            cal = calibrate_samples(scene.robot, samples, initial, level=args.level,
                                    compliance=args.compliance, free=args.free,
                                    options=options, prior=prior,
                                    free_scale=args.free_scale)
        except ValueError as e:
            raise InputError(str(e)) from None
        res = cal.result
    print(format_report(res, samples.n_zero, cal))
    doc = result_document(result_dict(res, cal), provenance(
        inputs + [("scene", scene.path), ("robot", scene.robot.source)], scene.name,
        scene.robot.name))
    if out:
        save_json(out, doc)
        print(f"result written to {out}")
    write_command_report(args, out or doc, samples=args.samples, scene=str(scene.path))
    if args.rrd:
        from planecal.present.rerun import log_fit_to_file
        path = log_fit_to_file(args.rrd, res, samples, scene)
        print(f"recording written to {path}")
    why = failure(res)
    if why:
        raise RunFailed(why)
    return 0
