"""A run for an engine's workers that reports as it goes (``test_progress``): importable
by a Dask worker, as a study's run is."""
import time

from planecal.base.progress import report


def reporting_run(x: int) -> int:
    """Reports six steps 0.3 s apart (a worker sends at most one report every 0.25 s),
    then returns 2 x."""
    for k in range(6):
        report(k + 1, 6, "steps")
        time.sleep(0.3)
    return 2 * x
