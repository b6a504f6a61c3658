"""Plane representations (seed 6.4.2, appendix D): the plane vector n~ (n~ . p = 1 on the
plane; it cannot describe a plane through the origin), a point and a unit normal, and a
plane moved between frames."""
from __future__ import annotations

import numpy as np

def n_tilde_from_point_normal(point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """n~ = n (p.n)/|p.n|^2 for the plane through ``point`` with unit ``normal``."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    h = float(np.dot(point, n))
    if abs(h) < 1e-9:
        raise ValueError("plane passes through the base origin: n~ cannot describe it")
    return n / h


def point_normal_from_n_tilde(n_tilde: np.ndarray):
    """Closest plane point to the origin and the unit normal pointing away from the origin."""
    n_tilde = np.asarray(n_tilde, float)
    nn = float(n_tilde @ n_tilde)
    return n_tilde / nn, n_tilde / np.sqrt(nn)


def transform_n_tilde(T: np.ndarray, n_tilde: np.ndarray) -> np.ndarray:
    """Express a plane given in frame P by n~ in frame B, with T = B_T_P (appendix D)."""
    p, nhat = point_normal_from_n_tilde(n_tilde)
    return n_tilde_from_point_normal(T[:3, :3] @ p + T[:3, 3], T[:3, :3] @ nhat)


def separation(n_a: np.ndarray, n_b: np.ndarray) -> float:
    """Signed distance of plane b from plane a along a's normal (n^ = n~/|n~|, pointing
    away from the origin): (n^_a . p_b) - 1/|n~_a| for a point p_b of b; for parallel planes
    the gap between them."""
    p_b, _ = point_normal_from_n_tilde(n_b)
    n_a = np.asarray(n_a, float)
    return float(n_a @ p_b / np.linalg.norm(n_a) - 1.0 / np.linalg.norm(n_a))


def parallel_rows(n_a: np.ndarray, n_b: np.ndarray, separation_m: float):
    """A length reference between two parallel planes (a stepped artefact): the residuals
    g (4,) = [n^_b - n^_a (3, the tilt between them, rad), 1/|n~_b| - 1/|n~_a| - s (the
    gap along the normal minus the reference's s, m)] and their derivatives by n~_a and
    n~_b (4, 3) each. Both planes on the same side of the origin, facing the same way
    (n~_b = n~_a / (1 + s |n~_a|) when g = 0)."""
    out = []
    for n in (np.asarray(n_a, float), np.asarray(n_b, float)):
        k = np.linalg.norm(n)
        u = n / k
        out.append((u, 1.0 / k, (np.eye(3) - np.outer(u, u)) / k, -n / k ** 3))
    (ua, ra, dua, dra), (ub, rb, dub, drb) = out
    g = np.concatenate([ub - ua, [rb - ra - separation_m]])
    Ga = np.vstack([-dua, -dra[None]])
    Gb = np.vstack([dub, drb[None]])
    return g, Ga, Gb
