"""The MuJoCo digital twin of the MC70 cell (robot behind an FD11 link + ZS-LD80 laser).

    from planecal.twin import Twin, TwinOptions
    twin = Twin("thesis_final", seed=3)            # hidden truth drawn from seed 3
    ref, cur = twin.exchange(np.zeros(6, np.int64))  # one 10 ms tick
    mm = twin.read()                                 # laser reading or None
    ref, counts, mm = twin.run(deltas)               # many ticks: (N, 6) deltas

Modules: ``core`` (Twin), ``ticks`` (the tick, written once: compiled and interpreted),
``errors`` (joint-side error sources), ``mjcf`` (MjSpec builders), ``truth`` (hidden
truth), ``laser`` (sensor model settings, noise), ``beam`` (the beams of many joint
states in one MuJoCo call), ``export`` (scene MJCF for a viewer).
"""
from planecal.twin.core import EncoderJumpError, Hit, Twin
from planecal.twin.options import TwinOptions
from planecal.twin.truth import Tolerances, draw_truth, load_truth

__all__ = ["Twin", "TwinOptions", "Hit", "EncoderJumpError", "Tolerances", "draw_truth",
           "load_truth"]
