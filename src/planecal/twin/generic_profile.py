"""The generic error profiles, for a robot without its own ``models/<robot>/errors/<name>.json``
(an imported robot, one written by hand): ``models/generic/errors/{ideal,realistic}.json``,
the MC70's, scaled to the robot by its size and payload (docs/ERRORS.md, "The generic
profile"):

* lengths (the geometry's a and d stds, the base and flange frame translations) by the
  robot's reach over the MC70's (``kinematics.reach_m``: 2.83 m);
* joint stiffness and the torque that holds a loaded joint on one flank (backlash
  preload) by the torque class a joint is built for: reach times payload over the MC70's
  (2.83 m, 70 kg; without ``payload_kg`` in robot.json by reach alone, and it says so),
  or, joint by joint, the gravity torque the robot's own masses put on that joint over
  the MC70's on its where that is larger (``model.gravity.joint_torques``, the profile's
  sensor on the flange, the 90th percentile of |torque| over ``TORQUE_SAMPLES`` random
  configurations within the limits): a joint carries its arm, so an arm heavier than its
  size class deflects no more than the MC70 in radians. By size alone a KR 210 (3,300 kg
  of moving links in its URDF) was 6.6 times as compliant as the MC70: 4.9 mm at the
  tool after an offsets calibration. Not the masses alone: ROS-Industrial's KUKA
  descriptions carry 2 kg placeholders on every link, which would make a KR 120's joints
  13 times softer than the MC70's;
* the joints' repeatability by the robot's over the MC70's 0.07 mm (the same 0.81 share
  of it): robot.json's datasheet figure, or where it states none the MC70's scaled by
  reach (``model.robot.default_repeatability_m``, the one default every consumer reads);
* angles (twists, Hayati's beta, gear errors, lost motion) and the cell's tolerances (the
  sensor's mounting, the plates) as they are: they belong to the reducer class and to
  the cell, not to the arm's size.

``ideal`` holds no number of the robot's own (its repeatability is robot.json's) and is
used as it is. A profile made so says so: its description starts with GENERIC, and the
command that loads it says once which scaling it used (a warning on stderr).
"""
from __future__ import annotations

import copy
import logging

import numpy as np

from planecal.base.paths import data_folder
from planecal.formats import read_json, validate
from planecal.formats.error_profile import ErrorProfileFile
from planecal.model.kinematics import reach_m
from planecal.model.robot import REFERENCE_REACH_M, REFERENCE_REPEATABILITY_MM

REFERENCE_PAYLOAD_KG = 70.0  # MC70 datasheet (seed H.1)
TORQUE_SAMPLES = 500
_told: set = set()
log = logging.getLogger(__name__)


def generic_path(name: str):
    return data_folder("models") / "generic" / "errors" / f"{name}.json"


def gravity_class(robot, payload) -> np.ndarray:
    """Each joint's gravity torque class [N m]: the 90th percentile of |torque| over
    TORQUE_SAMPLES random configurations within the limits, with ``payload`` (mass, com)
    on the flange."""
    from planecal.model.gravity import joint_torques
    Q = np.random.default_rng(0).uniform(robot.limits[:, 0], robot.limits[:, 1],
                                         (TORQUE_SAMPLES, robot.n_joints))
    return np.quantile(np.abs(joint_torques(robot, Q, payload)), 0.9, axis=0)


def scaling(robot, payload=None) -> dict:
    """The factors a generic profile uses for ``robot`` (module docstring); ``payload``:
    the profile's (mass, com) on the flange, for the torque classes."""
    from planecal.model.robot import load_robot
    length = reach_m(robot.kinematics) / REFERENCE_REACH_M
    pay = None if robot.payload_kg is None else robot.payload_kg / REFERENCE_PAYLOAD_KG
    torque = length * (pay if pay is not None else 1.0)
    rep = robot.repeatability_m * 1e3 / REFERENCE_REPEATABILITY_MM
    joints = None
    if robot.masses:
        ref = gravity_class(load_robot("mc70"), payload)
        own = gravity_class(robot, payload)
        joints = [max(torque, float(o / r)) if r > 0 else torque for o, r in zip(own, ref)]
    return {"length": length, "payload": pay, "torque": torque, "repeatability": rep,
            "joints": joints}


def generic_document(name: str, robot) -> tuple[dict, str]:
    """(the profile's JSON document scaled for ``robot``, a one-line note saying how)."""
    path = generic_path(name)
    raw = copy.deepcopy(read_json(path, "error profile"))
    pl = raw.get("payload")
    f = scaling(robot, None if not pl else (pl["mass_kg"], np.asarray(pl["com_m"], float)))
    if name == "ideal":
        how = (f"the generic 'ideal' profile ({path}), used as it is (it holds no number "
               "of the robot's own)")
    elif f["joints"] is not None and max(f["joints"][1:3]) > f["torque"]:
        how = (f"the generic '{name}' profile ({path}), the MC70's scaled by reach "
               f"{f['length']:.3g}, the joints' stiffness by their gravity torque over the "
               f"MC70's where above the size class {f['torque']:.3g} (J2 {f['joints'][1]:.3g}, "
               f"J3 {f['joints'][2]:.3g}: robot.json's masses)")
    else:
        how = (f"the generic '{name}' profile ({path}), the MC70's scaled by reach "
               f"{f['length']:.3g}" + (f" and payload {f['payload']:.3g}" if f["payload"]
                                       is not None else " (no payload_kg in robot.json: "
                                       "torques by reach alone)"))
    if name != "ideal":
        g = raw.get("geometry") or {}
        for key in ("a_m", "d_m"):
            if key in g:
                g[key] = [v * f["length"] for v in g[key]]
        for frame in ("base", "flange"):
            if frame in g:
                g[frame]["translation_m"] *= f["length"]
        j = raw["joints"]
        per = f["joints"] or [f["torque"]] * len(j["stiffness_nm_per_rad"])
        j["stiffness_nm_per_rad"] = [None if k is None else k * max(c, 1e-6)
                                     for k, c in zip(j["stiffness_nm_per_rad"], per)]
        if j.get("backlash_preload_nm"):
            j["backlash_preload_nm"] = [None if t is None else t * c
                                        for t, c in zip(j["backlash_preload_nm"], per)]
        if j.get("repeatability_mm") is not None:
            j["repeatability_mm"] *= f["repeatability"]
    raw["description"] = f"GENERIC for {robot.name}: {how}. " + raw.get("description", "")
    return raw, how


def generic_file(name: str, robot):
    """The validated generic ``name`` for ``robot`` and its path (warns once how it is
    made); ``twin.profile.load_profile`` makes the ErrorProfile of it."""
    raw, how = generic_document(name, robot)
    path = generic_path(name)
    doc = validate(ErrorProfileFile, raw, path, "error profile")
    key = (robot.digest, name)
    if key not in _told:
        _told.add(key)
        log.warning(f"{robot.name} has no '{name}' error profile of its own: {how}")
    return doc, path
