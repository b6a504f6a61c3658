"""The worlds a twin runs in: a hidden truth drawn from an error profile and a seed (or
read from a truth file), the twin's options with a study's noise overrides, and the error
sources of a world by family, each of which can be switched off (``without``: what
``validate``'s breakdown measures). One world builder for the studies, the API and the
commands (``planecal.twin.profile.draw_world`` draws; this module adds what a study asks
of a world).

A world travels with the files made in it (``WorldRef``): a run's sidecar, a truth file
and a result's provenance name the error profile and the truth's seed (or the truth file
and its hash), so a replay, a validation or the API rebuilds the same world from them.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.base.paths import file_sha256  # noqa: F401 (the world's files' hash)
from planecal.model.scene import Scene
from planecal.twin.options import TwinOptions
from planecal.twin.profile import ErrorProfile, draw_world, load_profile
from planecal.twin.truth import Truth, draw_truth


def with_noise(options: TwinOptions, laser_noise_mm: float | None = None,
               repeatability_mm: float | None = None) -> TwinOptions:
    """The twin's options with a study's noise overrides (None: the profile's)."""
    kw = {}
    if laser_noise_mm is not None:
        kw["laser_noise_mm"] = laser_noise_mm
    if repeatability_mm is not None:
        kw["repeatability_mm"] = repeatability_mm
    return replace(options, **kw)


def study_world(scene: Scene, profile: ErrorProfile, seed: int,
                offsets_all: bool = False) -> tuple[Truth, TwinOptions]:
    """The world of ``profile`` for ``seed`` (``draw_world``); ``offsets_all`` also draws
    delta1 and delta6 where the profile keeps them 0, within the largest of its bounds."""
    world, opts = draw_world(scene, seed, profile)
    if offsets_all:
        tol = profile.tolerances()
        b = tol.offset_bounds()
        if np.any(b == 0):
            b = np.where(b > 0, b, b.max())
            world = replace(world, params=draw_truth(scene, seed,
                                                     replace(tol, offset_rad=tuple(b))))
    return world, opts


@dataclass(frozen=True)
class WorldRef:
    """Where a world comes from, as files record it: an error profile (name or path) and
    the truth's seed, or a truth file (path and SHA-256); ``exact``: no random noise. The
    one record of a world (``to_dict``, ``from_dict``): a run sidecar's ``twin`` block
    (with the twin's noise ``seed`` beside it), a result's and a validation's ``world``."""
    errors: str
    truth_seed: int | None = None
    truth_file: str | None = None
    truth_sha256: str | None = None
    exact: bool = False

    def to_dict(self) -> dict:
        return {"errors": self.errors, "truth_seed": self.truth_seed,
                "truth_file": self.truth_file, "truth_sha256": self.truth_sha256,
                "exact": self.exact}

    @classmethod
    def from_dict(cls, d: dict, where: str, default: str = "ideal") -> "WorldRef":
        """The world a record names. Records written before it took this shape: a sidecar
        whose truth was drawn from its twin's ``seed`` (no ``truth_seed``), and one without
        ``errors``: ``default`` (the ideal world: runs made before error profiles)."""
        if not isinstance(d, dict):
            raise InputError(f"{where}: world: not a world reference")
        try:
            truth_file = d.get("truth_file")
            seed = d.get("truth_seed", None if truth_file else d.get("seed"))
            return cls(str(d.get("errors") or default),
                       None if truth_file is not None or seed is None else int(seed),
                       None if truth_file is None else str(truth_file), d.get("truth_sha256"),
                       bool(d.get("exact", False)))
        except (TypeError, ValueError) as e:
            raise InputError(f"{where}: world: not a world reference ({e})") from None

    def build(self, scene: Scene) -> tuple[Truth, TwinOptions]:
        """The world this reference names: the truth file's (checked against its hash), or
        the profile's draw for the seed."""
        from planecal.twin.profile import load_world
        profile = load_profile(self.errors, scene.robot)
        opts = profile.options()
        if self.exact:
            opts = replace(opts, servo="ideal", laser_noise_mm=0.0, repeatability_mm=0.0,
                           quantization=False)
        if self.truth_file is not None:
            if self.truth_sha256 is not None and file_sha256(self.truth_file) != self.truth_sha256:
                raise InputError(f"{self.truth_file}: the truth file changed since the run was "
                                 "made in its world (its SHA-256 differs)")
            world = load_world(scene, self.truth_file)
            check_world(world, profile, self.truth_file)
            return world, opts
        world, _ = draw_world(scene, int(self.truth_seed or 0), profile)
        return world, opts

    def describe(self) -> str:
        """In words: 'the realistic world of truth seed 3', 'the world of t.json (...)'."""
        name = Path(self.errors).stem if "/" in self.errors else self.errors
        if self.truth_file is not None:
            return f"the world of {self.truth_file} ({name} errors)"
        return f"the {name} world of truth seed {self.truth_seed}"


def check_world(world: Truth, profile: ErrorProfile, where) -> None:
    """InputError where a truth file's world cannot be the profile's: another count of gear
    phases, or no geometry for a profile that draws one."""
    opts = profile.options()
    if len(world.gear_phases) != len(opts.gear):
        raise InputError(f"{where}: its world has {len(world.gear_phases)} gear phases, the "
                         f"{profile.name} profile {len(opts.gear)} gear harmonics: give the "
                         "--errors the truth was drawn with")
    if profile.doc.geometry is not None and world.kinematics is None:
        raise InputError(f"{where}: no robot geometry in the file (no 'world'), but the "
                         f"{profile.name} profile has geometric errors: give --errors ideal, "
                         "or a truth file rehearse --truth-out wrote")


def make_twin(scene: Scene, ref: WorldRef, seed: int):
    """The twin of a world reference; ``seed`` its noise's."""
    from planecal.twin import Twin
    world, opts = ref.build(scene)
    return Twin(scene, truth=world, seed=seed, options=opts)


# The error sources of a world, by family (what ``without`` switches off): the ones the
# fit's model does not have, and the noise.
SOURCES = {
    "geometry": "geometry other than the joint offsets (link lengths and offsets, twists, "
                "base and flange frames)",
    "compliance": "gravity compliance",
    "gear": "gear transmission error",
    "backlash": "backlash",
    "noise": "repeatability, encoder quantisation and the laser's noise",
    "laser_linearity": "laser linearity",
    "thermal": "thermal growth",
}
SHORT = {"geometry": "link lengths, twists and frames", "compliance": "joint compliance",
         "gear": "gear error", "backlash": "backlash",
         "noise": "repeatability, quantisation, laser noise",
         "laser_linearity": "laser linearity", "thermal": "thermal growth"}
MISMATCH = ("geometry", "compliance", "gear", "backlash", "laser_linearity", "thermal")


def source_labels(options) -> dict[str, str]:
    """``SOURCES`` with what a world's options (``TwinOptions``) add: the joints its
    profile makes compliant (the UR5's J2, J3 and J4; the MC70's J2 and J3)."""
    out = dict(SOURCES)
    k = options.stiffness_nm_per_rad
    joints = [f"J{j + 1}" for j, v in enumerate(k or ()) if v is not None]
    if joints:
        out["compliance"] = f"gravity compliance ({', '.join(joints)})"
    return out


def sources_on(robot, world, options) -> list[str]:
    """The families of ``SOURCES`` present in a world (``Truth``, ``TwinOptions``)."""
    kin = world.kinematics if isinstance(world, Truth) else None
    nom = robot.kinematics
    geometry = kin is not None and not all(
        np.array_equal(getattr(kin, f), getattr(nom, f))
        for f in ("alpha", "a", "beta", "theta", "d", "base", "flange"))
    rep = robot.repeatability_m if options.repeatability_mm is None \
        else options.repeatability_mm * 1e-3
    on = {"geometry": geometry,
          "compliance": options.stiffness_nm_per_rad is not None
          and any(k is not None for k in options.stiffness_nm_per_rad),
          "gear": any(a > 0 for _, a, _ in options.gear),
          "backlash": options.backlash_rad is not None and bool(np.any(options.backlash_rad)),
          "noise": rep > 0 or options.quantization or options.laser_noise_mm > 0,
          "laser_linearity": options.laser_linearity_mm > 0,
          "thermal": options.thermal is not None}
    return [k for k in SOURCES if on[k]]


def without(world, options, off):
    """The world (``Truth``, ``TwinOptions``) with the families in ``off`` switched off
    (``SOURCES``; the cell's offsets, sensor pose and plates stay)."""
    if not isinstance(world, Truth):
        world = Truth(world)
    kw = {}
    for f in off:
        if f not in SOURCES:
            raise InputError(f"error source {f!r}: one of {', '.join(SOURCES)}")
        if f == "geometry":
            world = replace(world, kinematics=None)
        elif f == "compliance":
            kw["stiffness_nm_per_rad"] = None
        elif f == "gear":
            kw["gear"] = ()
            world = replace(world, gear_phases=())
        elif f == "backlash":
            kw.update(backlash_rad=None, backlash_preload_nm=None)
        elif f == "noise":
            kw.update(repeatability_mm=0.0, quantization=False, laser_noise_mm=0.0)
        elif f == "laser_linearity":
            kw["laser_linearity_mm"] = 0.0
        else:
            kw["thermal"] = None
    return world, replace(options, **kw)


def path_dependent(options) -> bool:
    """Joint errors that depend on how the robot got there (backlash by the direction of
    the last motion, thermal growth over robot time): a jump to rest cannot show them."""
    return bool((options.backlash_rad is not None and np.any(np.asarray(options.backlash_rad)))
                or options.thermal is not None)


def frame_error_of(T: np.ndarray) -> np.ndarray:
    """The (x, y, z, rx, ry, rz) of a frame T = T(t) Rz Ry Rx (``kinematics.frame_error``'s
    inverse; |ry| < 90 deg)."""
    R = T[:3, :3]
    ry = -np.arcsin(np.clip(R[2, 0], -1.0, 1.0))
    rz = np.arctan2(R[1, 0], R[0, 0])
    rx = np.arctan2(R[2, 1], R[2, 2])
    return np.array([*T[:3, 3], rx, ry, rz])


def true_params(robot, world: Truth, options: TwinOptions, fold_flange: bool = False):
    """A world's truth in the calibration's parameters (``CellParams``): the cell's joint
    offsets, sensor and planes, the true geometry as corrections of robot.json's modified
    DH, the true base frame, the joint compliance 1/k, and level 3's terms: each gear
    harmonic A sin(f q + phi) as its sin and cos amplitudes (A cos phi, A sin phi), each
    joint's backlash and the laser's linearity (``twin.laser``: 0.7 and 0.3 of its
    amplitude at one and two cycles over the measuring range). The true flange frame has no parameter of its own (a plane
    calibration puts it in the sensor pose): ``fold_flange`` does the same, the sensor's
    origin and beam expressed in robot.json's flange frame, so the parameters give the
    twin's beam exactly (its flange stays robot.json's)."""
    p = world.params.copy()
    kin = world.kinematics
    if kin is not None:
        nom = robot.kinematics
        p.geometry = np.stack([kin.alpha - nom.alpha, kin.a - nom.a, kin.beta - nom.beta,
                               kin.d - nom.d], -1)
        p.base = frame_error_of(kin.base @ np.linalg.inv(nom.base))
        if fold_flange:
            _fold_flange(p, np.linalg.inv(nom.flange) @ kin.flange)
    if options.stiffness_nm_per_rad is not None:
        k = list(options.stiffness_nm_per_rad)
        k = [None, *k, None, None, None] if len(k) == 2 else k  # J2, J3 only
        p.compliance = np.array([0.0 if v is None or v == 0 else 1.0 / v for v in k], float)
    amp: dict = {}
    phases = world.gear_phases or (0.0,) * len(options.gear)
    for (joint, a, f), phi in zip(options.gear, phases):
        key = (int(joint) - 1, int(f))
        amp[key] = amp.get(key, np.zeros(2)) + a * np.array([np.cos(phi), np.sin(phi)])
    p.gear_terms, p.gear = tuple(amp), np.array(list(amp.values()), float).reshape(-1, 2)
    if options.backlash_rad is not None:
        p.backlash = np.asarray(options.backlash_rad, float)
    if options.laser_linearity_mm > 0:  # a sin(2 pi k x + phi): (a cos phi, a sin phi) [m]
        a = options.laser_linearity_mm * 1e-3 * np.array([0.7, 0.3])
        ph = np.asarray(world.laser_phases, float)
        p.laser_orders = (1, 2)
        p.laser = np.stack([a * np.cos(ph), a * np.sin(ph)], -1)
    return p


def _fold_flange(p, T: np.ndarray) -> None:
    """The sensor of ``p`` on a flange T (4x4, in robot.json's flange frame) as a sensor on
    robot.json's flange."""
    from planecal.model.measurement import beam_direction
    z = T[:3, :3] @ beam_direction(p.phi_y, p.phi_z)
    p.sensor_origin = T[:3, :3] @ p.sensor_origin + T[:3, 3]
    p.phi_y = float(np.arccos(np.clip(z[2], -1.0, 1.0)))
    p.phi_z = float(np.arctan2(z[1], z[0]))
