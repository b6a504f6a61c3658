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
