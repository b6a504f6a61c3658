"""A world planecal's error model does not draw (issue 31), built on the model: the twin's
own pose draw (its sampling run, ideal world: the cell drawn around the scene), the
distances of ``model.measurement.predict`` with link geometry of a UR5's class (0.3 mm,
0.5 mrad) and J2/J3 compliance, plus joint errors no robot.json names -- gear terms at 3, 5
and 7 cycles a revolution and a smooth joint-coupled deformation -- and a sample's noise;
no approach-direction column. Two pose draws of one world: one to calibrate, one to
predict."""
from __future__ import annotations

import numpy as np

from planecal.model.encoder import counts_to_joints
from planecal.model.layout import level1_layout
from planecal.model.measurement import predict_with_jacobian
from planecal.studies.rehearsal import RehearsalSettings, twin_samples

NOISE_M = 12e-6  # a sample's distance noise (the MC70's repeatability on the beam, roughly)


class OffModelWorld:
    """World ``seed`` of ``scene`` (module docstring); ``samples(pose_seed, n)`` draws one
    set of (qe, d_m, plate) from it."""

    def __init__(self, scene, seed: int, geometry_std: float = 3e-4):
        self.scene = scene
        st = RehearsalSettings(scene=scene.name, samples=20, errors="ideal", seed=seed,
                               truth_seed=seed)
        self.world, _ = st.world(0)
        rng = np.random.default_rng(seed)
        truth = self.world.params.copy()
        truth.geometry = rng.normal(0.0, geometry_std, (6, 4))
        truth.geometry[:, 0] *= 1.7  # twists: 0.5 mrad
        truth.geometry[:, 2] = 0.0
        truth.compliance = np.array([0.0, 2e-7, 3.3e-7, 0.0, 0.0, 0.0])
        self.truth = truth
        self.phase = rng.uniform(0.0, 2.0 * np.pi, 8)
        self.seed = seed

    def joint_error(self, q: np.ndarray) -> np.ndarray:
        """(N, 6) [rad]: gear terms at orders no robot.json names (J2 3, J3 5, J4 7, J5 3
        cycles a revolution) and a deformation coupling J2, J3 and J5."""
        e = np.zeros_like(q)
        ph = self.phase
        for j, f in ((1, 3), (2, 5), (3, 7), (4, 3)):
            e[:, j] += 1e-4 * np.sin(f * q[:, j] + ph[3 + j])
        e[:, 1] += 1.5e-4 * np.sin(q[:, 1] + q[:, 2] + ph[0])
        e[:, 2] += 1.5e-4 * np.cos(q[:, 2] - 0.5 * q[:, 4] + ph[1])
        return e

    def samples(self, pose_seed: int, n: int = 150):
        """(qe, d_m, plate): the twin's pose draw ``pose_seed``, the world's distances."""
        st = RehearsalSettings(scene=self.scene.name, samples=n, errors="ideal",
                               seed=pose_seed, truth_seed=self.seed)
        qe, _, plate, _, _ = twin_samples(self.scene, self.world, st, pose_seed)
        q = counts_to_joints(self.scene.robot, qe)
        d, J = predict_with_jacobian(self.scene.robot, qe, self.truth, plate,
                                     level1_layout(self.truth.n_planes))
        noise = np.random.default_rng(pose_seed + 7).normal(0.0, NOISE_M, len(qe))
        return qe, d + np.einsum("nj,nj->n", J[:, :6], self.joint_error(q)) + noise, plate
