"""The calibration as a library call, at a chosen level (seed chapter 5; issue 13):

    level="offsets"  level 1: joint offsets, sensor, planes (today's ``fit.solve``, bit for bit)
    level="full"     level 2: the whole kinematic model (``model_full``): per joint
                     modified-DH alpha, a, beta (where axes are parallel), d; the base
                     frame; the sensor; the planes
    compliance=True  level 3's joint compliance of J2 and J3 (gravity torque from
                     robot.json's link masses), at either level

At level 2 the parameters the data can identify are chosen from the data: the Jacobian at
the initial parameters, column-scaled, through a pivoted QR (``identify.select_base``)
gives the base set; the fit frees it only and leaves the rest at their initial values,
each with its reason (``Calibration.excluded``).

    cal = calibrate(robot, qe, d_m, initial, plate, level="full")
    cal.params        # CellParams with the geometry corrections
    cal.result        # fit.Result (covariance over the base set, identifiability, ...)
    cal.excluded      # [identify.Excluded(parameter, reason, combination)]
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planecal.model.cell import CellParams, predict_with_jacobian
from planecal.estimation.fit import FitOptions, Problem, Result, free_mask, row_weights, solve
from planecal.estimation.identify import DEFAULT_TOL, BaseSet, Excluded, select_base
from planecal.model.kinematics import from_robot, parallel_pairs
from planecal.model.layout import ParamLayout, compliance_group, level1_layout, level2_layout
from planecal.model.robot import Robot
from planecal.io.samples import Samples

LEVELS = ("offsets", "full")


def layout_for(robot: Robot, n_planes: int, level: str = "offsets",
               compliance: bool = False) -> ParamLayout:
    """The parameter layout of a level: ``level1_layout`` for offsets (plus the compliance
    group with ``compliance``), ``level2_layout`` with the robot's parallel axes for full."""
    if level not in LEVELS:
        raise ValueError(f"unknown level {level!r} (offsets or full)")
    if level == "offsets":
        base = level1_layout(n_planes)
        return base if not compliance else ParamLayout(list(base.groups) + [compliance_group()])
    parallel = tuple(i + 1 for i in parallel_pairs(from_robot(robot)))
    return level2_layout(n_planes, parallel, compliance)


def scale_lengths(robot: Robot, k: int = 2) -> list[str]:
    """The ``k`` longest link lengths of the robot's model (``a{j}``/``d{j}`` names; the
    MC70: a3 = 0.9 m, d4 = 0.99 m). Together with the planes' distances they set the arm's
    scale, which 65-95 mm laser readings see only through the sensor's own gain: a gain
    error of 0.1 % (the ZS-LD80's linearity class) makes a free-scale fit put the tool up
    to 2 mm off over a 2 m reach (docs/STUDIES.md, "Level 2")."""
    kin = from_robot(robot)
    lengths = [(abs(v), f"a{j + 1}") for j, v in enumerate(kin.a)]
    lengths += [(abs(v), f"d{j + 1}") for j, v in enumerate(kin.d)]
    return [name for _, name in sorted(lengths, reverse=True)[:k]]


def geometry_prior(layout: ParamLayout, length_m: float, angle_rad: float) -> tuple:
    """``FitOptions.prior`` for the joint geometry (alpha, a, beta, d of every joint): a
    std of ``length_m`` for lengths and ``angle_rad`` for angles about the nominal values
    (machining and assembly tolerances), a maximum a posteriori fit."""
    if not (length_m > 0 and angle_rad > 0):
        raise ValueError("a geometry prior needs a length and an angle std > 0")
    return tuple((p.name, length_m if p.unit == "m" else angle_rad)
                 for g in layout.groups_of("joint_geometry") for p in g.params)


@dataclass(frozen=True, eq=False)
class Calibration:
    level: str
    compliance: bool
    result: Result
    base_set: BaseSet | None  # None where no selection ran (offsets without compliance)
    prior: tuple[float, float] | None = None  # the geometry prior (m, rad), if any

    @property
    def params(self) -> CellParams:
        return self.result.params

    @property
    def excluded(self) -> list[Excluded]:
        return [] if self.base_set is None else list(self.base_set.excluded)

    def to_dict(self) -> dict:
        """The result file's level-2 keys: ``level``, ``compliance``, ``base_set`` (names)
        and ``excluded`` (parameter, reason, combination)."""
        bs = self.base_set
        return {"level": self.level, "compliance": self.compliance,
                "base_set": None if bs is None else list(bs.base),
                "excluded": [] if bs is None else [
                    {"parameter": e.parameter, "reason": e.reason,
                     "combination": dict(e.combination)} for e in bs.excluded],
                "base_set_tolerance": None if bs is None else bs.tol,
                "geometry_prior_m_rad": None if self.prior is None else list(self.prior)}


def calibrate(robot: Robot, qe, d_m, initial: CellParams, plate=None, *,
              level: str = "offsets", compliance: bool = False, free=None,
              options: FitOptions | None = None, tol: float = DEFAULT_TOL,
              prior: tuple[float, float] | None = None,
              free_scale: bool = False) -> Calibration:
    """Calibrate at ``level`` (module docstring) from encoder counts ``qe`` (N, 6), measured
    distances ``d_m`` (N,) [m] and 0-based ``plate`` (N,) (default all 0), starting at
    ``initial``. ``free``: names (list, comma string, "all") or a mask over the level's
    layout, overriding its default free set; at level full the base set is selected among
    them. ``prior`` (level full): (length std [m], angle std [rad]) of the joint geometry
    about robot.json's (``geometry_prior``; a MAP fit: the base set's weakly determined
    geometry stays near the nominal instead of taking up model errors the parameters do
    not describe). At level full the arm's scale (``scale_lengths``: its two longest link
    lengths) stays at robot.json's unless ``free_scale`` or ``free`` names them: a plane
    and a laser do not measure it (each is listed in ``excluded`` with reason "scale").
    ValueError for a problem that cannot be solved (too few samples, ...)."""
    options = options or FitOptions()
    if prior is not None and level != "full":
        raise ValueError("a geometry prior needs level full")
    if level == "offsets" and not compliance:
        pb = Problem.from_arrays(robot, qe, d_m, initial, plate, free=free, options=options)
        return Calibration(level, False, solve(pb), None)
    layout = layout_for(robot, initial.n_planes, level, compliance)
    if prior is not None:
        options = replace(options, prior=geometry_prior(layout, *prior))
    mask = free_mask(layout, free)
    pinned = []
    if level == "full" and free is None and not free_scale:
        pinned = [n for n in scale_lengths(robot) if n in layout.names]
        mask = mask & ~layout.mask(pinned)
    n = len(np.asarray(d_m))
    pidx = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    _, J = predict_with_jacobian(robot, np.asarray(qe, np.int64), initial, pidx, layout)
    bs = select_base(J, layout, mask, tol, row_weights(J, layout, options))
    if pinned:
        bs = replace(bs, excluded=sorted(
            list(bs.excluded) + [Excluded(n, "scale") for n in pinned],
            key=lambda e: layout.index(e.parameter)))
    pb = Problem.from_arrays(robot, qe, d_m, initial, pidx, free=bs.mask(layout),
                             options=options, layout=layout)
    return Calibration(level, compliance, solve(pb), bs, prior)


def calibrate_samples(robot: Robot, samples: Samples, initial: CellParams, **kw) -> Calibration:
    """``calibrate`` on a sample file's ``Samples`` (mm -> m here)."""
    return calibrate(robot, samples.qe, samples.d_mm * 1e-3, initial, samples.plate, **kw)
