"""The ZS-LD80 model's settings and its noise stream (the reading itself is computed in
``ticks.laser``, one implementation for one tick or many).

* Beam: along the ``laser`` site's +z (``beam.BeamCaster``), seeing only the static cell
  (geom group 0: plates, stands, floor, obstacles); the tool is excluded.
* Window: a reading outside ``window_mm`` (65-95 mm, the ZS-LD80's 80 +- 15 mm) or no
  hit gives None, like the sensor's raw 0.
* Linearity: a smooth error of the reading over the window, ``linearity_mm`` x (0.7
  sin(2 pi x + p1) + 0.3 sin(4 pi x + p2)), x the place in the window, the phases drawn
  with the truth (the ZS-LD80's linearity is +-0.1 % of its 30 mm full scale: +-0.03 mm).
* Noise: Gaussian, ``noise_mm`` std (default 0.001 mm, the ZS-LD80's resolution; its
  repeatability is ~2 um), drawn ahead in blocks of ``NOISE_BLOCK`` and used from the end
  of a block; optional quantisation to ``quantum_mm``.
"""
from __future__ import annotations

import numpy as np

NOISE_BLOCK = 4096
SEEN_GROUPS = (0,)  # geom groups the beam sees


class LaserNoise:
    """The laser model's settings and its noise block (``block[left - 1]`` is next)."""

    def __init__(self, window_mm=(65.0, 95.0), noise_mm: float = 0.001,
                 quantum_mm: float | None = None, rng: np.random.Generator | None = None,
                 linearity_mm: float = 0.0, phases=(0.0, 0.0)):
        self.lo, self.hi = float(window_mm[0]), float(window_mm[1])
        self.noise_mm = float(noise_mm)
        self.quantum_mm = float(quantum_mm or 0.0)
        a = float(linearity_mm)
        self.lin = np.array([0.7 * a, phases[0], 0.3 * a, phases[1]])
        self.rng = rng if rng is not None else np.random.default_rng()
        self.block = np.zeros(0)
        self.left = 0

    def refill(self) -> None:
        self.block = self.rng.normal(0.0, self.noise_mm, NOISE_BLOCK)
        self.left = NOISE_BLOCK


def seen_mask() -> np.ndarray:
    """The geomgroup mask of the groups the beam sees (MuJoCo's mjNGROUP = 6 entries)."""
    mask = np.zeros(6, np.uint8)
    mask[list(SEEN_GROUPS)] = 1
    return mask
