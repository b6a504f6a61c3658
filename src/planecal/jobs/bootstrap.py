"""The bootstrap job (``planecal bootstrap``, seed 9.3's result analysis): random subsets
of a pool of runs, read in their cell (``jobs.runs``), each calibrated from the same
initial parameters on ``studies.distributed.Engine`` (``studies.bootstrap``)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from planecal.jobs.calibrate import initial_params
from planecal.jobs.report import write_command_report
from planecal.jobs.runs import read_runs

FORMAT = "planecal-bootstrap/1"


@dataclass(frozen=True)
class BootstrapRequest:
    """``planecal bootstrap``'s options: the pool's sample files, --scene (None: the
    runs'), --initial, the subsets (``sizes``: None for the default; ``repeats``,
    ``seed``), --out, --report, --rrd, --resume; ``settings``: the calibration's settings
    for the cell's robot; ``engine``: the study's engine and results file, made when the
    pool is read (the options checked then)."""
    samples: tuple
    settings: Callable
    engine: Callable
    scene: str | None = None
    initial: str | None = None
    sizes: tuple | None = None
    repeats: int = 10
    seed: int = 0
    out: str | None = None
    report: str | None = None
    rrd: str | None = None
    resume: bool = False


def bootstrap(req: BootstrapRequest) -> dict:
    """The bootstrap (``studies.bootstrap``), printed and written: its document."""
    from planecal.io.params import save_json
    from planecal.present.bootstrap import format_bootstrap
    from planecal.studies.bootstrap import BootstrapSettings, Pool, bootstrap as run_bootstrap
    from planecal.studies.bootstrap import check_settings

    runs = read_runs(req.samples, req.scene)
    scene, samples = runs.scene, runs.samples
    initial = initial_params(req.initial, scene)
    cal = req.settings(scene.robot)
    pool = Pool(scene.robot, samples.qe, samples.d_mm * 1e-3, samples.plate, initial, cal,
                samples.direction, scene.references)
    settings = check_settings(pool, BootstrapSettings(req.sizes, req.repeats, req.seed))
    engine, results = req.engine()  # its options checked before any file
    with engine:
        res = run_bootstrap(pool, settings, engine, results=results, resume=req.resume)
    print(format_bootstrap(res, pool.layout))
    res = {"format": FORMAT, **res}
    if req.out:
        save_json(req.out, res)
        print(f"result written to {req.out}")
    write_command_report(req.report, res, scene=scene)
    if req.rrd:
        from planecal.present.rerun.studies import log_bootstrap
        print(f"plots written to {log_bootstrap(req.rrd, res, scene, pool)}")
    return res
