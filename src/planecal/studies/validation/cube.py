"""Where the ISO 9283 cube goes: inside the calibrated region (the package docstring states
the rule). The samples' poses by the nominal model: their joints, flanges and tool points
(the laser's beam point at its measuring centre, the scene's nominal sensor pose)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.encoder import counts_to_joints
from planecal.model.kinematics import fk
from planecal.model.measurement import beam_point

EDGE_MAX_M = 0.25  # the default edge: at most this ...
EDGE_SHARE = 0.8  # ... and this share of the samples' flanges' smallest 10-90 % range
SHRINK = 0.75  # a cube that does not fit shrinks by this ...
SHRINKS = 9  # ... at most this many times (0.75^9 = 0.075 of the first edge)
CENTRES = 20  # the centre: the first of this many samples nearest the middle that the
# robot reaches from where it starts (straight or by a detour)


@dataclass(frozen=True, eq=False)
class SamplePoses:
    """The calibration samples by the nominal model: ``counts`` (N, 6), joints ``q`` (N, 6)
    [rad], flange poses ``flange`` (N, 4, 4) and tool points ``tool`` (N, 3) [m] in the
    robot frame."""
    counts: np.ndarray
    q: np.ndarray
    flange: np.ndarray
    tool: np.ndarray

    @classmethod
    def of(cls, scene, sample_counts) -> "SamplePoses":
        robot = scene.robot
        c = np.atleast_2d(np.asarray(sample_counts, np.int64))
        q = counts_to_joints(robot, c)
        T = fk(robot.kinematics, q)
        t = beam_point(scene.sensor_origin, scene.phi_y, scene.phi_z, scene.standoff_m)
        return cls(c, q, T, T[:, :3, :3] @ t + T[:, :3, 3])


def medoid_order(points: np.ndarray) -> np.ndarray:
    """The points' indices by their summed distance to all others, least first: the first
    is the medoid (one of them, in the middle of where most are)."""
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    return np.argsort(d.sum(1), kind="stable")


def medoid(points: np.ndarray) -> int:
    """The index of the points' medoid (``medoid_order``'s first)."""
    return int(medoid_order(points)[0])


def default_edge(points: np.ndarray) -> float:
    """The first edge tried [m]: ``EDGE_SHARE`` of the points' smallest range between
    their 10th and 90th percentiles, at most ``EDGE_MAX_M``. Of the samples' flange
    positions, whose hull the calibrated region is (their tool points lie within the
    sampling distances of the plates: one plate's are a slab a few cm thin)."""
    rng = np.percentile(points, 90, axis=0) - np.percentile(points, 10, axis=0)
    return float(min(EDGE_MAX_M, EDGE_SHARE * rng.min()))


def nearest_sample_m(points: np.ndarray, samples: np.ndarray) -> np.ndarray:
    """Each point's distance (m) to the nearest of ``samples`` (N, 3)."""
    return np.linalg.norm(points[:, None, :] - samples[None, :, :], axis=2).min(1)
