"""The twin's hidden truth: the cell's real parameters (a ``CellParams``), drawn from a
seed around a scene's nominal values, or read from a parameter file (params.py format).

Calibration code never reads this; tests compare its result with it.

Default tolerances (``Tolerances``), each a hard bound, drawn uniformly:
* joint offsets delta_2..delta_5: |delta_i| <= 3 mrad. delta_1 and delta_6 stay 0
  (no plane calibration can see them: delta_1 is a rotation of the plates about the
  base axis, delta_6 a roll of the sensor) unless ``offsets_all=True``; ``offset_rad``
  may also give one bound per joint (an error profile's).
* sensor origin: a displacement of length <= 10 mm in a uniformly random direction.
* sensor angles: phi_y and phi_z each moved by <= 0.035 rad, so the beam direction
  moves by <= 0.05 rad.
* each plane: its point (the plate centre on the nominal plane) moved by <= 10 mm, its
  normal tilted by <= 0.05 rad about a random in-plane axis; n~ recomputed from those.
* a known length (the scene's ``references``: a stepped artefact) moves as one body: its
  second plate is its first's true plane moved by the separation (plus a draw of its std)
  and tilted by a draw of its parallelism std.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.planes import n_tilde_from_point_normal, point_normal_from_n_tilde
from planecal.base.errors import InputError
from planecal.model.kinematics import Kinematics
from planecal.io.params import load_params
from planecal.model.scene import Scene, nominal_params


@dataclass(frozen=True)
class Tolerances:
    offset_rad: float | tuple = 3e-3
    offsets_all: bool = False  # also perturb delta_1 and delta_6
    origin_m: float = 0.010
    angle_rad: float = 0.035
    plane_point_m: float = 0.010
    plane_normal_rad: float = 0.05

    def offset_bounds(self) -> np.ndarray:
        """The bound of each joint's offset (6,)."""
        if np.ndim(self.offset_rad):
            return np.asarray(self.offset_rad, float).reshape(6)
        b = np.full(6, float(self.offset_rad))
        if not self.offsets_all:
            b[[0, 5]] = 0.0
        return b


@dataclass(frozen=True)
class Truth:
    """A world's hidden truth: the cell (``params``: joint offsets, sensor pose, planes),
    the robot's true geometry (``kinematics``; None: robot.json's exactly), the phases of
    its gear errors (one per harmonic of the twin's options) and of the laser's linearity
    error."""
    params: CellParams
    kinematics: Kinematics | None = None
    gear_phases: tuple = ()
    laser_phases: tuple = (0.0, 0.0)


def _ball(rng, radius):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v) * radius * rng.uniform() ** (1 / 3)


def _tilt(rng, n, max_angle):
    """Rotate unit n by an angle <= max_angle about a random axis perpendicular to it."""
    a = rng.normal(size=3)
    a -= (a @ n) * n
    a /= np.linalg.norm(a)
    ang = rng.uniform(0, max_angle)
    return np.cos(ang) * n + np.sin(ang) * np.cross(a, n)


def draw_truth(scene: Scene, seed: int = 0, tol: Tolerances = Tolerances()) -> CellParams:
    """Hidden truth around the scene's nominal parameters (see the module docstring)."""
    rng = np.random.default_rng(seed)
    nom = nominal_params(scene)
    b = tol.offset_bounds()
    delta = rng.uniform(-b, b, 6) + 0.0  # (+ 0.0: no -0.0 where a bound is 0)
    origin = nom.sensor_origin + _ball(rng, tol.origin_m)
    phi_y = nom.phi_y + rng.uniform(-tol.angle_rad, tol.angle_rad)
    phi_z = nom.phi_z + rng.uniform(-tol.angle_rad, tol.angle_rad)
    planes = []
    for plate in scene.plates:
        _, nhat = point_normal_from_n_tilde(plate.n_tilde)
        p = plate.center() + _ball(rng, tol.plane_point_m)
        planes.append(n_tilde_from_point_normal(p, _tilt(rng, nhat, tol.plane_normal_rad)))
    for ref in scene.references:  # a stepped artefact moves as one body
        a, b = ref.plates
        planes[b] = _step(rng, planes[a], ref)
    return CellParams(delta, origin, phi_y, phi_z, np.array(planes),
                      laser_range_m=nom.laser_range_m)


def _step(rng, n_a: np.ndarray, ref) -> np.ndarray:
    """Plate b of a known length (``model.scene.LengthReference``) as the artefact makes it:
    plate a's true plane moved by the true separation (the reference's, plus a draw of its
    std) along a's normal, tilted by a draw of the parallelism std."""
    p_a, n = point_normal_from_n_tilde(n_a)
    gap = ref.separation_m + rng.normal(0.0, ref.std_m)
    return n_tilde_from_point_normal(p_a + gap * n,
                                     _tilt(rng, n, abs(rng.normal(0.0, ref.parallel_std_rad))))


def load_truth(scene: Scene, path) -> CellParams:
    """A truth file (params.py format); it must hold one plane per plate, and be of the
    scene's robot where it records one (``save_truth``)."""
    p = load_params(path, scene.robot)
    if p.n_planes != len(scene.plates):
        raise InputError(f"{path}: {p.n_planes} planes for a scene with {len(scene.plates)} plates")
    return p


def resolve_truth(scene: Scene, truth=None, seed: int = 0) -> Truth:
    """``truth`` as given: None -> draw_truth(scene, seed); a Truth; a CellParams; a path;
    or the string 'nominal' (truth = the nominal values)."""
    if isinstance(truth, Truth):
        params = truth.params
    elif truth is None:
        return Truth(draw_truth(scene, seed))
    elif isinstance(truth, CellParams):
        params = truth
    elif isinstance(truth, str) and truth == "nominal":
        return Truth(nominal_params(scene))
    else:
        return Truth(load_truth(scene, truth))
    if params.n_planes != len(scene.plates):
        raise InputError(f"truth: {params.n_planes} planes for {len(scene.plates)} plates")
    return truth if isinstance(truth, Truth) else Truth(params.copy())
