"""One validation: ISO 9283 at the tool point and the flange, and the gauge block; the
nominal model, each calibrated model and the twin's own true model, on one world."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.base.progress import report
from planecal.studies.validation.cube import (CENTRES, SHRINK, SHRINKS, SamplePoses,
                                              default_edge, medoid_order, nearest_sample_m)
from planecal.studies.validation.gauge import gauge_block, predicted_spread
from planecal.studies.validation.iso9283 import Mover, iso9283, plan_iso, robot_frame
from planecal.studies.validation.settings import WHERE, ValidationSettings

CUBE_RULE = ("centred on the tool point of the samples' medoid (the sample whose tool point "
             "is nearest all the others in sum; the next nearer the middle where the robot "
             "has no path there from its start, or where no cube fits), with that sample's "
             "flange orientation; edge 80 % of the sample flange positions' smallest "
             "10-90 % range (at most 250 mm), "
             "shrunk by 0.75 until every model's five poses are reachable, collision-free "
             "and inside the calibrated region (the samples' flange hull + 50 mm, their "
             "joint ranges + 2 deg)")


def figures(iso: dict, name: str, role: str) -> dict:
    """Model ``name``'s figures under ``role``'s keys (``settings.figure_keys``): AP (robot
    and cell frame) and RP, worst of P1..P5, at the tool point and at the flange."""
    m = iso["models"][name]
    out = {}
    for w in WHERE:
        out[f"ap_{role}_{w}_mm"] = float(m[w]["ap_mm"].max())
        out[f"ap_{role}_{w}_cell_mm"] = float(m[w]["ap_cell_mm"].max())
        out[f"rp_{role}_{w}_mm"] = float(m[w]["rp_mm"].max())
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
             options=None) -> dict:
    """ISO 9283 AP/RP and the gauge block on a twin of ``world`` (a ``twin.truth.Truth``;
    a ``CellParams`` is robot.json's geometry) with ``options`` (``TwinOptions``; None:
    ``TwinOptions()``, the ideal world's). ``calibrated``: a ``compensate.CalibratedModel``
    or several (lower levels first; the last is the one validated, "after"), each
    commanding the same poses beside the nominal model and the twin's own true model
    (the oracle). ``sample_counts``: the calibration samples (they place the cube and
    bound the calibrated region); ``fit``: the validated calibration's ``fit.Result``,
    whose covariance predicts the spread (None: no prediction)."""
    from planecal.estimation.compensate import CalibratedModel, Region
    from planecal.model.scene import nominal_params
    from planecal.studies.validation.commanders import ModelCommander, OracleCommander
    from planecal.twin import Twin, TwinOptions
    from planecal.twin.oracle import TrueModel
    from planecal.twin.truth import Truth

    options = TwinOptions() if options is None else options
    st = st or ValidationSettings()
    st.check()
    world = world if isinstance(world, Truth) else Truth(world)
    models = [calibrated] if isinstance(calibrated, CalibratedModel) else list(calibrated)
    names = ["nominal"] + [m.level for m in models] + ["oracle"]
    if len(set(names)) != len(names):
        raise ValueError(f"validate: models of one name: {names}")
    robot = scene.robot
    twin = Twin(scene, truth=world, seed=st.seed, options=options)
    mover = Mover(twin, robot, checker, _detour(scene, checker))
    start = mover.drv.commanded_counts
    frame = robot_frame(robot, world)
    standoff = scene.standoff_m
    true_model = TrueModel(twin, standoff)
    commanders = [ModelCommander("nominal", CalibratedModel(robot, nominal_params(scene),
                                                            "nominal"), standoff)]
    commanders += [ModelCommander(m.level, m, standoff) for m in models]
    commanders.append(OracleCommander(true_model, frame, robot))
    samples = SamplePoses.of(scene, sample_counts)
    region = Region.from_counts(robot, sample_counts, "the calibration samples")
    plan, centre = _place(scene, commanders, samples, st, mover, region, checker)
    tcps = named_tcps(scene, st)
    iso = iso9283(twin, plan, st, mover, standoff, tcps, frame)
    after = models[-1]
    out = {**figures(iso, "nominal", "before"), **figures(iso, after.level, "after"),
           **figures(iso, "oracle", "oracle"), "model_after": after.level,
           "standoff_mm": standoff * 1e3,
           "levels": [{"level": m.level, **figures(iso, m.level, "after")} for m in models],
           "tcps": _tcp_rows(iso, tcps, after.level),
           "cube": _cube(plan, samples, centre, region, st),
           "oracle": {"tool_in_flange_m": true_model.tool_in_flange,
                      "rounding_mm": _rounding_mm(true_model, plan, frame)},
           "iso": iso, "gauge": None, "predicted_from_fit": None,
           "gauge_error_before_mm": None, "gauge_error_after_mm": None,
           "gauge_error_offsets_only_mm": None,
           "residual_offset_error": _offset_error(after, world, iso, tcps),
           "settings": {k: getattr(st, k) for k in st.__dataclass_fields__}}
    b, a = out["ap_before_tool_mm"], out["ap_after_tool_mm"]
    out["ap_tool_ratio"] = b / a if a > 0 else float("inf")
    if st.gauge:  # from where the robot started, the way it came (its paths are known)
        mover.go(samples.counts[centre], "back to the cube's centre sample")
        mover.go(start, "back to the start")
        _gauge(out, twin, scene, world, after, st, checker, mover, options, fit, plan)
    return out


def _detour(scene, checker):
    """The sampling run's detour around a blocked path (None without a checker)."""
    if checker is None:
        return None
    from planecal.sampling.planner import Detour
    from planecal.sampling.poses import PoseGenerator
    return Detour(PoseGenerator(scene), checker)


def _place(scene, commanders, samples, st, mover, region, checker):
    """The ISO plan in the cube the package docstring's rule places (``CUBE_RULE``), and
    the sample it is centred on; a cube of the user's (``st.cube_edge_m``) is not shrunk,
    and may reach outside the region (``cube.outside_region_mm`` says how far)."""
    order = medoid_order(samples.tool)
    start = mover.drv.commanded_counts
    ks = [int(i) for i in order[:CENTRES] if mover.path_ok(start, samples.counts[i])]
    ks = ks or [int(order[0])]
    given = st.cube_edge_m is not None
    edges = [st.cube_edge_m if given else default_edge(samples.flange[:, :3, 3])]
    if not given:
        for _ in range(SHRINKS):
            edges.append(edges[-1] * SHRINK)
    for k in ks[:1] if given else ks:  # the next centre where no cube fits
        center, R, q_ref = samples.tool[k], samples.flange[k, :3, :3], samples.q[k]
        for edge in edges:
            report(what=f"placing the ISO cube ({edge * 1e3:.0f} mm)")
            try:
                return plan_iso(scene, commanders, center, edge, R, q_ref, mover, region,
                                checker, inside=not given), k
            except InputError as e:
                last = e
    raise last


def _cube(plan, samples, centre, region, st) -> dict:
    rank = int(np.flatnonzero(medoid_order(samples.tool) == centre)[0])
    return {"rule": "given (--cube-mm)" if st.cube_edge_m is not None else CUBE_RULE,
            "center_m": plan.center_m, "edge_m": plan.edge_m,
            "sample_index": centre, "medoid_rank": rank,
            "nearest_sample_mm": nearest_sample_m(plan.points_m, samples.tool) * 1e3,
            "outside_region_mm": plan.outside_mm, "outside_region_deg": plan.outside_deg,
            "inside_region": bool(not plan.outside_mm.any() and not plan.outside_deg.any()),
            "region": region.to_dict()}


def _rounding_mm(true_model, plan, frame) -> np.ndarray:
    """The oracle's whole counts' share: its true tool point's distance from each target."""
    P = plan.points_m @ frame[:3, :3].T + frame[:3, 3]
    return np.array([np.linalg.norm(true_model.tool_point(c) - p) * 1e3
                     for c, p in zip(plan.counts["oracle"], P)])


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
    """The gauge block (package docstring) with the nominal model, the validated one and
    its sensor with nominal offsets, and the fit's predicted spread, into ``out``."""
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
                     linearity=lin)
    if fit is not None:
        out["predicted_from_fit"] = predicted_spread(
            scene.robot, gb["measurements"], calibrated, fit.layout, fit.covariance,
            plan.points_m, plan.R, plan.tool_in_flange[model.level], plan.q_ref)
    gb.pop("measurements")
    out.update(gauge=gb, gauge_error_before_mm=gb["models"]["nominal"]["error_mm"],
               gauge_error_after_mm=gb["models"]["calibrated"]["error_mm"],
               gauge_error_offsets_only_mm=gb["models"]["calibrated_sensor_nominal_offsets"]
               ["error_mm"])


__all__ = ["CUBE_RULE", "figures", "named_tcps", "validate"]
