"""The sampling application (seed 7.1): random sensor poses, step generator, laser read, the
collect core and the run loop shared by the twin rehearsal (``planecal rehearse``), the
real cell (``planecal sample``) and the studies.

Modules, top to bottom: ``poses`` (random sensor poses, IK choice), ``steps`` (step
generator), ``laserread`` (stable laser read), ``observer`` (hooks), ``driver`` (the
link's delta, checked moves), ``planner`` (plans: random, a pose list, in the
background), ``collect`` (plan -> acquire -> account), ``runfiles`` (sample file, sidecar,
lock), ``run`` (the run: collect into the files,
resume), ``session`` (start/end moves, progress), ``enable`` (the real cell's enable
signal)."""
from planecal.sampling.collect import (Cursor, DriveAcquirer, MemoryRecorder, RestAcquirer,
                                       Tally, collect)
from planecal.sampling.driver import (Driver, EnableDropped, PathBlocked, move_home,
                                      move_to_calibration, move_to_counts)
from planecal.sampling.enable import FollowingMonitor
from planecal.sampling.laserread import LaserResult, LaserSettings, read_stable
from planecal.sampling.observer import NullObserver, Observer
from planecal.sampling.planner import ListPlanner, Plan, Planner
from planecal.sampling.poses import PoseGenerator, PoseSettings, SensorPose
from planecal.sampling.run import RunSettings, RunStats, SamplingRun
from planecal.sampling.runfiles import load_sidecar, sidecar_path
from planecal.sampling.steps import MAX_STEP, step_path

__all__ = ["Cursor", "DriveAcquirer", "Driver", "EnableDropped", "FollowingMonitor",
           "LaserResult", "LaserSettings", "ListPlanner", "MAX_STEP", "MemoryRecorder",
           "NullObserver", "Observer", "PathBlocked", "Plan", "Planner",
           "PoseGenerator", "PoseSettings", "RestAcquirer", "RunSettings", "RunStats",
           "SamplingRun", "SensorPose", "Tally", "collect", "load_sidecar", "move_home",
           "move_to_calibration", "move_to_counts", "read_stable", "sidecar_path",
           "step_path"]
