"""Encoder model with wrist coupling (MODEL-NOTES, seed 6.1.1 and 6.4.1).

actuator angle  x_i = (qe_i - qe0_i) / g_i
joint angle     q   = C x          (C: identity but for the wrist coupling terms)
Joint offsets delta (rad) add to q; the encoder offsets that realise them are
qe0' = qe0 - g * (C^-1 delta).
"""
from __future__ import annotations

import numpy as np

from planecal.robot import Robot


def counts_to_joints(robot: Robot, qe: np.ndarray, qe0: np.ndarray | None = None) -> np.ndarray:
    """Encoder counts (..., 6) -> joint angles q (..., 6) [rad]."""
    qe0 = robot.qe0 if qe0 is None else np.asarray(qe0, float)
    x = (np.asarray(qe, float) - qe0) / robot.gains
    return x @ robot.coupling.T


def joints_to_counts(robot: Robot, q: np.ndarray, qe0: np.ndarray | None = None,
                     rounded: bool = True) -> np.ndarray:
    """Joint angles q (..., 6) [rad] -> encoder counts; int64 when ``rounded``."""
    qe0 = robot.qe0 if qe0 is None else np.asarray(qe0, float)
    x = np.asarray(q, float) @ np.linalg.inv(robot.coupling).T
    qe = robot.gains * x + qe0
    return np.rint(qe).astype(np.int64) if rounded else qe


def offsets_to_qe0(robot: Robot, delta: np.ndarray, qe0: np.ndarray | None = None) -> np.ndarray:
    """Encoder offsets qe0' that make counts_to_joints(qe, qe0') = q + delta (float counts)."""
    qe0 = robot.qe0 if qe0 is None else np.asarray(qe0, float)
    return qe0 - robot.gains * np.linalg.solve(robot.coupling, np.asarray(delta, float))


def counts_in_range(robot: Robot, qe: np.ndarray) -> np.ndarray:
    qe = np.asarray(qe)
    return np.all((qe >= 0) & (qe < (1 << robot.encoder_bits)), axis=-1)
