"""Where the ISO 9283 cubes go (the package docstring states both rules): the near-sample
cube, centred on a calibration sample inside the calibrated region, and the standard's
cube, the largest cube inside the samples' flange hull (ISO 9283's cube: the largest in the
part of the working space the work uses). The samples' poses by the nominal model: their
joints, flanges and tool points (the laser's beam point at its measuring centre, the
scene's nominal sensor pose)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.base.errors import InputError
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


NEAR_RULE = ("centred on the tool point of the samples' medoid (the sample whose tool point "
             "is nearest all the others in sum; the next nearer the middle where the robot "
             "has no path there from its start, or where no cube fits), with that sample's "
             "flange orientation; edge 80 % of the sample flange positions' smallest "
             "10-90 % range (at most 250 mm), "
             "shrunk by 0.75 until every model's five poses are reachable, collision-free "
             "and inside the calibrated region (the samples' flange hull + 50 mm, their "
             "joint ranges + 2 deg)")
STANDARD_RULE = ("ISO 9283's cube: the largest cube with edges parallel to the robot's axes "
                 "inside the region the cell's work uses, here the samples' flange hull (a "
                 "linear program over its facets), at the flange orientation of one of the "
                 "20 samples nearest its centre (the first that fits); shrunk by 0.75 about "
                 "the same centre until every model's five poses are reachable, "
                 "collision-free and inside the samples' joint ranges + 2 deg")


def largest_cube(facets: np.ndarray) -> tuple[np.ndarray, float]:
    """The largest cube with edges parallel to the axes inside the convex polytope
    ``n . p + b <= 0`` (``facets`` (F, 4), unit outward normals): (centre (3,), edge) [m],
    by a linear program (a cube's worst corner against a facet lies ``h |n|_1`` beyond its
    centre). InputError where the polytope holds no cube."""
    from scipy.optimize import linprog
    n, b = facets[:, :3], facets[:, 3]
    A = np.hstack([n, np.abs(n).sum(1, keepdims=True)])
    res = linprog(c=[0, 0, 0, -1.0], A_ub=A, b_ub=-b,
                  bounds=[(None, None)] * 3 + [(0, None)], method="highs")
    if not res.success or res.x[3] <= 0:
        raise InputError("no cube fits inside the samples' flange hull")
    return np.asarray(res.x[:3], float), float(2 * res.x[3])


def place_near(scene, commanders, samples, st, mover, region, checker):
    """The near-sample cube's ISO plan (``NEAR_RULE``) and the sample it is centred on; a
    cube of the user's (``st.cube_edge_m``) is not shrunk, and may reach outside the
    region (the plan says how far)."""
    from planecal.studies.validation.iso9283 import plan_iso
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
            try:
                return plan_iso(scene, commanders, center, edge, R, q_ref, mover, region,
                                checker, inside=not given), k
            except InputError as e:
                last = e
    raise last


def place_standard(scene, commanders, samples, mover, region, checker):
    """The standard's cube's ISO plan (``STANDARD_RULE``), the sample whose orientation it
    takes and the largest cube's edge in the hull [m] (before any shrink)."""
    from planecal.studies.validation.iso9283 import plan_iso
    centre_f, top = largest_cube(region.facets)
    t = np.asarray(commanders[0].tool_in_flange, float)  # the nominal model's tool point
    near = np.argsort(np.linalg.norm(samples.flange[:, :3, 3] - centre_f, axis=1),
                      kind="stable")[:CENTRES]
    last = None
    for edge in top * SHRINK ** np.arange(SHRINKS + 1):
        for k in near:
            R = samples.flange[k, :3, :3]
            try:  # the flange cube stays where the program put it, whatever R
                return plan_iso(scene, commanders, centre_f + R @ t, float(edge), R,
                                samples.q[k], mover, region, checker), int(k), top
            except InputError as e:
                last = e
    raise InputError(f"the standard's cube: none fits ({last})")


def cube_record(plan, samples, region, rule: str, sample: int) -> dict:
    """What a result says of a cube: its rule, centre, edge, the sample it is centred on
    or takes its orientation from, each ISO point's distance to the nearest sample's tool
    point, and how far it reaches outside the calibrated region."""
    rank = int(np.flatnonzero(medoid_order(samples.tool) == sample)[0])
    return {"rule": rule, "center_m": plan.center_m, "edge_m": plan.edge_m,
            "sample_index": sample, "medoid_rank": rank,
            "nearest_sample_mm": nearest_sample_m(plan.points_m, samples.tool) * 1e3,
            "outside_region_mm": plan.outside_mm, "outside_region_deg": plan.outside_deg,
            "inside_region": bool(not plan.outside_mm.any() and not plan.outside_deg.any()),
            "region": region.to_dict()}
