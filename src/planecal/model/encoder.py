"""Encoder model with wrist coupling (MODEL-NOTES, seed 6.1.1 and 6.4.1).

actuator angle  x_i = (qe_i - qe0_i) / g_i
joint angle     q   = C x          (C: identity but for the wrist coupling terms)
Joint offsets delta (rad) add to q; the encoder offsets that realise them are
qe0' = qe0 - g * (C^-1 delta).
"""
from __future__ import annotations

import numpy as np

from planecal.model.robot import Robot


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


def encoder_zero_counts(robot: Robot, delta: np.ndarray, qe0: np.ndarray | None = None,
                        q_ref: np.ndarray | None = None):
    """The encoder offsets an operator enters into the controller to realise joint offsets
    ``delta`` (rad), as integers: ``qe0' = rint(qe0 - g (C^-1 delta))``, from the encoder
    offsets ``qe0`` the offsets were identified with (default robot.json's). The wrist
    coupling applies: a delta4 or delta5 moves q5's and q6's zeros even with delta6 = 0.

    Returns (qe0' int64 (6,), residual (6,) [rad]: the joint offsets the integers realise
    minus ``delta``, flange displacement [m] of that residual at joint angles ``q_ref``
    (default all zero): |J_v residual|)."""
    from planecal.model.kinematics import jacobian
    qe0 = robot.qe0 if qe0 is None else np.asarray(qe0, float)
    exact = offsets_to_qe0(robot, delta, qe0)
    counts = np.rint(exact).astype(np.int64)
    realised = (qe0 - counts) / robot.gains @ robot.coupling.T  # C (qe0 - qe0') / g
    residual = realised - np.asarray(delta, float)
    q_ref = np.zeros(robot.n_joints) if q_ref is None else np.asarray(q_ref, float)
    tcp = float(np.linalg.norm(jacobian(robot.kinematics, q_ref)[:3] @ residual))
    return counts, residual, tcp
