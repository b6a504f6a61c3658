"""Synthetic sample sets made through the analytic model (no MuJoCo): the sampling poses of
``sampling.poses`` with distances from the model at a given truth, plus Gaussian noise.

For benchmarks and studies that need many samples fast; the twin (``planecal.twin``) is
the independent, physical stand-in and is what rehearsals use.
"""
from __future__ import annotations

import numpy as np

from planecal.cell import CellParams, predict
from planecal.encoder import joints_to_counts
from planecal.sampling.poses import PoseGenerator, PoseSettings
from planecal.scene import Scene


def synthetic_samples(scene: Scene, truth: CellParams, n: int, rng: np.random.Generator,
                      noise_m: float = 0.0, settings: PoseSettings | None = None):
    """n samples (qe (n,6) int64, d (n,) m, plate (n,) int) on the scene's plates."""
    gen = PoseGenerator(scene, settings)
    q = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    qe, plate = [], []
    lo, hi = (v * 1e-3 for v in scene.laser_range_mm)
    while len(qe) < n:
        k = gen.plate_for(len(qe), rng)
        target = gen.joint_target(gen.draw(rng, k), q)
        if target is None:
            continue
        counts = joints_to_counts(scene.robot, target)
        d = predict(scene.robot, counts[None], truth, np.array([k]))[0]
        if not lo < d < hi:
            continue
        q = target
        qe.append(counts)
        plate.append(k)
    qe = np.array(qe)
    plate = np.array(plate)
    d = predict(scene.robot, qe, truth, plate) + rng.normal(0.0, noise_m, n)
    return qe, d, plate
