"""The calibration: one entry, every caller (the CLI's commands, the Python API, the demo
and every study) calibrates through ``calibrate``.

    settings = CalibrationSettings(level="full", compliance=True)
    cal = calibrate(robot, qe, d_m, initial, plate, settings)
    cal.params        # CellParams at the solution
    cal.result        # fit.Result (covariance over the base set, identifiability, history)
    cal.base_set      # identifiability.BaseSet: the identifiable parameters, and the
                      # candidates left at their initial values, each with its reason

What is free is a layout (``planecal.model.levels.layout_for``: the level and the
compliance) and a choice of names (``free``), never a branch here. The parameters the data
can identify are chosen from the data: the Jacobian at the initial parameters, column-scaled,
through a pivoted QR (``identifiability.select_base``); the fit frees the base set only.
The arm's scale (``levels.scale_lengths``) stays at robot.json's unless ``free_scale`` or
``free`` names it. A geometry prior (length std [m], angle std [rad]) pulls the joint
geometry towards robot.json's: a maximum a posteriori fit.

Results in robot terms (``encoder_offsets``): a joint offset is an encoder offset the
controller can take only where the calibration fixed it and a plane can see it; delta1
(the plates' turn about the base z axis) and delta6 (the sensor's roll) never are.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.fit import (SIGMA_START_M, FitOptions, FitPrior, Problem, Result,
                                     solve)
from planecal.estimation.identifiability import DEFAULT_TOL, BaseSet, Excluded, select_base
from planecal.estimation.noise import repeatability_sigma, row_weights
from planecal.estimation.selection import Selection, family_of, select
from planecal.model.cell_params import CellParams
from planecal.model.layout import ParamLayout
from planecal.model.layout import layout_prior
from planecal.model.levels import (DEFAULT_GEOMETRY_PRIOR, LEVELS, PLANE_BLIND_OFFSETS,
                                   layout_for, level_name, pinned_scale, whole_model,
                                   with_compliance)
from planecal.model.measurement import (Joints, has_backlash, joints_of_counts,
                                        predict_joints_with_jacobian)
from planecal.model.robot import Robot


@dataclass(frozen=True)
class CalibrationSettings:
    """How to calibrate: the ``level`` (``levels.LEVELS`` or the seed's number), J2/J3
    ``compliance``, the candidates ``free`` (names, a comma string, "all"; None: the
    layout's default), a ``geometry_prior`` (m, rad), ``free_scale``, the fit's
    ``options``, the base set's tolerance and whether the level's families are chosen by
    held-out prediction (``select``)."""
    level: str = "offsets"
    compliance: bool = False
    free: tuple | str | None = None
    geometry_prior: tuple[float, float] | None = None
    free_scale: bool = False
    options: FitOptions = field(default_factory=FitOptions)
    base_tolerance: float = DEFAULT_TOL
    # the level's families enter by held-out prediction (``estimation.selection``); off:
    # every family of the level (and with ``free`` given: the names given)
    select: bool = True

    def __post_init__(self):
        object.__setattr__(self, "level", level_name(self.level))
        object.__setattr__(self, "compliance", with_compliance(self.level, self.compliance))
        if self.geometry_prior is None:
            object.__setattr__(self, "geometry_prior", DEFAULT_GEOMETRY_PRIOR.get(self.level))
        if isinstance(self.free, list):
            object.__setattr__(self, "free", tuple(self.free))

    def check(self) -> None:
        """InputError naming the option for a combination that cannot be calibrated."""
        if self.geometry_prior is not None:
            if not whole_model(self.level):
                raise InputError("--geometry-prior needs --level full or nonkinematic")
            if not all(np.isfinite(v) and v > 0 for v in self.geometry_prior):
                raise InputError(f"--geometry-prior: both stds must be > 0, got "
                                 f"{self.geometry_prior}")
        if self.free_scale and not whole_model(self.level):
            raise InputError("--free-scale needs --level full or nonkinematic")

    @property
    def label(self) -> str:
        """'offsets', 'full + compliance', 'nonkinematic' (compliance is part of level 3):
        what the result says it is."""
        return self.level + (" + compliance" if self.compliance and
                             not with_compliance(self.level, False) else "")

    def to_dict(self) -> dict:
        return {"level": self.level, "compliance": self.compliance,
                "free": None if self.free is None else (
                    self.free if isinstance(self.free, str) else list(self.free)),
                "geometry_prior_m_rad": None if self.geometry_prior is None
                else list(self.geometry_prior),
                "free_scale": self.free_scale, "base_set_tolerance": self.base_tolerance,
                "select": self.select,
                "weighted": self.options.joint_sigma_rad is not None,
                # the weighted fit's noise model (what a drift check weighs a run with)
                "joint_sigma_rad": self.options.joint_sigma_rad,
                "distance_sigma_m": (self.options.distance_sigma_m
                                     if self.options.joint_sigma_rad is not None else None)}


def geometry_prior(layout: ParamLayout, length_m: float, angle_rad: float) -> tuple:
    """``FitOptions.prior`` for the joint geometry (alpha, a, beta, d of every joint): a
    std of ``length_m`` for lengths and ``angle_rad`` for angles about the initial values
    (machining and assembly tolerances)."""
    return tuple((p.name, length_m if p.unit == "m" else angle_rad)
                 for g in layout.groups_of("joint_geometry") for p in g.params)


def calibration_prior(layout: ParamLayout, settings: CalibrationSettings) -> tuple:
    """The parameter prior a calibration of ``layout`` with ``settings`` fits with
    ((name, std), ...): the layout's own (level 3's terms) and the geometry prior."""
    return layout_prior(layout) + (() if settings.geometry_prior is None
                                   else geometry_prior(layout, *settings.geometry_prior))


@dataclass(frozen=True, eq=False)
class Calibration:
    settings: CalibrationSettings
    result: Result
    base_set: BaseSet
    selection: Selection | None = None  # the families chosen by held-out prediction

    @property
    def params(self) -> CellParams:
        return self.result.params

    @property
    def level(self) -> str:
        return self.settings.level

    @property
    def compliance(self) -> bool:
        return self.settings.compliance

    @property
    def excluded(self) -> list[Excluded]:
        return list(self.base_set.excluded)

    @property
    def status(self) -> str:
        """What the result file says the fit is: "converged" only when it converged and
        identified every free parameter; "not_identifiable", "max_iterations" otherwise."""
        res = self.result
        if res.converged and res.identifiability.not_identifiable:
            return "not_identifiable"
        return res.status.value

    def failure(self) -> str | None:
        """Why the fit did not do its job (not converged, a free parameter not
        identifiable), or None."""
        res = self.result
        if not res.converged:
            return (f"the fit did not converge in {res.iterations} iterations (--max-iter); "
                    "its parameters are not a calibration")
        bad = res.identifiability.not_identifiable
        if bad:
            return (f"the samples cannot identify {', '.join(bad)}: fix them (--free) or "
                    "sample more varied poses")
        return None


def encoder_offsets(layout: ParamLayout, free: np.ndarray, params: CellParams,
                    initial: CellParams) -> tuple[np.ndarray, list[str], list[str]]:
    """The joint offsets a controller can take from a calibration (module docstring):
    (offsets (6,) [rad], the joints calibrated, the joints kept at their initial values).
    InputError when delta1 or delta6 was fitted: a combination of the plates' or the
    sensor's frame with the joint's zero, not an encoder offset."""
    names = layout.group("joint_offsets").names
    fitted = set(layout.names_of(free))
    blind = [n for n in PLANE_BLIND_OFFSETS if n in fitted]
    if blind:
        raise InputError(f"{', '.join(blind)} fitted freely: a plane calibration cannot tell "
                         "J1's zero from the plates' turn about the base z axis, nor J6's "
                         "from the sensor's roll; recalibrate with them fixed (the default)")
    out = np.where([n in fitted for n in names], params.joint_offsets, initial.joint_offsets)
    return (out, [n for n in names if n in fitted], [n for n in names if n not in fitted])


def candidates(robot: Robot, layout: ParamLayout, settings: CalibrationSettings,
               references: tuple = ()):
    """The parameters a calibration may fit (a mask over ``layout``) and the scale lengths
    it keeps (module docstring): the settings' ``free`` or the layout's default, without
    the arm's scale unless ``free`` names it, ``free_scale``, or a known length
    (``references``) fixes the scale."""
    mask = layout.free_mask(settings.free)
    pinned = ([] if (settings.free is not None or settings.free_scale or references)
              else pinned_scale(robot, layout))
    return mask & ~layout.mask(pinned), pinned


def base_set(robot: Robot, qe, initial: CellParams, plate, settings: CalibrationSettings,
             options: FitOptions | None = None, joints: Joints | None = None,
             direction=None, references: tuple = (),
             jacobian: np.ndarray | None = None,
             left_out: tuple = ()) -> tuple[ParamLayout, BaseSet]:
    """The layout of the settings' level and the base set of the parameters these poses
    (counts ``qe``, 0-based ``plate``, approach ``direction`` or None) and the scene's
    known lengths (``references``: their rows join the Jacobian) can identify, at
    ``initial`` (module docstring): what ``calibrate`` fits, and what ``planecal layouts``
    and ``plan`` predict. ``jacobian``: the distances' Jacobian at ``initial`` over the
    level's whole layout, where the caller has it. ``left_out``: parameters the selection
    left out (``estimation.selection``), excluded with reason "held_out"."""
    st = settings
    layout = layout_for(robot, initial.n_planes, st.level, st.compliance)
    options = options or st.options
    mask, pinned = candidates(robot, layout, st, references)
    held = [n for n in layout.names_of(mask) if n in set(left_out)]
    mask &= ~layout.mask(held)
    if jacobian is None:
        if joints is None:
            joints = joints_of_counts(robot, np.asarray(qe, np.int64), direction,
                                      has_backlash(layout) or bool(initial.backlash.any()))
        _, jacobian = predict_joints_with_jacobian(robot, joints, initial, plate, layout)
    J = jacobian
    w = row_weights(J[:, layout.slice("joint_offsets")], options.joint_sigma_rad,
                    options.distance_sigma_m)
    if references:
        prior = FitPrior.of(layout, initial.to_vector(layout), np.ones(len(layout), bool),
                            references, options.prior_sigma_m or SIGMA_START_M)
        P, _ = prior.rows(initial.to_vector(layout), len(layout))
        J = np.vstack([J, P])
        w = None if w is None else np.concatenate([w, np.ones(len(P))])
    bs = select_base(J, layout, mask, st.base_tolerance, w)
    if pinned or held:
        bs = replace(bs, free=sorted(list(bs.free) + held, key=layout.index), excluded=sorted(
            list(bs.excluded) + [Excluded(name, "scale") for name in pinned]
            + [Excluded(name, "held_out") for name in held],
            key=lambda e: layout.index(e.parameter)))
    return layout, bs


def calibrate(robot: Robot, qe, d_m, initial: CellParams, plate=None,
              settings: CalibrationSettings = CalibrationSettings(),
              direction=None, references: tuple = ()) -> Calibration:
    """Calibrate (module docstring) from encoder counts ``qe`` (N, 6), measured distances
    ``d_m`` (N,) [m], 0-based ``plate`` (N,) (default all 0) and each sample's recorded
    approach ``direction`` (N, 6) in -1, 0, +1 (None: not recorded; level 3's backlash)
    and the scene's known lengths (``references``), starting at ``initial``. InputError for
    a problem that cannot be solved (too few samples, unknown names, ...)."""
    st = settings
    st.check()
    options = st.options
    if options.joint_sigma_rad is None and options.noise_joint_sigma_rad is None:
        # "not identifiable in practice" judged at the robot's noise, not at the mismatch
        options = replace(options, noise_joint_sigma_rad=repeatability_sigma(robot))
    layout = layout_for(robot, initial.n_planes, st.level, st.compliance)
    prior = calibration_prior(layout, st)
    if prior:
        options = replace(options, prior=prior + tuple(options.prior))
    n = len(np.asarray(d_m))
    pidx = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    try:
        # the samples checked (shapes, plates) before the Jacobian; the free set after
        probe = Problem(robot, qe, d_m, pidx, initial, layout, np.zeros(len(layout), bool),
                        options, direction=direction, references=tuple(references))
        mask = candidates(robot, layout, st, references)[0]
        n_cand = int((mask & ~layout.mask(n for n, _ in options.prior)).sum())
        if n <= n_cand:
            raise ValueError(f"{n} samples cannot determine {n_cand} free parameters"
                             + (" without a prior" if options.prior else ""))
        # the distances and Jacobian at the initial values: the base set's, and the fit's
        # first evaluation
        at_initial = predict_joints_with_jacobian(robot, probe.joints, initial, pidx, layout)

        def fit(left_out=(), opts=options):
            _, bs = base_set(robot, probe.qe, initial, pidx, st, opts, probe.joints,
                             references=tuple(references), jacobian=at_initial[1],
                             left_out=left_out)
            return Calibration(st, solve(replace(probe, free=bs.mask(layout), options=opts,
                                                 at_initial=at_initial)), bs)
        cal = fit()
        if not (st.select and st.free is None and whole_model(st.level)):
            return cal
        sel = select(cal.result, st.label, st.geometry_prior is not None)
        gone = {f for f, _, _ in sel.left_out}
        k = sel.chosen.widen
        dropped = st.geometry_prior is not None and not sel.chosen.geometry_prior
        if gone or k != 1.0 or dropped:
            # the families left out; the geometry prior widened, or dropped where a simpler
            # level's model (which has none) predicted the held-out samples better
            geometry = {n for n, _ in geometry_prior(layout, 1.0, 1.0)}
            opts = replace(options, prior=tuple(
                (n, sd * k) if n in geometry else (n, sd) for n, sd in options.prior
                if not (dropped and n in geometry)))
            other = fit(tuple(n for n in layout.names if family_of(layout, n) in gone), opts)
            # held-out distances do not see the tool: the change stands only where the
            # reference model puts the tool no further off (``estimation.reference``)
            from planecal.estimation.reference import build
            ref = build(cal.result)
            before, after = ref.rms_mm(cal.params), ref.rms_mm(other.params)
            sel = replace(sel, at_tool=(before, after))
            if after < before:
                cal = other
            else:
                sel = sel.kept_as_asked()
        return replace(cal, selection=sel)
    except ValueError as e:
        raise InputError(str(e)) from None


def calibrate_samples(robot: Robot, samples, initial: CellParams,
                      settings: CalibrationSettings = CalibrationSettings(),
                      references: tuple = ()) -> Calibration:
    """``calibrate`` on a sample file's ``Samples`` (mm -> m here; their recorded approach
    directions, where the file has them) with the scene's known lengths."""
    return calibrate(robot, samples.qe, samples.d_mm * 1e-3, initial, samples.plate, settings,
                     samples.direction, references)


__all__ = ["LEVELS", "Calibration", "CalibrationSettings", "base_set", "calibrate", "candidates",
           "calibration_prior",
           "calibrate_samples", "encoder_offsets", "geometry_prior"]
