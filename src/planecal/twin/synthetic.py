"""Synthetic sample sets made through the analytic model (no MuJoCo): the sampling run's
random poses (``sampling.planner.Planner``, without collision checks) collected by the
collect core, each measured by the model at a given truth (the laser window applied),
plus Gaussian noise.

For benchmarks and studies that need many samples fast; the twin (``planecal.twin``) is
the independent, physical stand-in and is what rehearsals use.
"""
from __future__ import annotations

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict
from planecal.sampling.collect import Acquired, Cursor, MemoryRecorder, Tally, collect
from planecal.sampling.laserread import LaserResult
from planecal.sampling.planner import NoCollisionChecks, Plan, Planner
from planecal.sampling.poses import PoseSettings
from planecal.model.scene import Scene


class ModelAcquirer:
    """The distance the analytic model gives at the target for the truth, None outside
    the laser's window."""
    idle = None

    def __init__(self, scene: Scene, truth: CellParams):
        self.robot, self.truth = scene.robot, truth
        self.lo, self.hi = scene.laser_range_mm

    def acquire(self, plan: Plan) -> Acquired:
        mm = float(predict(self.robot, plan.qe_goal[None], self.truth,
                           np.array([plan.plate]))[0]) * 1e3
        if not self.lo < mm < self.hi:
            return Acquired(plan.qe_goal, LaserResult(None, "out_of_range", 1, None, 1))
        return Acquired(plan.qe_goal, LaserResult(mm, "stable", 1, 0.0, 0))


def synthetic_samples(scene: Scene, truth: CellParams, n: int, rng: np.random.Generator,
                      noise_m: float = 0.0, settings: PoseSettings | None = None):
    """n samples (qe (n,6) int64, d (n,) m, plate (n,) int) on the scene's plates."""
    pose = settings or PoseSettings(cone_deg=scene.cone_deg, distance_mm=tuple(scene.distance_mm))
    planner = Planner(scene, pose, NoCollisionChecks())
    rec, tally = MemoryRecorder(n), Tally()
    q0 = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    collect(planner, ModelAcquirer(scene, truth), rec, n,
            Cursor(q0, np.random.default_rng(rng.integers(2 ** 63)).bit_generator.state),
            tally, max_attempts=20 * n)
    if tally.status != "complete":
        raise RuntimeError(f"synthetic samples: {tally.reason}")
    qe, d, plate, _ = rec.arrays()  # the model moves no robot: the direction is unknown (0)
    return qe, d + rng.normal(0.0, noise_m, n), plate
