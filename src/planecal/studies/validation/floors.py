"""Each level's floor: the best a model of that level can do at the tool point.

A calibration at a level is a choice of that level's parameters (``fit.Result.layout``, the
ones it freed); its AP is what that choice leaves. The floor of the level is what the best
choice leaves: the oracle that knows the twin's truth and what the level models, and
nothing else. Where the level's model holds the world's structure (level 3 in the
realistic world: geometry, compliance, gear harmonics at the reducer's periods, backlash)
that is the truth itself, expressed in the level's parameters; where it does not (offsets
only, or level 2, in a world with link geometry, gear error and backlash), the truth
restricted to the level's parameters is *not* the best the level can do: a calibration's
offsets absorb part of what they lack. So the floor is a fit:

* start: the twin's truth in the calibration's parameters (``twin.world.true_params``, the
  true flange frame folded into the sensor pose), restricted to the level's layout (what
  the layout does not hold at the calibration's initial values: robot.json's);
* targets: the twin's true tool point at each calibration sample's counts, approached from
  its recorded direction (``twin.oracle.TrueModel``: the twin's own map and MuJoCo, no
  code of the calibration's model), in the true robot frame (J1's axis and zero), without
  noise;
* fitted: the level's robot parameters the calibration freed (joint offsets, geometry,
  compliance, gear harmonics, backlash; not the base frame, which the robot frame
  registers away) and the tool point in the flange frame (the sensor's origin, its beam
  angles kept), by least squares over the samples' poses (scipy's ``least_squares``).

It is the best that model class does over the calibrated poses, in the rms sense: a
calibration of the level may come closer at five particular ISO poses by chance, never
over the region. It commands the ISO poses like every calibrated model
(``commanders.ModelCommander``); what it leaves when the twin drives there is what the
level does not model, repeatability and whole counts. The gap between a calibration and
its level's floor is what the calibration's data and method (the samples' noise, the
plane geometry, the prior) leave.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.encoder import counts_to_joints

ROBOT_KINDS = ("joint_offsets", "joint_geometry", "compliance", "gear", "backlash")
# the error sources of ``twin.world.SOURCES`` each kind of parameter models
MODELLED_BY = {"geometry": "joint_geometry", "compliance": "compliance", "gear": "gear",
               "backlash": "backlash", "laser_linearity": "laser"}


def modelled_sources(layout) -> list[str]:
    """The error families (``twin.world.SOURCES``) a layout has parameters for."""
    kinds = {g.kind for g in layout.groups}
    return [f for f, k in MODELLED_BY.items() if k in kinds]


@dataclass(frozen=True, eq=False)
class ModelClass:
    """What a floor needs of a calibration (a ``fit.Result`` is one): its ``layout``, the
    parameters it freed (``free``, a mask over it) and where it started (``initial``)."""
    layout: object
    free: np.ndarray
    initial: object

    @classmethod
    def of_document(cls, robot, doc: dict, n_planes: int) -> "ModelClass | None":
        """The model class of a result file's document (its level, compliance, free
        names and initial values); None for a file that does not say them."""
        from planecal.io.params import params_from_dict
        from planecal.model.levels import LEVELS, layout_for
        if doc.get("level") not in LEVELS or not isinstance(doc.get("free"), list) \
                or not isinstance(doc.get("initial"), dict):
            return None
        layout = layout_for(robot, n_planes, doc["level"], bool(doc.get("compliance")))
        names = [n for n in doc["free"] if n in layout.names]
        return cls(layout, layout.mask(names), params_from_dict(doc["initial"]))


@dataclass(frozen=True, eq=False)
class Floor:
    """A level's floor: the fitted ``model`` (``compensate.CalibratedModel``), how far its
    tool point lies from the true one at the samples' poses before (the truth restricted
    to the level) and after the fit (rms and max, mm), and what it freed."""
    model: object
    restricted_rms_mm: float
    rms_mm: float
    max_mm: float
    free: tuple

    def to_dict(self) -> dict:
        return {"level": self.model.level, "restricted_truth_rms_mm": self.restricted_rms_mm,
                "fit_rms_mm": self.rms_mm, "fit_max_mm": self.max_mm,
                "free": list(self.free)}


def level_floor(scene, truth, result, true_model, frame: np.ndarray, sample_counts,
                direction=None, name: str = "floor") -> Floor:
    """The floor of ``result``'s level (module docstring; ``result``: a ``fit.Result`` or
    a ``ModelClass``). ``truth``: the world's truth in
    the calibration's parameters (``twin.world.true_params(..., fold_flange=True)``);
    ``true_model``: the world twin's ``TrueModel``; ``frame``: the true robot frame in the
    cell frame (``iso9283.robot_frame``); ``sample_counts`` (N, 6) and ``direction`` (N, 6)
    or None: the calibration's samples and their approach directions; ``name``: the
    floor model's label."""
    from scipy.optimize import least_squares

    from planecal.estimation.compensate import CalibratedModel
    from planecal.model.measurement import beam_direction

    robot = scene.robot
    layout = result.layout
    counts = np.atleast_2d(np.asarray(sample_counts, np.int64))
    # no recorded direction: every joint's side unknown (0), but where gravity holds it
    d = (np.zeros((len(counts), 6), np.int64) if direction is None
         else np.atleast_2d(np.asarray(direction)))
    q = counts_to_joints(robot, counts)
    Finv = np.linalg.inv(frame)
    target = true_model.tool_points(counts, d) @ Finv[:3, :3].T + Finv[:3, 3]
    start = result.initial.with_vector(truth.to_vector(layout), layout)
    free = np.zeros(len(layout), bool)
    for g in layout.groups:
        if g.kind in ROBOT_KINDS:
            free[layout.slice(g.name)] = result.free[layout.slice(g.name)]
    x0 = start.to_vector(layout)
    cols = np.flatnonzero(free)
    beam = scene.standoff_m * beam_direction(start.phi_y, start.phi_z)

    def model_of(v):
        x = x0.copy()
        x[cols] = v[:len(cols)]
        p = start.with_vector(x, layout)
        p.sensor_origin = v[len(cols):] - beam  # the tool point in the flange frame
        return CalibratedModel(robot, p, name)

    def residuals(v):
        m = model_of(v)
        T = np.linalg.inv(m.robot_frame()) @ m.flange(q, m.sides(q, d))
        tool = T[:, :3, :3] @ (m.params.sensor_origin + beam) + T[:, :3, 3]
        return (tool - target).ravel()

    v0 = np.concatenate([x0[cols], start.sensor_origin + beam])
    r0 = residuals(v0).reshape(-1, 3)
    sol = least_squares(residuals, v0, x_scale="jac", method="trf", xtol=1e-12, ftol=1e-12,
                        gtol=1e-12, max_nfev=50 * (len(v0) + 1))
    r = sol.fun.reshape(-1, 3)
    e0, e = np.linalg.norm(r0, axis=1), np.linalg.norm(r, axis=1)
    best = sol.x if np.sqrt(np.mean(e ** 2)) <= np.sqrt(np.mean(e0 ** 2)) else v0
    if best is v0:
        e = e0
    return Floor(model_of(best), float(np.sqrt(np.mean(e0 ** 2)) * 1e3),
                 float(np.sqrt(np.mean(e ** 2)) * 1e3), float(e.max() * 1e3),
                 tuple(layout.names_of(free)) + ("tool point",))


__all__ = ["Floor", "MODELLED_BY", "ModelClass", "ROBOT_KINDS", "level_floor", "modelled_sources"]
