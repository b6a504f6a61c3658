"""The sampling application (seed 7.1): random sensor poses, step generator, laser read and
the run loop shared by the twin rehearsal (``planecal rehearse``) and the real cell
(``planecal sample``)."""
from planecal.sampling.enable import FollowingMonitor
from planecal.sampling.laserread import LaserResult, LaserSettings, read_stable
from planecal.sampling.poses import PoseGenerator, PoseSettings, SensorPose
from planecal.sampling.run import (Driver, EnableDropped, NullObserver, Observer, PathBlocked,
                                   RunSettings, RunStats, SamplingRun, load_sidecar,
                                   move_home, move_to_calibration, move_to_counts,
                                   sidecar_path)
from planecal.sampling.steps import MAX_STEP, NOMINAL_STEP, step_path

__all__ = ["Driver", "EnableDropped", "FollowingMonitor", "LaserResult", "LaserSettings",
           "MAX_STEP", "NOMINAL_STEP", "NullObserver", "Observer", "PathBlocked",
           "PoseGenerator", "PoseSettings", "RunSettings", "RunStats", "SamplingRun",
           "SensorPose", "load_sidecar", "move_home", "move_to_calibration", "move_to_counts",
           "read_stable", "sidecar_path", "step_path"]
