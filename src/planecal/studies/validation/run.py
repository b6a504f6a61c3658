"""One validation: ISO 9283 and the gauge block, nominal vs calibrated, on one world."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.model.cell_params import CellParams
from planecal.model.encoder import counts_to_joints
from planecal.model.kinematics import fk
from planecal.studies.validation.gauge import gauge_block, predicted_spread
from planecal.studies.validation.iso9283 import Mover, cube_from_flanges, iso9283, robot_frame
from planecal.studies.validation.settings import ValidationSettings


def validate(scene, world, calibrated: CellParams, sample_counts: np.ndarray,
             st: ValidationSettings | None = None, checker=None, fit=None,
             options=None) -> dict:
    """ISO 9283 AP/RP and the gauge block, nominal vs calibrated, on a twin of ``world``
    (a ``twin.truth.Truth``; a ``CellParams`` is robot.json's geometry) with ``options``
    (``TwinOptions``: the profile's joint and laser errors, noise; None: ``TwinOptions()``,
    the ideal world's). ``sample_counts``: the calibration samples (they place the ISO
    cube); ``fit``: the calibration's ``fit.Result``, whose covariance predicts the spread
    (None: no prediction)."""
    from planecal.model.scene import nominal_params
    from planecal.twin import Twin, TwinOptions
    from planecal.twin.laser import LaserNoise
    from planecal.twin.truth import Truth

    options = TwinOptions() if options is None else options
    st = st or ValidationSettings()
    st.check()
    world = world if isinstance(world, Truth) else Truth(world)
    truth = world.params
    robot = scene.robot
    twin = Twin(scene, truth=world, seed=st.seed, options=options)
    mover = Mover(twin, robot, checker)
    flanges = fk(robot.kinematics, counts_to_joints(robot, sample_counts))[:, :3, 3]
    center, edge = cube_from_flanges(flanges, st.cube_edge_m)
    q_cal = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    R = fk(robot.kinematics, q_cal)[:3, :3]
    frame = robot_frame(robot, world)
    models = {"nominal": CellParams(planes=calibrated.planes), "calibrated": calibrated}
    for attempt in range(6):  # a cube of our own choosing shrinks until all poses are clear
        try:
            iso = iso9283(twin, scene, models, center, edge, R, st, checker, frame, mover)
            break
        except InputError:
            if st.cube_edge_m is not None or attempt == 5:
                raise
            edge *= 0.75
    ap_b, ap_a = iso["models"]["nominal"]["ap_mm"], iso["models"]["calibrated"]["ap_mm"]
    rp = np.maximum(iso["models"]["nominal"]["rp_mm"], iso["models"]["calibrated"]["rp_mm"])
    d_err = calibrated.joint_offsets - truth.joint_offsets
    # what is left: delta1 turns everything about the base axis, delta6 turns a TCP off axis 6
    r_xy = np.hypot(iso["points_m"][:, 0], iso["points_m"][:, 1])
    left = {"offset_error_rad": d_err, "delta1_error_rad": float(d_err[0]),
            "delta6_error_rad": float(d_err[5]),
            "delta1_share_mm": float(abs(d_err[0]) * r_xy.max() * 1e3),
            "delta6_share_mm": float(abs(d_err[5]) * np.hypot(*np.asarray(st.tcp_m)[:2]) * 1e3)}
    out = {
        "ap_before_mm": float(ap_b.max()), "ap_after_mm": float(ap_a.max()),
        "ap_ratio": float(ap_b.max() / ap_a.max()) if ap_a.max() > 0 else float("inf"),
        "ap_before_cell_mm": float(iso["models"]["nominal"]["ap_cell_mm"].max()),
        "ap_after_cell_mm": float(iso["models"]["calibrated"]["ap_cell_mm"].max()),
        "rp_mm": float(rp.max()),
        "rp_before_mm": float(iso["models"]["nominal"]["rp_mm"].max()),
        "rp_after_mm": float(iso["models"]["calibrated"]["rp_mm"].max()),
        "gauge_error_before_mm": None, "gauge_error_after_mm": None,
        "gauge_error_offsets_only_mm": None, "predicted_from_fit": None,
        "iso": iso, "gauge": None, "residual_offset_error": left,
        "settings": {k: getattr(st, k) for k in st.__dataclass_fields__},
    }
    if not st.gauge:
        return out
    nominal = nominal_params(scene)
    mixed = calibrated.copy()
    mixed.joint_offsets = nominal.joint_offsets.copy()
    lin = LaserNoise(scene.laser_range_mm, 0.0, None, None, options.laser_linearity_mm,
                     world.laser_phases).lin
    gb = gauge_block(twin, scene, truth, {"nominal": nominal, "calibrated": calibrated,
                                          "calibrated_sensor_nominal_offsets": mixed}, st,
                     checker, mover=mover, laser_noise_mm=options.laser_noise_mm,
                     linearity=lin)
    if fit is not None:
        out["predicted_from_fit"] = predicted_spread(
            robot, gb["measurements"], calibrated, fit.layout, fit.covariance,
            iso["points_m"], R, np.asarray(st.tcp_m, float), q_cal)
    gb.pop("measurements")
    out.update(gauge=gb, gauge_error_before_mm=gb["models"]["nominal"]["error_mm"],
               gauge_error_after_mm=gb["models"]["calibrated"]["error_mm"],
               gauge_error_offsets_only_mm=gb["models"]["calibrated_sensor_nominal_offsets"]
               ["error_mm"])
    return out
