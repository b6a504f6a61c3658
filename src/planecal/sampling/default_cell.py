"""A default cell for any robot (``planecal scene new``): plates in its reach at its size,
the laser's mount on its flange, no obstacles; docs/ROBOTS.md.

* The sensor: on the flange axis, ``SENSOR_OUT_M`` out, the beam pitched ``SENSOR_PITCH``
  off the flange's z (phi_y; phi_z = 0). Not along it: the beam angles (seed 6.7) are
  polar angles about the flange's z, so a beam on that axis leaves phi_z without effect
  and the fit excludes it, though the true mounting has one (a twin run so calibrated
  was 3.8 std off on delta4); the more pitch, the better phi_z is determined (UR5 cell,
  realistic twin: std 10, 7.4, 6.0 mrad at 30, 45, 60 deg); the seed's bracket is
  pitched 71 deg. The ZS-LD80's window
  (65-95 mm) and the seed's sampling (a 30 deg cone, 70-90 mm).
* The plates: the seed's 350 x 250 mm plate scaled by the arm's horizontal reach over the
  MC70's 2 m (at least 0.6 of it), each on a stand and tilted ``TILT_DEG`` towards the
  robot (the seed's plate is tilted 15.8 deg), so that no plane passes near the base
  origin (the plane n~ . p = 1 cannot). Where: in front of the robot (the direction its
  flange points at its home), a plate for each of ``candidates``' distances (a share of
  the horizontal reach) and heights (a share of the shoulder's height), the one whose
  random sensor poses (the sampling's own draw, ``PoseGenerator``) most often have a
  configuration within the limits and clear of the cell (``CollisionWorld``), in both
  wrist branches. With three plates the second and third stand ``SIDE_DEG`` to either
  side of the first, tilted more (30 and 45 deg): three orientations.
* The positions: the calibration position is the configuration that puts the sensor
  above the first plate's centre, beam on its normal, clear of the cell, nearest to the
  robot's home; the robot's home counts are kept if clear, else the calibration
  position's counts are the scene's home.

The search is deterministic (fixed seeds); ``RunFailed`` when no placement reaches
``MIN_REACHABLE`` of its poses (place the plates by hand: docs/FORMATS.md). With a judge
(``scene new``: ``studies.cell_check``, does the cell identify the level asked on the
poses its default run would use?) plates are added, the second and third as above, up to
``MAX_PLATES``, until the judge is content, else RunFailed with its reason.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError, RunFailed
from planecal.model.encoder import counts_to_joints, joints_to_counts
from planecal.model.kinematics import fk, frames
from planecal.model.robot import Robot

SENSOR_OUT_M = 0.10  # sensor origin on the flange axis (adapter 12 mm + head 60 mm + ...)
SENSOR_PITCH = 1.0472  # rad (60 deg): the beam's angle from the flange's z (phi_y)
PLATE_M = (0.35, 0.25)  # the seed's plate (6.4.2), for a 2 m arm
TILT_DEG = 15.0
SIDE_DEG = 50.0
DISTANCES = (0.45, 0.55, 0.65)  # share of the horizontal reach
HEIGHTS = (0.15, 0.5, 0.9)  # share of the shoulder's height above the floor
POSES = 40  # random sensor poses a placement is scored on
MIN_REACHABLE = 0.3
MAX_PLATES = 3
THICKNESS_M = 0.012
ABOVE_FLOOR_M = 0.02  # a plate's lowest edge above the floor (its stand or wedge)


def workspace(robot: Robot) -> dict:
    """The arm's horizontal reach (99th percentile of random configurations within the
    limits), the shoulder's height and the direction its flange points at home."""
    kin = robot.kinematics
    Q = np.random.default_rng(0).uniform(robot.limits[:, 0], robot.limits[:, 1], (4000, 6))
    P = fk(kin, Q)[:, :3, 3]
    reach = float(np.quantile(np.hypot(P[:, 0], P[:, 1]), 0.99))
    home = counts_to_joints(robot, robot.home_counts)
    shoulder = float(frames(kin, home)[2, 2, 3])
    f = fk(kin, home)[:3, 3]
    az = float(np.arctan2(f[1], f[0])) if np.hypot(f[0], f[1]) > 0.1 * reach else 0.0
    return {"reach": reach, "shoulder": shoulder, "azimuth": az, "home": home}


def plate(name: str, centre, azimuth: float, tilt_deg: float, size, floor_z: float) -> dict:
    """A scene plate centred at ``centre``, its face up and tilted towards the base axis
    by ``tilt_deg`` (away from it if the plane would pass near the base origin), its
    lowest edge at least ``ABOVE_FLOOR_M`` above the floor (lifted if need be: a plate
    through the floor would let the beam hit the floor at its low edge)."""
    c = np.asarray(centre, float).copy()
    t = np.deg2rad(tilt_deg)
    low = c[2] - size[1] / 2 * np.sin(t) - THICKNESS_M * np.cos(t)
    c[2] += max(0.0, floor_z + ABOVE_FLOOR_M - low)
    er = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
    et = np.array([-np.sin(azimuth), np.cos(azimuth), 0.0])
    for t in (tilt_deg, -tilt_deg):
        n = np.cos(np.deg2rad(t)) * np.array([0.0, 0.0, 1.0]) - np.sin(np.deg2rad(t)) * er
        if abs(n @ c) > 0.1:
            break
    y = np.cross(n, et)
    corner = c - size[0] / 2 * et - size[1] / 2 * y
    return {"name": name, "n_tilde": _r(n / (n @ c)), "corner_m": _r(corner), "x_axis": _r(et),
            "size_m": _r(size), "thickness_m": THICKNESS_M, "face": 1 if n @ c > 0 else -1,
            "stand": True}


def _r(v) -> list[float]:
    return [round(float(x), 6) for x in np.asarray(v, float).ravel()]


def document(robot_ref: str, name: str, plates: list[dict], floor_z: float,
             description: str, positions: dict | None = None, allowed=()) -> dict:
    return {"format": "planecal-scene/1", "name": name, "description": description,
            **({"allowed_pairs": list(allowed)} if allowed else {}),
            "robot": robot_ref,
            "sensor": {"origin_m": [0.0, 0.0, SENSOR_OUT_M], "phi_y_rad": SENSOR_PITCH,
                       "phi_z_rad": 0.0, "range_mm": [65.0, 95.0]},
            "plates": plates, "obstacles": [], "floor_z_m": floor_z,
            "positions": positions or {}, "sampling": {"cone_deg": 30.0, "distance_mm": [70.0, 90.0]}}


def _load(doc: dict, folder: Path):
    """The scene a document describes (validated, as planecal loads it)."""
    from planecal.model.scene import load_scene
    with tempfile.NamedTemporaryFile("w", suffix=".json", dir=folder, delete=False) as f:
        json.dump(doc, f)
    try:
        return load_scene(f.name)
    except InputError as e:  # named as the cell, not the temporary file it is read from
        raise InputError(str(e).replace(f.name, f"the default cell (floor_z_m "
                                                f"{doc['floor_z_m']:g})")) from None
    finally:
        Path(f.name).unlink(missing_ok=True)


def score(scene, plate_index: int = 0) -> float:
    """Share of POSES random sensor poses on the plate with a configuration within the
    limits and clear of the cell, counting a pose fully when both wrist branches have one."""
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling.poses import PoseGenerator
    gen = PoseGenerator(scene)
    world = CollisionWorld(scene)
    rng = np.random.default_rng(1)
    got = 0.0
    for _ in range(POSES):
        pose = gen.draw(rng, plate_index)
        Q = gen.branch_targets(pose, workspace_home(scene))
        got += sum(world.check_config(q).ok for q in Q) / 2
    return got / POSES


def workspace_home(scene) -> np.ndarray:
    return counts_to_joints(scene.robot, scene.robot.home_counts)


def calibration_position(scene, world) -> np.ndarray | None:
    """The clear configuration with the sensor above plate 1's centre, beam on its normal
    (80 mm), nearest to the robot's home (module docstring)."""
    from planecal.model.ik import ik_all
    from planecal.sampling.poses import PoseGenerator
    gen = PoseGenerator(scene)
    F = scene.plates[0].frame()
    centre = scene.plates[0].center()
    home = workspace_home(scene)
    best, cost = None, np.inf
    for roll in np.deg2rad(np.arange(0, 360, 30)):
        T = np.eye(4)
        beam = -F[:3, 2]
        x = np.cos(roll) * F[:3, 0] + np.sin(roll) * F[:3, 1]
        T[:3, :3] = np.column_stack([x, np.cross(beam, x), beam])
        T[:3, 3] = centre - 0.08 * beam
        for q in ik_all(scene.robot, T @ gen.T_sf):
            c = float(np.max(np.abs(q - home) * np.abs(scene.robot.gains)))
            if c < cost and world.check_config(q).ok:
                best, cost = q, c
    return best


def default_cell(robot: Robot, robot_ref: str, name: str, n_plates: int, folder: Path,
                 floor_z: float = 0.0, log=print, judge=None) -> dict:
    """The scene document of the default cell (module docstring). ``judge(scene) ->
    (ok, why)``: whether a cell will do (``studies.cell_check`` via ``scene new``); with
    one, plates are added from ``n_plates`` up to ``MAX_PLATES`` until it says yes, else
    RunFailed with its last reason."""
    ws = workspace(robot)
    s = max(0.6, min(1.0, ws["reach"] / 2.0))
    size = (PLATE_M[0] * s, PLATE_M[1] * s)
    above = max(ws["shoulder"] - floor_z, 0.2)
    best = None
    middle = (DISTANCES[len(DISTANCES) // 2], HEIGHTS[len(HEIGHTS) // 2])
    az = ws["azimuth"]
    ws["allowed"] = tool_contacts(robot, robot_ref, name, folder, floor_z, ws, size, log)
    for f, h in sorted(((f, h) for f in DISTANCES for h in HEIGHTS),  # ties: the middle
                       key=lambda fh: abs(fh[0] - middle[0]) + abs(fh[1] - middle[1])):
        c = [f * ws["reach"] * np.cos(az), f * ws["reach"] * np.sin(az), floor_z + h * above]
        doc = document(robot_ref, name, [plate("plate1", c, az, TILT_DEG, size, floor_z)],
                       floor_z, "", allowed=ws["allowed"])
        sc = score(_load(doc, folder))
        log(f"plate at {f:.2f} of the reach, {c[2] - floor_z:.2f} m up (at least): {sc:.0%} of "
            f"{POSES} poses reachable and clear")
        if best is None or sc > best[0] + 1e-9:
            best = (sc, f, h, c)
    sc, f, h, c = best
    if sc < MIN_REACHABLE:
        raise RunFailed(f"no plate placement reaches {MIN_REACHABLE:.0%} of its poses (best "
                        f"{sc:.0%}): place the plates by hand (docs/FORMATS.md)")
    why = ""
    for k in range(n_plates, (MAX_PLATES if judge else n_plates) + 1):
        doc, scene = _cell(robot, robot_ref, name, k, folder, floor_z, log, ws, size, f, c)
        if judge is None:
            return doc
        ok, why = judge(scene)
        if ok:
            doc["description"] += f" Checked by planecal scene new: {why}"
            return doc
    raise RunFailed(f"no default cell of up to {MAX_PLATES} plates will do: {why}; place the "
                    "plates by hand (docs/FORMATS.md) and check them with planecal layouts")


def tool_contacts(robot: Robot, robot_ref: str, name: str, folder: Path, floor_z: float,
                  ws: dict, size, log) -> list[dict]:
    """The pairs of the tool's pieces with the arm's that touch whatever the joints do
    (``safety.self_contact``: a wrist hull that swallows the flange swallows the adapter
    on it too), each logged with its reason: the scene allows them."""
    from planecal.safety.self_contact import always_touching
    c = [0.5 * ws["reach"], 0.0, floor_z + 0.5]
    doc = document(robot_ref, name, [plate("plate1", c, 0.0, TILT_DEG, size, floor_z)],
                   floor_z, "")
    found, _, _ = always_touching(robot, scene=_load(doc, folder))
    for p in found:
        log(f"the arm's {p['pieces'][0]} and the tool's {p['pieces'][1]}: allowed (not "
            f"checked): {p['why']}")
    return found


def _cell(robot: Robot, robot_ref: str, name: str, n_plates: int, folder: Path,
          floor_z: float, log, ws: dict, size, f: float, c) -> tuple[dict, object]:
    """The default cell's document of ``n_plates`` plates, the first at ``c``, and its
    scene."""
    from planecal.safety.collision import CollisionWorld
    plates = [plate("plate1", c, ws["azimuth"], TILT_DEG, size, floor_z)]
    for k, (side, tilt) in enumerate(((SIDE_DEG, 30.0), (-SIDE_DEG, 45.0))[:n_plates - 1]):
        az = ws["azimuth"] + np.deg2rad(side)
        cs = [f * ws["reach"] * np.cos(az), f * ws["reach"] * np.sin(az), c[2]]
        plates.append(plate(f"plate{k + 2}", cs, az, tilt, size, floor_z))
    desc = (f"Default cell for {robot.name} (planecal scene new): {n_plates} plate(s) of "
            f"{size[0] * 1e3:.0f} x {size[1] * 1e3:.0f} mm on stands at {f:.2f} of the arm's "
            f"{ws['reach']:.2f} m horizontal reach, tilted {TILT_DEG:g} deg (the others more); "
            f"the sensor {SENSOR_OUT_M * 1e3:.0f} mm out on the flange axis, the beam "
            f"pitched {np.rad2deg(SENSOR_PITCH):.0f} deg off it; no obstacles.")
    doc = document(robot_ref, name, plates, floor_z, desc, allowed=ws["allowed"])
    scene = _load(doc, folder)
    for i in range(1, len(plates)):
        log(f"plate{i + 1}: {score(scene, i):.0%} of {POSES} poses reachable and clear")
    world = CollisionWorld(scene)
    q = calibration_position(scene, world)
    if q is None:
        raise RunFailed("no clear configuration puts the sensor above plate 1's centre: "
                        "place the plates by hand (docs/FORMATS.md)")
    pos = {"calibration_deg": _r(np.rad2deg(q))}
    if not world.check_config(workspace_home(scene)).ok:
        pos["home_counts"] = [int(v) for v in joints_to_counts(robot, q)]
        log("the robot's home is not clear of this cell: the scene's home is the calibration "
            "position")
    doc["positions"] = pos
    return doc, _load(doc, folder)  # as planecal will load it
