"""Point the beam at a plate point: sensor pose -> flange pose -> IK -> encoder counts.

Test helper (moved out of src/: only tests use it; the sampling application has its own pose
generator). ``params`` says where the sensor is and what the joint offsets are: pass
the nominal parameters to aim like the real application would, or the truth to hit
exactly.
"""
from __future__ import annotations

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.encoder import joints_to_counts
from planecal.model.geometry import sensor_pose
from planecal.model.robot import Robot
from planecal.model.ik import ik_nearest


def beam_frame(target: np.ndarray, beam: np.ndarray, distance_m: float, roll: float) -> np.ndarray:
    """Sensor frame (4x4, base) whose +z is ``beam`` and whose origin is ``distance_m``
    before ``target``; ``roll`` turns it about the beam."""
    z = np.asarray(beam, float) / np.linalg.norm(beam)
    h = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(h, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(roll), np.sin(roll)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = c * x + s * y, -s * x + c * y, z
    T[:3, 3] = np.asarray(target, float) - distance_m * z
    return T


def aim_joints(robot: Robot, params: CellParams, T_base_sensor: np.ndarray, q_near):
    """Joint angles q (encoder side, without offsets) that put the sensor at
    T_base_sensor, nearest to q_near; None when out of reach or limits."""
    T_fs = sensor_pose(params.sensor_origin, params.phi_y, params.phi_z)
    T_bf = T_base_sensor @ np.linalg.inv(T_fs)
    return ik_nearest(robot, T_bf, np.asarray(q_near, float), params.joint_offsets)


def cone_direction(axis: np.ndarray, max_angle: float, rng: np.random.Generator) -> np.ndarray:
    """A unit vector within ``max_angle`` of ``axis``, uniform over the spherical cap."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    cos_t = rng.uniform(np.cos(max_angle), 1.0)
    phi = rng.uniform(0, 2 * np.pi)
    h = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(axis, h)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    s = np.sqrt(1 - cos_t ** 2)
    return cos_t * axis + s * (np.cos(phi) * u + np.sin(phi) * v)


def random_aims(scene, params: CellParams, n: int, rng: np.random.Generator, q_near=None,
                plates=None, cone_deg: float | None = None, distance_mm=None,
                margin_m: float = 0.03, max_tries: int | None = None):
    """Up to ``n`` (counts int64[6], plate index) that aim the beam at random points of
    the plates (``margin_m`` inside their edges, on ``params``' planes) from the scene's
    sampling distance range, within its cone around the plate normal."""
    robot = scene.robot
    cone = np.deg2rad(scene.cone_deg if cone_deg is None else cone_deg)
    dmin, dmax = np.asarray(scene.distance_mm if distance_mm is None else distance_mm) * 1e-3
    plates = range(len(scene.plates)) if plates is None else plates
    plates = list(plates)
    q0 = (scene.calibration_q if scene.calibration_q is not None else np.zeros(6)) \
        if q_near is None else np.asarray(q_near, float)
    out = []
    tries = 0
    max_tries = max_tries or 20 * n
    while len(out) < n and tries < max_tries:
        tries += 1
        k = plates[rng.integers(len(plates))]
        plate = scene.plates[k]
        F = plate.frame(params.planes[k])
        uv = rng.uniform(margin_m, plate.size - margin_m)
        target = F[:3, 3] + F[:3, :2] @ uv
        beam = cone_direction(-F[:3, 2], cone, rng)
        T = beam_frame(target, beam, rng.uniform(dmin, dmax), rng.uniform(-np.pi, np.pi))
        q = aim_joints(robot, params, T, q0)
        if q is None:
            continue
        out.append((joints_to_counts(robot, q), k))
    return out

