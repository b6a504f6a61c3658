"""What the studies share: the map of a pure run function over run descriptions (through
``studies.distributed.Engine``), progress on stderr,
terminal tables, the per-sample noise model of the twin and the covariance formulas
(Cramer-Rao bound, OLS sandwich) the studies compare with.

Noise model of one sample (SI): the twin's distance error is
  e_i = sum_j (dd/dq_j)_i eps_j + laser_i
with eps ~ N(0, s^2 I) the repeatability perturbation of the six joints drawn each time the
robot comes to rest (``robot.repeatability_sigma``: a 3-sigma flange spread of the
robot's repeatability, 0.07 mm for the MC70, s ~ 1.1e-5 rad) and laser_i the laser noise of
the sample value, the mean of a 100-reading buffer (std noise / 10). dd/dq_j equals the
Jacobian column of delta_j. So e_i is Gaussian, independent between samples, zero mean, but
its variance v_i = s^2 |J_delta,i|^2 + sigma_L^2 depends on the pose (heteroscedastic): the
white-noise bound sigma^2 (J^T J)^-1 is then not the covariance of the (unweighted) least
squares estimate; that is the sandwich (J^T J)^-1 J^T V J (J^T J)^-1, and the Cramer-Rao
bound for this noise is (J^T V^-1 J)^-1, which the weighted fit reaches
(``FitOptions(joint_sigma_rad=s)``; ``fit.noise_variance`` is v_i).
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterable, Iterator


from planecal.base.errors import InputError
from planecal.base.progress import Progress
from planecal.studies.distributed import Engine



def parse_int_list(text: str, what: str, minimum: int = 1,
                   maximum: int | None = None) -> list[int]:
    """"30,50,100" -> [30, 50, 100], each in [minimum, maximum]; InputError on anything
    else."""
    try:
        vals = [int(v) for v in str(text).split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated integers, got {text!r}") from None
    if not vals:
        raise InputError(f"{what}: no values in {text!r}")
    bad = [v for v in vals if v < minimum]
    if bad:
        raise InputError(f"{what}: values must be at least {minimum}, got {bad[0]}")
    big = [v for v in vals if maximum is not None and v > maximum]
    if big:
        raise InputError(f"{what}: values must be at most {maximum}, got {str(big[0])[:40]}")
    return vals


@contextmanager
def engine_for(engine: Engine | int | None) -> Iterator[Engine]:
    """``engine`` if it is an ``Engine`` (the caller opened it and closes it); otherwise an
    engine of that many jobs (None: ``Engine()``, a LocalCluster on every core; 1: this
    process), opened here and closed after."""
    if isinstance(engine, Engine):
        yield engine
        return
    with Engine(jobs=engine) as eng:
        yield eng


def parallel_map(fn: Callable, items: Iterable, engine: Engine | int | None = 1,
                 progress: Progress | None = None, key: Callable | None = None,
                 results=None, resume: bool = False, header: dict | None = None) -> list:
    """[fn(item) for item in items], in order, through ``engine`` (``engine_for``; fn and
    the items picklable, fn a pure function of its item: the item carries its own seed).
    ``progress`` steps as each run completes; with ``results`` (a JSON-lines file) each
    result is written as it completes and ``resume`` reruns only the items whose ``key`` is
    not in it yet (``Engine.map``)."""
    with engine_for(engine) as eng:
        return eng.map(fn, items, key=key, out=results, resume=resume, header=header,
                       progress=progress)


# ----- per-process caches of what every run of a study rebuilds otherwise -------------------

_CACHE: dict = {}


def cached_scene(name):
    """The scene ``name`` (``scene.load_scene``), loaded once per process."""
    from planecal.model.scene import load_scene
    key = ("scene", name)
    if key not in _CACHE:
        _CACHE[key] = load_scene(name)
    return _CACHE[key]


def cached_world(name, clearance_m: float):
    """The collision world of scene ``name`` at ``clearance_m``, built once per process."""
    key = ("world", name, clearance_m)
    if key not in _CACHE:
        from planecal.safety.collision import CollisionWorld
        _CACHE[key] = CollisionWorld(cached_scene(name), clearance_m=clearance_m)
    return _CACHE[key]


def cached_profile(scene_name, errors):
    """The error profile ``errors`` for scene ``scene_name``'s robot, read once per process."""
    from planecal.twin.profile import load_profile
    key = ("profile", scene_name, str(errors))
    if key not in _CACHE:
        _CACHE[key] = load_profile(errors, cached_scene(scene_name).robot)
    return _CACHE[key]
