"""One validation: ISO 9283 at the tool point and the flange, in the near-sample cube and
the standard's, and the gauge block; the nominal model, each calibrated model, each level's
floor and the twin's own whole true model, on one world."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.studies.validation.cube import (NEAR_RULE, STANDARD_RULE, SamplePoses,
                                              cube_record, place_near, place_standard)
from planecal.studies.validation.gauge import gauge_block, predicted_spread
from planecal.studies.validation.iso9283 import Mover, iso9283, robot_frame
from planecal.studies.validation.settings import WHERE, ValidationSettings

CUBE_RULE = NEAR_RULE  # the near-sample cube's rule (the name before issue 31)
FLOOR = "floor: {}"  # a level's floor's name among the models


def figures(iso: dict, name: str, role: str, cube: str = "") -> dict:
    """Model ``name``'s figures under ``role``'s keys in ``cube`` (``settings.figure_keys``):
    AP (robot and cell frame) and RP, worst of P1..P5, at the tool point and at the flange;
    None where the model did not command (``iso`` None or without it)."""
    m = None if iso is None else iso["models"].get(name)
    out = {}
    for w in WHERE:
        for key, what in ((f"ap_{role}_{w}{cube}_mm", "ap_mm"),
                          (f"ap_{role}_{w}{cube}_cell_mm", "ap_cell_mm"),
                          (f"rp_{role}_{w}{cube}_mm", "rp_mm")):
            out[key] = None if m is None else float(m[w][what].max())
    return out


def named_tcps(scene, st: ValidationSettings) -> dict:
    """The TCPs besides the tool point: the scene's (``tools``) and ``--tcp-mm``'s ("tcp")."""
    out = {t.name: np.asarray(t.tcp, float) for t in scene.tools}
    if st.tcp_m is not None:
        if "tcp" in out:
            raise InputError("--tcp-mm: the scene already names a TCP 'tcp'")
        out["tcp"] = np.asarray(st.tcp_m, float)
    return out


def validate(scene, world, calibrated, sample_counts: np.ndarray,
             st: ValidationSettings | None = None, checker=None, fit=None,
             options=None, sample_direction=None) -> dict:
    """ISO 9283 AP/RP and the gauge block on a twin of ``world`` (a ``twin.truth.Truth``;
    a ``CellParams`` is robot.json's geometry) with ``options`` (``TwinOptions``; None:
    ``TwinOptions()``, the ideal world's). ``calibrated``: a ``compensate.CalibratedModel``
    or several (lower levels first; the last is the one validated, "after"), each
    commanding the same poses beside the nominal model, each level's floor and the twin's
    own whole true model (the oracle). ``sample_counts``: the calibration samples (they
    place the cubes, bound the calibrated region and are where a floor is fitted;
    ``sample_direction`` their approach directions); ``fit``: the calibrations' ``fit.Result``
    (one per model, or the validated one's alone): its layout gives the level's floor, the
    validated one's covariance the predicted spread (None: neither)."""
    from planecal.estimation.compensate import CalibratedModel, Region
    from planecal.twin import Twin, TwinOptions
    from planecal.twin.oracle import TrueModel
    from planecal.twin.truth import Truth

    options = TwinOptions() if options is None else options
    st = st or ValidationSettings()
    st.check()
    world = world if isinstance(world, Truth) else Truth(world)
    models = [calibrated] if isinstance(calibrated, CalibratedModel) else list(calibrated)
    robot = scene.robot
    twin = Twin(scene, truth=world, seed=st.seed, options=options)
    mover = Mover(twin, robot, checker, _detour(scene, checker))
    start = mover.drv.commanded_counts
    frame = robot_frame(robot, world)
    standoff = scene.standoff_m
    true_model = TrueModel(twin, standoff)
    floors = _floors(scene, world, options, models, fit, true_model, frame, sample_counts,
                     sample_direction)
    commanders = _commanders(scene, models, floors, true_model, frame)
    samples = SamplePoses.of(scene, sample_counts)
    region = Region.from_counts(robot, sample_counts, "the calibration samples")
    plan, centre = place_near(scene, commanders, samples, st, mover, region, checker)
    tcps = named_tcps(scene, st)
    iso = iso9283(twin, plan, st, mover, standoff, tcps, frame)
    after = models[-1]
    out = {**_roles(iso, after.level, floors), "model_after": after.level,
           "standoff_mm": standoff * 1e3,
           "tcps": _tcp_rows(iso, tcps, after.level),
           "cube": cube_record(plan, samples, region,
                               "given (--cube-mm)" if st.cube_edge_m is not None
                               else NEAR_RULE, centre),
           "floors": {m: f.to_dict() for m, f in floors.items()},
           "cell_frame": _cell_frame(frame, world, plan),
           "oracle": {"tool_in_flange_m": true_model.tool_in_flange,
                      "rounding_mm": _rounding_mm(true_model, plan, frame)},
           "iso": iso, "iso_standard": None, "standard_cube": None, "gauge": None,
           "gauge_failed": None, "predicted_from_fit": None,
           "gauge_error_before_mm": None, "gauge_error_after_mm": None,
           "gauge_error_offsets_only_mm": None,
           "residual_offset_error": _offset_error(after, world, iso, tcps),
           "settings": {k: getattr(st, k) for k in st.__dataclass_fields__}}
    b, a = out["ap_before_tool_mm"], out["ap_after_tool_mm"]
    out["ap_tool_ratio"] = b / a if a > 0 else float("inf")
    home = (samples.counts[centre], "back to the cube's centre sample")
    if st.standard_cube:
        home = _standard(out, scene, commanders, samples, st, mover, region, checker, twin,
                         tcps, frame, floors, home, start)
    if st.gauge:  # from where the robot started, the way it came (its paths are known)
        try:
            _go_back(mover, home, start)
            _gauge(out, twin, scene, world, after, st, checker, mover, options,
                   _validated_fit(fit), plan)
        except InputError as e:  # the ISO figures stand; the block's failure beside them
            out["gauge_failed"] = str(e)
    out["levels"] = [{"level": m.level, **_level_figures(out, m.level, floors)}
                     for m in models]
    return out


def _commanders(scene, models, floors, true_model, frame) -> list:
    """Who commands the ISO poses, in order: the nominal model, each calibrated one, each
    level's floor, the twin's whole true model (``commanders``)."""
    from planecal.estimation.compensate import CalibratedModel
    from planecal.model.scene import nominal_params
    from planecal.studies.validation.commanders import ModelCommander, OracleCommander
    names = (["nominal"] + [m.level for m in models] + [f.model.level for f in floors.values()]
             + ["oracle"])
    if len(set(names)) != len(names):
        raise ValueError(f"validate: models of one name: {names}")
    robot, standoff = scene.robot, scene.standoff_m
    out = [ModelCommander("nominal", CalibratedModel(robot, nominal_params(scene), "nominal"),
                          standoff)]
    out += [ModelCommander(m.level, m, standoff)
            for m in models + [f.model for f in floors.values()]]
    return out + [OracleCommander(true_model, frame, robot)]


def _validated_fit(fit):
    """The validated calibration's ``fit.Result`` of ``validate``'s ``fit`` (None where
    it is only a ``floors.ModelClass``: no covariance to predict from)."""
    from planecal.estimation.fit import Result
    f = fit[-1] if isinstance(fit, (list, tuple)) else fit
    return f if isinstance(f, Result) else None


def _floors(scene, world, options, models, fit, true_model, frame, counts, direction) -> dict:
    """Each model's level's floor (``floors.level_floor``) by the model's name, where its
    ``fit.Result`` is known: ``fit`` one per model, or the last model's alone."""
    from planecal.studies.validation.floors import level_floor
    from planecal.twin.world import true_params
    if fit is None:
        return {}
    fits = list(fit) if isinstance(fit, (list, tuple)) else [None] * (len(models) - 1) + [fit]
    if len(fits) != len(models):
        raise ValueError(f"validate: {len(fits)} fits for {len(models)} models")
    truth = true_params(scene.robot, world, options, fold_flange=True)
    return {m.level: level_floor(scene, truth, f, true_model, frame, counts, direction,
                                 FLOOR.format(m.level))
            for m, f in zip(models, fits) if f is not None}


def _roles(iso: dict, after: str, floors: dict, cube: str = "") -> dict:
    """The figures of the nominal model ("before"), the validated one ("after"), its
    level's floor ("floor") and the oracle in one cube's ``iso``."""
    floor = floors[after].model.level if after in floors else None
    return {**figures(iso, "nominal", "before", cube), **figures(iso, after, "after", cube),
            **figures(iso, floor, "floor", cube), **figures(iso, "oracle", "oracle", cube)}


def _level_figures(out: dict, level: str, floors: dict) -> dict:
    """One level's figures beside the validated one: its AP/RP and its floor's, in both
    cubes."""
    floor = floors[level].model.level if level in floors else None
    row = {}
    for cube, iso in (("", out["iso"]), ("_standard", out["iso_standard"])):
        row.update(figures(iso, level, "after", cube))
        row.update(figures(iso, floor, "floor", cube))
    return row


def _standard(out, scene, commanders, samples, st, mover, region, checker, twin, tcps,
              frame, floors, home, start):
    """The standard's cube (``cube.STANDARD_RULE``) into ``out``, planned from the start
    (the robot goes back there first); its failure, where none fits, beside the near
    cube's figures. Returns where the robot goes back from after it."""
    try:
        _go_back(mover, home, start)
        plan, k, top = place_standard(scene, commanders, samples, mover, region, checker)
    except InputError as e:
        out["standard_cube"] = {"rule": STANDARD_RULE, "failed": str(e)}
        out.update(_roles(None, out["model_after"], floors, "_standard"))
        return home
    iso = iso9283(twin, plan, st, mover, scene.standoff_m, tcps, frame)
    out["iso_standard"] = iso
    out["standard_cube"] = {**cube_record(plan, samples, region, STANDARD_RULE, k),
                            "largest_edge_m": top, "cell_frame": _cell_frame(frame, None, plan)}
    out.update(_roles(iso, out["model_after"], floors, "_standard"))
    return samples.counts[k], "back to the standard cube's orientation sample"


def _go_back(mover, home, start) -> None:
    """Back to the start the way the robot came (by ``home``: (counts, what), the sample a
    cube was planned around), else by the straight path or the detour from where it is."""
    try:
        mover.go(*home)
    except InputError:
        pass
    mover.go(start, "back to the start")


def _detour(scene, checker):
    """The sampling run's detour around a blocked path (None without a checker)."""
    if checker is None:
        return None
    from planecal.sampling.detour import Detour
    from planecal.sampling.poses import PoseGenerator
    return Detour(PoseGenerator(scene), checker)


def _cell_frame(frame, world, plan) -> dict:
    """What the cell frame adds to AP at these ISO poses: how far the robot frame
    (J1's axis and zero, in the cell frame) moves them (the robot's placement and J1's
    zero offset delta1, which no plane calibration sees), and delta1."""
    P = np.asarray(plan.points_m)
    shift = np.linalg.norm(P @ frame[:3, :3].T + frame[:3, 3] - P, axis=1)
    out = {"shift_mm": shift * 1e3}
    if world is not None:
        out["delta1_rad"] = float(world.params.joint_offsets[0])
    return out


def _rounding_mm(true_model, plan, frame) -> np.ndarray:
    """The oracle's whole counts' share: its true tool point's distance from each target."""
    P = plan.points_m @ frame[:3, :3].T + frame[:3, 3]
    d = [None] * len(P) if plan.direction is None else plan.direction["oracle"]
    return np.array([np.linalg.norm(true_model.tool_point(c, di) - p) * 1e3
                     for c, p, di in zip(plan.counts["oracle"], P, d)])


def _tcp_rows(iso, tcps: dict, after: str) -> list[dict]:
    """Per named TCP: AP (robot and cell frame) of the nominal model, the validated one and
    the oracle, and the validated one's RP, worst of P1..P5 (``..._tcp_...`` keys: at this
    TCP)."""
    rows = []
    for name, tcp in tcps.items():
        row = {"name": name, "tcp_m": tcp}
        for role, model in (("before", "nominal"), ("after", after), ("oracle", "oracle")):
            m = iso["models"][model]["tcps"][name]
            row[f"ap_{role}_tcp_mm"] = float(m["ap_mm"].max())
            row[f"ap_{role}_tcp_cell_mm"] = float(m["ap_cell_mm"].max())
        row["rp_after_tcp_mm"] = float(iso["models"][after]["tcps"][name]["rp_mm"].max())
        rows.append(row)
    return rows


def _offset_error(model, world, iso, tcps) -> dict:
    """The validated model's joint offsets against the truth, and what delta1 and delta6
    leave: delta1 turns everything about the base axis (the cell frame's AP), delta6 turns
    a named TCP off axis 6 (the tool point's sensor pose absorbs it)."""
    d_err = model.params.joint_offsets - world.params.joint_offsets
    r_xy = np.hypot(iso["points_m"][:, 0], iso["points_m"][:, 1])
    lever = max((float(np.hypot(*t[:2])) for t in tcps.values()), default=0.0)
    return {"offset_error_rad": d_err, "delta1_error_rad": float(d_err[0]),
            "delta6_error_rad": float(d_err[5]),
            "delta1_share_mm": float(abs(d_err[0]) * r_xy.max() * 1e3),
            "delta6_share_mm": float(abs(d_err[5]) * lever * 1e3)}


def _gauge(out, twin, scene, world, model, st, checker, mover, options, fit, plan) -> None:
    """The gauge block (package docstring), aimed with the validated model, measured with
    the nominal model, the validated one and its sensor with nominal offsets, and the
    fit's predicted spread, into ``out``."""
    from planecal.model.scene import nominal_params
    from planecal.twin.laser import LaserNoise
    calibrated = model.params
    nominal = nominal_params(scene)
    mixed = calibrated.copy()
    mixed.joint_offsets = nominal.joint_offsets.copy()
    lin = LaserNoise(scene.laser_range_mm, 0.0, None, None, options.laser_linearity_mm,
                     world.laser_phases).lin
    gb = gauge_block(twin, scene, world.params, {"nominal": nominal, "calibrated": calibrated,
                                                 "calibrated_sensor_nominal_offsets": mixed},
                     st, checker, mover=mover, laser_noise_mm=options.laser_noise_mm,
                     linearity=lin, aim=model)
    if fit is not None:
        out["predicted_from_fit"] = predicted_spread(
            scene.robot, gb["measurements"], calibrated, fit.layout, fit.covariance,
            plan.points_m, plan.R, plan.tool_in_flange[model.level], plan.q_ref)
    gb.pop("measurements")
    out.update(gauge=gb, gauge_error_before_mm=gb["models"]["nominal"]["error_mm"],
               gauge_error_after_mm=gb["models"]["calibrated"]["error_mm"],
               gauge_error_offsets_only_mm=gb["models"]["calibrated_sensor_nominal_offsets"]
               ["error_mm"])


__all__ = ["CUBE_RULE", "FLOOR", "figures", "named_tcps", "validate"]
