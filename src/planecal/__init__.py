"""planecal: joint-offset calibration on a plane, with a MuJoCo digital twin test bench."""
import os

# planecal's linear algebra is many small dense problems (N x 12 Jacobians, 4x4 chains).
# OpenBLAS threads make those 10-40x slower on a loaded 2-core machine (measured: QR of a
# 1000 x 10 matrix 2.9 ms threaded vs 0.07 ms single-threaded); parallel studies use
# processes instead. Effective only when planecal is imported before numpy; an explicit
# setting by the user wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

__version__ = "0.1.0"

# The notebook API (planecal.api), loaded on first use so that `import planecal` stays
# cheap (no numpy, scipy or MuJoCo until a call needs them).
__all__ = ["load_samples", "rehearse", "calibrate", "validate", "SampleSet", "Rehearsal",
           "CalibratedCell", "Validation", "__version__"]
_API = frozenset(__all__) - {"__version__"}


def __getattr__(name):
    if name in _API:
        from planecal import api
        return getattr(api, name)
    raise AttributeError(f"module 'planecal' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | _API)
