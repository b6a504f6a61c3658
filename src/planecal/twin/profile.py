"""Error profiles: how the twin's world differs from the nominal model (format
``planecal-errors/1``, ``formats.errors``). Named profiles live beside the robot,
``models/<robot>/errors/<name>.json`` (``ideal``, ``realistic``); any copy a user edits is
given by its path (``--errors FILE.json``).

A profile and a seed make a world (``draw_world``): the hidden truth -- the cell's joint
offsets, sensor pose and plates (``truth.draw_truth``, the same draws for the same seed
as the first twin), the robot's true geometry (``kinematics.Kinematics``) and the phases
of the gear errors, both from a stream of their own -- and the twin's options (servo,
laser, the errors the tick adds to the joints).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.formats import read_json, validate
from planecal.formats.base import Num, Record, Vector
from planecal.formats.error_profile import N_JOINTS, ErrorProfileFile
from planecal.model.kinematics import Kinematics, frame_error, parallel_pairs
from planecal.model.robot import Robot
from planecal.model.scene import Scene
from planecal.twin.generic_profile import generic_document, generic_file
from planecal.twin.options import TwinOptions
from planecal.twin.truth import Tolerances, Truth, draw_truth

PROFILES = ("ideal", "realistic")
DEFAULT_PROFILE = "realistic"
_Row = Vector(Num, N_JOINTS, "values, one per joint")
_Frame = Vector(Vector(Num, 4, "numbers in a row"), 4, "rows of a 4x4 frame")


@dataclass(frozen=True)
class ErrorProfile:
    name: str
    path: Path
    doc: ErrorProfileFile

    def tolerances(self) -> Tolerances:
        c = self.doc.cell
        return Tolerances(offset_rad=tuple(c.joint_offsets_rad), origin_m=c.sensor_origin_m,
                          angle_rad=c.sensor_angles_rad, plane_point_m=c.plane_point_m,
                          plane_normal_rad=c.plane_normal_rad)

    def options(self, **kw) -> TwinOptions:
        """The twin's options of this profile (``kw`` overrides: noise_seed, check_steps)."""
        d = self.doc
        j = d.joints
        stiff = tuple(k for k in j.stiffness_nm_per_rad)
        payload = None if d.payload is None else (d.payload.mass_kg, tuple(d.payload.com_m))
        th = d.thermal
        thermal = (th.expansion_per_k, th.rise_k, th.time_constant_s) if th and th.enabled else None
        opts = TwinOptions(
            servo=d.servo.mode, tau_s=d.servo.tau_s, laser_noise_mm=d.laser.noise_mm,
            laser_quantum_mm=d.laser.quantum_mm, repeatability_mm=j.repeatability_mm,
            stiffness_nm_per_rad=stiff if any(k is not None for k in stiff) else None,
            backlash_rad=tuple(j.backlash_rad) if any(j.backlash_rad) else None,
            backlash_preload_nm=(None if j.backlash_preload_nm is None
                                 else tuple(j.backlash_preload_nm)),
            laser_linearity_mm=d.laser.linearity_mm,
            quantization=j.quantization,
            gear=tuple((h.joint, h.amplitude_rad, h.cycles_per_rev) for h in j.gear),
            payload=payload, thermal=thermal)
        return replace(opts, **kw)


def profile_path(name_or_path: str | Path, robot: Robot) -> Path:
    """A named profile beside the robot (``models/<robot>/errors/<name>.json``) or a path."""
    p = Path(name_or_path)
    if str(name_or_path) in PROFILES or (not p.suffix and len(p.parts) == 1):
        if robot.source is None:
            raise InputError(f"--errors {name_or_path}: the robot has no folder of profiles")
        p = robot.source.parent / "errors" / f"{name_or_path}.json"
        if not p.exists():
            raise InputError(f"--errors {name_or_path}: no such profile (the named ones: "
                             f"{', '.join(PROFILES)}; or give a file path)")
    return p


def load_profile(name_or_path: str | Path, robot: Robot) -> ErrorProfile:
    """A named profile or a profile file, validated (one-line InputError otherwise). A
    robot without a named profile of its own gets the generic one, scaled to it
    (``planecal.twin.generic_profile``)."""
    if str(name_or_path) in PROFILES and not _own(str(name_or_path), robot):
        doc, p = generic_file(str(name_or_path), robot)
        return ErrorProfile(doc.name, p, doc)
    p = profile_path(name_or_path, robot)
    doc = validate(ErrorProfileFile, read_json(p, "error profile"), p, "error profile")
    return ErrorProfile(doc.name, p, doc)


def draw_geometry(robot: Robot, profile: ErrorProfile, rng: np.random.Generator) -> Kinematics:
    """The robot's true geometry: robot.json's, every parameter moved by a normal draw of
    the profile's std (beta only where consecutive axes are parallel), the base and
    flange frames (robot.json's) moved by a translation and a small rotation."""
    nom = robot.kinematics
    g = profile.doc.geometry
    if g is None:
        return nom
    n = robot.n_joints
    beta = np.zeros(n)
    par = parallel_pairs(nom)
    alpha = nom.alpha + rng.normal(0.0, g.alpha_rad)
    a = nom.a + rng.normal(0.0, g.a_m)
    d = nom.d + rng.normal(0.0, g.d_m)
    b = rng.normal(0.0, g.beta_rad)
    beta[par] = b[par]
    # the base error composed with robot.json's base frame as the calibration's model does
    # (measurement.kinematics_of: frame_error(base) @ nominal base), the flange's likewise
    base = frame_error(np.concatenate([rng.normal(0.0, g.base.translation_m, 3),
                                       rng.normal(0.0, g.base.rotation_rad, 3)])) @ nom.base
    flange = nom.flange @ frame_error(np.concatenate([rng.normal(0.0, g.flange.translation_m, 3),
                                                      rng.normal(0.0, g.flange.rotation_rad, 3)]))
    return Kinematics(alpha, a, beta, nom.theta, d, base, flange)


def draw_world(scene: Scene, seed: int, profile: ErrorProfile) -> tuple[Truth, TwinOptions]:
    """The hidden truth and the twin's options of ``profile`` for ``seed`` (module
    docstring). The cell's draws are the first twin's for the same seed; the geometry and
    the gear phases come from a second stream, so adding them changes nothing else."""
    params = draw_truth(scene, seed, profile.tolerances())
    rng = np.random.default_rng([seed, 1])
    kin = draw_geometry(scene.robot, profile, rng)
    phases = tuple(float(v) for v in rng.uniform(0.0, 2 * np.pi, len(profile.doc.joints.gear)))
    laser = tuple(float(v) for v in rng.uniform(0.0, 2 * np.pi, 2))
    return Truth(params, kin, phases, laser), profile.options()


def save_truth(path, twin, errors: str | None = None, truth_seed: int | None = None) -> None:
    """The twin's hidden truth as a parameter file (``params``: what a level-1 calibration
    is compared with), plus the world it was drawn in: the error profile and seed it was
    drawn with, the robot's true geometry and the gear phases (``world``; extra keys a
    parameter-file reader keeps)."""
    from planecal.io.params import PARAMS_FORMAT, params_to_dict, save_json
    doc = {"format": PARAMS_FORMAT, **params_to_dict(twin.truth),
           "robot": {"name": twin.robot.name, "sha256": twin.robot.digest}}
    kin = twin.true_kinematics
    world = {"errors": None if errors is None else str(errors), "truth_seed": truth_seed,
             "gear_phases_rad": list(twin.world.gear_phases),
             "laser_linearity_phases_rad": list(twin.world.laser_phases)}
    if kin is not None:
        world["kinematics"] = {"alpha_rad": kin.alpha.tolist(), "a_m": kin.a.tolist(),
                               "beta_rad": kin.beta.tolist(), "theta_rad": kin.theta.tolist(),
                               "d_m": kin.d.tolist(), "base": kin.base.tolist(),
                               "flange": kin.flange.tolist()}
    doc["world"] = world
    save_json(path, doc)



class _KinematicsDoc(Record):
    """``world.kinematics`` of a truth file: the true robot's geometry (kinematics.py)."""
    alpha_rad: _Row
    a_m: _Row
    beta_rad: _Row
    theta_rad: _Row
    d_m: _Row
    base: _Frame
    flange: _Frame


class _WorldDoc(Record):
    errors: str | None = None
    truth_seed: int | None = None
    gear_phases_rad: list[Num] = []
    laser_linearity_phases_rad: Vector(Num, 2) = [0.0, 0.0]
    kinematics: _KinematicsDoc | None = None


class _TruthWorld(Record):
    world: _WorldDoc


def load_world(scene: Scene, path) -> Truth:
    """The world a truth file holds (``save_truth``'s): its ``params`` (what the twin's cell
    is) and, under ``world``, the robot's true geometry and the gear and laser phases. A
    parameter file without ``world`` (written before error profiles, or by hand) is a
    world with robot.json's geometry and no phases: the ideal world's. One-line InputError
    naming the file and the field."""
    from planecal.twin.truth import load_truth

    params = load_truth(scene, path)
    doc = read_json(path, "truth file")
    if not isinstance(doc, dict) or doc.get("world") is None:
        return Truth(params)
    w = validate(_TruthWorld, doc, path, "truth file").world
    kin = None
    if w.kinematics is not None:
        k = w.kinematics
        frames = {}
        for name in ("base", "flange"):
            T = np.array(getattr(k, name), float)
            R = T[:3, :3]
            if (np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0
                    or np.abs(T[3] - (0, 0, 0, 1)).max() > 0):
                raise InputError(f"{path}: world.kinematics.{name}: not a rigid 4x4 frame "
                                 "(rotation orthonormal, last row 0 0 0 1)")
            frames[name] = T
        kin = Kinematics(np.array(k.alpha_rad), np.array(k.a_m), np.array(k.beta_rad),
                         np.array(k.theta_rad), np.array(k.d_m), frames["base"],
                         frames["flange"])
        _same_robot(kin, scene.robot, path)
    return Truth(params, kin, tuple(float(v) for v in w.gear_phases_rad),
                 tuple(float(v) for v in w.laser_linearity_phases_rad))


def _same_robot(kin: Kinematics, robot: Robot, path) -> None:
    """InputError where a truth file's true geometry is not a drawn error away from the
    robot's nominal one (a truth file of another robot, written before truth files recorded
    their robot): no error profile moves a length by 5 cm or a twist by 0.1 rad."""
    nom = robot.kinematics
    if len(kin.a) != len(nom.a):
        raise InputError(f"{path}: world.kinematics holds {len(kin.a)} joints, the robot "
                         f"{robot.name!r} {len(nom.a)}: a truth file of another robot")
    for name, tol, unit in (("a", 0.05, "m"), ("d", 0.05, "m"), ("alpha", 0.1, "rad")):
        dev = np.abs(getattr(kin, name) - getattr(nom, name))
        j = int(np.argmax(dev))
        if dev[j] > tol:
            raise InputError(f"{path}: world.kinematics.{name}{'_rad' if unit == 'rad' else '_m'}"
                             f"[{j}] is {getattr(kin, name)[j]:.4g} {unit}, robot {robot.name!r} "
                             f"has {getattr(nom, name)[j]:.4g}: a truth file of another robot")


def truth_file_errors(path) -> str | None:
    """The error profile a truth file says its world was drawn with (``save_truth``), or
    None (a file written before it recorded it, or by hand)."""
    doc = read_json(path, "truth file")
    w = doc.get("world") if isinstance(doc, dict) else None
    e = w.get("errors") if isinstance(w, dict) else None
    return e if isinstance(e, str) else None


def _own(name: str, robot: Robot) -> bool:
    return robot.source is not None and (robot.source.parent / "errors" / f"{name}.json").exists()


def profile_source(name: str, robot: Robot) -> str:
    """Where the robot's profile ``name`` comes from (its own file, or the generic one)."""
    if _own(name, robot):
        return str(profile_path(name, robot))
    return generic_document(name, robot)[1]
