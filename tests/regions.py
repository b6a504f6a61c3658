"""A calibrated region for tests that give targets without samples: the joint ranges of the
given poses grown by a margin, and a flange hull so large that only the joint ranges decide
(``estimation.compensate.Region`` needs a hull)."""
import numpy as np

from planecal.estimation.compensate import Region


def joint_region(q, margin=0.01, hull_m=100.0):
    q = np.atleast_2d(q)
    facets = np.array([[*n, -hull_m] for n in np.vstack([np.eye(3), -np.eye(3)])])
    return Region(q.min(0) - margin, q.max(0) + margin, facets, len(q), "test", 0.0, 0.0)
