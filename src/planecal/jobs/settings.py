"""How to calibrate, from the values a user gives (the command line's, the API's): the
fit's options and the one ``estimation.calibrate.CalibrationSettings``, each value checked
with the option it came from named (``--free``, ``--geometry-prior``, ...)."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError


def parse_prior(value) -> tuple[float, float] | None:
    """--geometry-prior MM,MRAD (text, or a pair in m and rad) -> (m, rad)."""
    if value is None:
        return None
    if not isinstance(value, str):
        return tuple(float(v) for v in value)
    try:
        mm, mrad = (float(v) for v in value.split(","))
    except ValueError:
        raise InputError(f"--geometry-prior: expected MM,MRAD (two numbers), got "
                         f"{value!r}") from None
    if not (np.isfinite(mm) and np.isfinite(mrad) and mm > 0 and mrad > 0):
        raise InputError(f"--geometry-prior: both stds must be > 0, got {value!r}")
    return mm * 1e-3, mrad * 1e-3


def parse_free(value) -> tuple[str, ...] | None:
    """--free NAMES (a comma string, or names) -> the names, each once."""
    if value is None:
        return None
    names = ([s.strip() for s in value.split(",") if s.strip()] if isinstance(value, str)
             else [str(s) for s in value])
    if not names:
        raise InputError(f"--free: no parameter named in {value!r}")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"--free: {', '.join(dup)} named twice")
    return tuple(names)


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
    if rep is not None and not (np.isfinite(rep) and rep > 0):
        raise InputError(f"--repeatability-mm must be > 0, got {rep:g}")
    sd_um = 1.0 if distance_sigma_um is None else distance_sigma_um
    if not (np.isfinite(sd_um) and sd_um > 0):
        raise InputError(f"--distance-sigma-um must be > 0, got {sd_um:g}")
    r_m = robot.repeatability_m if rep is None else rep * 1e-3
    if not r_m > 0:
        raise InputError("--weighted: the robot description has no repeatability_mm; "
                         "give --repeatability-mm")
    return {"joint_sigma_rad": repeatability_sigma(robot, r_m), "distance_sigma_m": sd_um * 1e-6}


def fit_options(robot, *, max_iter: int = 30, improvement_limit: float = 1e-12,
                outlier_sigma: float | None = None, method: str = "gn", scale: bool = True,
                weighted: bool = False, repeatability_mm: float | None = None,
                distance_sigma_um: float | None = None):
    """The fit's ``FitOptions``, each value checked; with ``weighted`` the repeatability
    noise model of ``robot`` (or of ``repeatability_mm``)."""
    from planecal.estimation.fit import FitOptions

    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise InputError(f"--max-iter must be a positive integer, got {max_iter!r}")
    if not (np.isfinite(improvement_limit) and improvement_limit >= 0):
        raise InputError(f"--improvement-limit must be a number >= 0, got {improvement_limit}")
    if outlier_sigma is not None and not (np.isfinite(outlier_sigma) and outlier_sigma > 0):
        raise InputError(f"--outlier-sigma must be a number > 0, got {outlier_sigma}")
    return FitOptions(max_iter=int(max_iter), improvement_limit=improvement_limit,
                      outlier_sigma=outlier_sigma, method=method, scale=scale,
                      **weighting(weighted, robot, repeatability_mm, distance_sigma_um))


def calibration_settings(*, level="offsets", compliance: bool = False, free=None,
                         geometry_prior=None, free_scale: bool = False, weighted: bool = False,
                         robot=None, options=None, scene=None):
    """The ``CalibrationSettings`` of these values, checked (InputError naming the
    option). ``options``: the fit's (``fit_options``); otherwise the defaults, with
    ``weighted`` the repeatability noise model of ``robot`` (None: a study sets its
    world's noise per run). With ``scene``, ``free``'s names are checked against the
    level's parameters on its plates before any work."""
    from planecal.estimation.calibrate import CalibrationSettings
    from planecal.estimation.fit import FitOptions

    if options is None:
        options = FitOptions(**weighting(weighted, robot))
    st = CalibrationSettings(level=level, compliance=compliance, free=parse_free(free),
                             geometry_prior=parse_prior(geometry_prior),
                             free_scale=free_scale, options=options)
    st.check()
    if scene is not None and st.free is not None:
        from planecal.model.levels import layout_for
        layout_for(scene.robot, len(scene.plates), st.level, st.compliance).free_mask(st.free)
    return st
