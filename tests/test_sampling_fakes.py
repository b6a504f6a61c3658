"""Fakes for the sampling tests (no tests here): an ideal-servo RobotLink + Laser built on
the analytic distance model (``cell.predict``, limited to the plate rectangles) with the
ZS-LD80 window, a no-op collision checker (unit tests only: rehearse always checks
collisions), and enable signals."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import plane_distance, sensor_in_base
from planecal.model.encoder import counts_to_joints
from planecal.model.encoder import joints_to_counts
from planecal.model.scene import Scene, nominal_params

TRUE_OFFSETS = np.array([0.0, 0.0008, -0.0012, 0.0007, 0.0005, 0.0])


def perturbed_truth(scene: Scene, offsets=TRUE_OFFSETS) -> CellParams:
    p = nominal_params(scene)
    p.joint_offsets = np.asarray(offsets, float)
    p.sensor_origin = p.sensor_origin + np.array([0.0006, -0.0004, 0.0008])
    p.phi_y += 0.004
    p.phi_z -= 0.003
    p.planes = p.planes * (1 + 0.002)
    return p


class FakeCell:
    """RobotLink + Laser: commanded = reference + delta is reached at once (ideal servo);
    the laser reads the model distance on the true parameters, None outside 65-95 mm."""

    def __init__(self, scene: Scene, truth: CellParams | None = None, start_q=None,
                 start_counts=None, noise_mm: float = 0.0, seed: int = 0, window=(65.0, 95.0),
                 record: bool = True):
        self.robot = scene.robot
        self.truth = truth if truth is not None else perturbed_truth(scene)
        if start_counts is None:
            start_counts = joints_to_counts(self.robot, scene.calibration_q if start_q is None
                                            else start_q)
        self.ref = np.asarray(start_counts, np.int64).copy()
        self.cur = self.ref.copy()
        self.prev = np.zeros(6, np.int64)
        self.sent: list[np.ndarray] = []
        self.record = record
        self.max_jump = 0
        self.noise_mm = noise_mm
        self.rng = np.random.default_rng(seed)
        self.window = window
        self.reads = 0
        self.closed = False
        # plate rectangles on the true planes: a beam counts only where it meets a plate
        self.frames = [pl.frame(n) for pl, n in zip(scene.plates, self.truth.planes)]
        self.sizes = [pl.size for pl in scene.plates]

    # RobotLink
    def exchange(self, delta):
        delta = np.asarray(delta, np.int64)
        jump = int(np.max(np.abs(delta - self.prev)))
        self.max_jump = max(self.max_jump, jump)
        self.prev = delta.copy()
        if self.record:
            self.sent.append(self.prev)
        self.cur = self.ref + delta
        return self.ref.copy(), self.cur.copy()

    # Laser
    def true_mm(self, qe=None) -> float:
        qe = self.cur if qe is None else qe
        o_b, z_b = sensor_in_base(self.robot, counts_to_joints(self.robot, qe), self.truth)
        best = float("nan")
        for k, (F, size) in enumerate(zip(self.frames, self.sizes)):
            d = float(plane_distance(self.truth.planes[k], o_b, z_b))
            uv = F[:3, :2].T @ (o_b + d * z_b - F[:3, 3])
            if d > 0 and np.all(uv >= 0) and np.all(uv <= size) and not d * 1e3 >= best:
                best = d * 1e3
        return best

    def read(self):
        self.reads += 1
        d = self.true_mm()
        if not (self.window[0] <= d <= self.window[1]):
            return None
        return d + (self.rng.normal(0, self.noise_mm) if self.noise_mm else 0.0)

    def close(self):
        self.closed = True


@dataclass
class Clear:
    ok: bool = True
    min_distance_m: float = 1.0
    pair: tuple | None = None


class NullChecker:
    """No collision checking: unit tests of the loop only."""

    def check_config(self, q):
        return Clear()

    def check_path(self, q0, q1):
        return Clear()


class DropAfter:
    """Enable signal that drops after ``n`` calls (i.e. before the (n+1)-th tick)."""

    def __init__(self, n: int):
        self.n = n
        self.calls = 0
        self.reason = "test: dead-man switch released"

    def enabled(self) -> bool:
        self.calls += 1
        return self.calls <= self.n
