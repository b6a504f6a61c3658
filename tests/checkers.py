"""Collision checkers the planner tests put in place of the cell's (test-only)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np


class NoWayTo:
    """The cell's own checker (``world``), with every path to or from one configuration
    blocked, and from each configuration whole turns away from it (the same flange pose: a
    pose list serves a pose blocked every way a turn away)."""

    def __init__(self, world, q_bad):
        self.world, self.q_bad = world, np.asarray(q_bad)

    def check_config(self, q):
        return self.world.check_config(q)

    def check_path(self, q0, q1):
        if any(np.allclose(np.angle(np.exp(1j * (np.asarray(q) - self.q_bad))), 0, atol=1e-9)
               for q in (q0, q1)):
            return SimpleNamespace(ok=False, pair=("wall", "q_bad"))
        return self.world.check_path(q0, q1)
