"""The tool point a calibration is judged at (issue 22): the laser's beam point at its
nominal standoff (the middle of the scene's measuring range), in the model's robot frame
(its frame of joint 1 at q = 0 mapped onto robot.json's: ``compensate.registered_frame``,
what ``planecal validate`` measures AP in); and its derivative by the parameters."""
from __future__ import annotations

import numpy as np

from planecal.model.measurement import kinematics_of, sensor_in_base
from planecal.model.robot import Robot

FD_STEP = 1e-7  # central differences (SI units: rad, m, 1/m; compliance scaled below)


def standoff_m(params) -> float:
    """The tool point's standoff: the middle of the parameters' laser range (the scene's
    ``sensor.range_mm``, which ``nominal_params`` carries)."""
    return 0.5 * (params.laser_range_m[0] + params.laser_range_m[1])


def tool_point(robot: Robot, q: np.ndarray, params, side, standoff_m: float) -> np.ndarray:
    """(N, 3): the beam point at ``standoff_m`` in the model's robot frame (module
    docstring)."""
    from planecal.estimation.compensate import registered_frame
    o, z = sensor_in_base(robot, q, params, side)
    F = np.linalg.inv(registered_frame(robot, kinematics_of(robot, params)))
    return (o + standoff_m * z) @ F[:3, :3].T + F[:3, 3]


def tool_jacobian(robot: Robot, q: np.ndarray, side, layout, params, names,
                  standoff_m: float) -> np.ndarray:
    """(N, 3, p): the tool point's derivative by the parameters ``names`` of ``layout`` at
    ``params``, by central differences (a calibration's free ones: its ``Covariance.names``;
    a plan's: the base set it designs for)."""
    x0 = params.to_vector(layout)
    T = np.empty((len(q), 3, len(names)))
    for k, name in enumerate(names):
        i = layout.index(name)
        h = FD_STEP * (1e-3 if layout.param(name).unit == "rad/(N m)" else 1.0)
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        T[:, :, k] = (tool_point(robot, q, params.with_vector(xp, layout), side, standoff_m)
                      - tool_point(robot, q, params.with_vector(xm, layout), side, standoff_m)) \
            / (2 * h)
    return T
