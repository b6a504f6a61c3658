"""The ZS-LD80 model: a MuJoCo ray along the ``laser`` site's +z, then the sensor's
window and noise.

* Ray: ``mujoco.mj_ray`` from the site origin along its z axis (a unit vector, so the
  returned distance is in metres), ``flg_static=1`` (the plates are on the world body),
  a geomgroup mask that keeps only group 0 (plates, stands, floor, obstacles) and
  ``bodyexclude`` = the tool body. It uses the data's last kinematics.
* Window: a reading outside ``window_mm`` (65-95 mm, the ZS-LD80's 80 +- 15 mm) or no
  hit gives None, like the sensor's raw 0.
* Noise: Gaussian, ``noise_mm`` std (default 0.001 mm, the ZS-LD80's resolution; its
  repeatability is ~2 um); optional quantisation to ``quantum_mm``.
"""
from __future__ import annotations

import mujoco
import numpy as np

NOISE_BLOCK = 4096


class LaserModel:
    def __init__(self, window_mm=(65.0, 95.0), noise_mm: float = 0.001,
                 quantum_mm: float | None = None, rng: np.random.Generator | None = None):
        self.lo, self.hi = float(window_mm[0]), float(window_mm[1])
        self.noise_mm = float(noise_mm)
        self.quantum_mm = quantum_mm
        self.rng = rng if rng is not None else np.random.default_rng()
        # the current block of draws, used from the end: numpy for batches, a list
        # (made on first use) for single readings; ``_left`` values not used yet
        self._block = np.zeros(0)
        self._list: list[float] | None = None
        self._left = 0

    def _refill(self) -> None:
        self._block = self.rng.normal(0.0, self.noise_mm, NOISE_BLOCK)
        self._list = None
        self._left = NOISE_BLOCK

    def _next_noise(self) -> float:
        if not self._left:
            self._refill()
        if self._list is None:
            self._list = self._block.tolist()
        self._left -= 1
        return self._list[self._left]

    def _take_noise(self, n: int) -> np.ndarray:
        """The next ``n`` noise values in the order ``n`` calls of ``reading`` use them."""
        if n <= 0:
            return np.zeros(0)
        if n <= self._left:  # one block: its values from the end
            hi = self._left
            self._left = lo = hi - n
            return self._block[hi - 1:lo - 1 if lo else None:-1].copy()
        out = np.empty(n)
        i = 0
        while i < n:
            if not self._left:
                self._refill()
            k = min(n - i, self._left)
            out[i:i + k] = self._take_noise(k)
            i += k
        return out

    def readings(self, distance_m: np.ndarray) -> np.ndarray:
        """Readings [mm] for true distances [m] (NaN or < 0, as mj_ray's -1: no hit),
        NaN where ``reading`` gives None. Same values and noise stream as one
        ``reading`` call per element."""
        return self.readings_mm(np.multiply(distance_m, 1000.0))

    def readings_mm(self, mm: np.ndarray) -> np.ndarray:
        """``readings`` from the true distances in mm (``distance_m * 1000``, NaN or < 0:
        no hit), in place: the readings are ``mm`` itself."""
        valid = None  # the hits, before noise and quantisation
        if self.noise_mm > 0.0:
            valid = mm >= 0.0  # False for NaN and misses
            k = int(np.count_nonzero(valid))
            if k == len(mm):
                mm += self._take_noise(k)
            elif k:
                mm[valid] += self._take_noise(k)
        elif self.lo < 0.0:
            valid = mm >= 0.0
        if self.quantum_mm:
            mm = np.round(mm / self.quantum_mm) * self.quantum_mm
        if self.lo >= 0.0:  # misses (< 0) are below the window; NaN compares False
            mm[(mm < self.lo) | (mm > self.hi)] = np.nan
        else:
            mm[~valid | (mm < self.lo) | (mm > self.hi)] = np.nan
        return mm

    def reading(self, distance_m: float | None) -> float | None:
        """mm reading for a true distance [m] (None: no hit)."""
        if distance_m is None:
            return None
        mm = distance_m * 1000.0
        if self.noise_mm > 0.0:
            mm += self._next_noise()
        if self.quantum_mm:
            mm = round(mm / self.quantum_mm) * self.quantum_mm
        if mm < self.lo or mm > self.hi:
            return None
        return mm


class RayCaster:
    """Casts the beam in a compiled model; ``cast()`` -> (distance m or None, geom id)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, site_id: int,
                 exclude_body: int, groups=(0,)):
        self.model, self.data = model, data
        self.site_id = site_id
        self.exclude_body = int(exclude_body)
        self.mask = np.zeros(6, np.uint8)
        self.mask[list(groups)] = 1
        self.geomid = np.zeros(1, np.int32)
        self._pnt = data.site_xpos[site_id]
        self._mat = data.site_xmat[site_id]
        self._vec = np.zeros(3)

    def cast(self):
        m = self._mat
        v = self._vec
        v[0], v[1], v[2] = m[2], m[5], m[8]
        d = mujoco.mj_ray(self.model, self.data, self._pnt, v, self.mask, 1,
                          self.exclude_body, self.geomid)
        if d < 0:
            return None, -1
        return d, int(self.geomid[0])
