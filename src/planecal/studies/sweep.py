"""A sweep: accuracy against robot time over a grid of scene x error profile x pose design x
sample count x calibration level, R runs per grid cell (docs/SWEEP.md).

One run (``run_one``, a pure function of its item) rehearses in the twin, calibrates and
measures:

* the world: the error profile's hidden truth for the *world seed* (``draw_world``), the
  twin's noise for the *run seed*;
* sampling: the collect core (``sampling.collect``) with the sampling run's own planner --
  ``random``: ``Planner`` (pose draw, IK, target and path collision-checked, the run
  seed's random stream); ``planned`` / ``planned+ordered``: the plan's pose list
  (``studies.planning.plan``, without / with the robot-time tour) through ``ListPlanner``
  -- and the twin set at rest at each target (``RestAcquirer``) or, in a world whose joint
  errors depend on the path (backlash, thermal), driven there tick by tick
  (``DriveAcquirer``, as ``planecal rehearse``). A ``tour.Clock`` counts the robot's ticks
  (travel, dwell, laser reads): the robot time;
* calibration at the cell's ``level`` by the one calibration (``estimation.calibrate``)
  from the scene's nominal parameters: ``offsets`` or ``full`` (the seed's ``1``, ``2``),
  either with ``+compliance`` (J2 and J3's joint compliance), e.g. ``full+compliance``;
  the planned designs are planned for level offsets;
* measurement: each free joint offset's error against the truth.

Seeds: run k of a cell has the world seed ``seed(spec seed, scene, errors, k)`` -- the same
truth for every design and sample count, so designs are compared on the same robots -- and
the run seed ``seed(spec seed, cell, k)``: fixed by the grid cell and k, whatever worker
runs it (``SeedSequence`` of the spec seed and a CRC-32 of the cell's JSON).

The runs go through ``studies.distributed.Engine`` with a results file: a killed sweep
resumes (``resume=True``) and ends with the same table, because the table is computed from
the results in item order, read back from the file.

Per cell (``summarize``): the runs, the mean robot time and travel per sample, the std over
the runs of each free offset's error (ddof 1), the RMS error, and ``offset_std``: the RMS
over the free offsets of their std (the figure the plots show against robot minutes).
"""
from __future__ import annotations

import itertools
import json
import math
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.base.limits import MAX_CANDIDATES, MAX_RUNS, MAX_SAMPLES, SEED_MAX
from planecal.studies.common import cached_profile, cached_scene, cached_world

FORMAT = "planecal-sweep/1"
DESIGNS = ("random", "planned", "planned+ordered")
AXES = ("scene", "errors", "design", "samples", "level")
MAX_SPEC_BYTES = 2**20  # a spec is a few lines



@dataclass(frozen=True)
class SweepSpec:
    """SPEC.toml (docs/SWEEP.md)."""
    scene: tuple = ("thesis_final",)
    errors: tuple = ("realistic",)
    design: tuple = ("random", "planned+ordered")
    samples: tuple = (150,)
    level: tuple = ("offsets",)
    runs: int = 20
    seed: int = 1000
    plan_candidates: int = 1500
    plan_seed: int = 0
    clearance_m: float = 0.01

    def cells(self) -> list[dict]:
        """The grid cells, in axis order (scene slowest, level fastest)."""
        return [dict(zip(AXES, v)) for v in itertools.product(
            self.scene, self.errors, self.design, self.samples, self.level)]

    def header(self) -> dict:
        """The results file's header: everything that decides a run's result."""
        return {"format": FORMAT, **{k: (list(v) if isinstance(v, tuple) else v)
                                     for k, v in asdict(self).items()}}


_KIND = {int: "an integer", str: "a string", float: "a number"}


def _list(v, where: str, kind, allow_scalar: bool = True) -> tuple:
    if allow_scalar and isinstance(v, kind) and not isinstance(v, bool):
        v = [v]
    if not isinstance(v, list) or not v:
        raise InputError(f"{where}: expected a non-empty list, got {v!r}")
    for x in v:
        if not isinstance(x, kind) or isinstance(x, bool):
            raise InputError(f"{where}: {x!r} is not {_KIND[kind]}")
    if len(set(v)) != len(v):
        raise InputError(f"{where}: a value appears twice")
    return tuple(v)


def load_spec(path) -> SweepSpec:
    """SPEC.toml read and checked: a one-line InputError naming the file and the field."""
    from planecal.formats.base import read_toml
    p = Path(path)
    return spec_from_dict(read_toml(p, "sweep spec", MAX_SPEC_BYTES), p)


def spec_from_dict(doc: dict, path: Path | None = None) -> SweepSpec:
    """A spec from the parsed TOML (``[grid]`` and ``[sweep]`` tables); FILE error profiles
    are resolved against the spec's folder."""
    where = str(path) if path is not None else "<spec>"
    unknown = set(doc) - {"grid", "sweep"}
    if unknown:
        raise InputError(f"{where}: unknown table [{sorted(unknown)[0]}] (expected [grid] and "
                         "[sweep])")
    grid, sw = doc.get("grid", {}), doc.get("sweep", {})
    if not isinstance(grid, dict) or not isinstance(sw, dict):
        raise InputError(f"{where}: [grid] and [sweep] must be tables")
    bad = set(grid) - set(AXES)
    if bad:
        raise InputError(f"{where}: grid.{sorted(bad)[0]}: unknown axis (the axes: "
                         f"{', '.join(AXES)})")
    fields = {"runs", "seed", "plan_candidates", "plan_seed", "clearance_m"}
    bad = set(sw) - fields
    if bad:
        raise InputError(f"{where}: sweep.{sorted(bad)[0]}: unknown setting (the settings: "
                         f"{', '.join(sorted(fields))})")
    kw: dict = {}
    d = SweepSpec()
    kw["scene"] = _list(grid.get("scene", list(d.scene)), f"{where}: grid.scene", str)
    errors = _list(grid.get("errors", list(d.errors)), f"{where}: grid.errors", str)
    kw["errors"] = tuple(_resolve_errors(e, path, where) for e in errors)
    kw["design"] = _list(grid.get("design", list(d.design)), f"{where}: grid.design", str)
    for x in kw["design"]:
        if x not in DESIGNS:
            raise InputError(f"{where}: grid.design: {x!r} is not a pose design "
                             f"({', '.join(DESIGNS)})")
    kw["samples"] = _list(grid.get("samples", list(d.samples)), f"{where}: grid.samples", int)
    for n in kw["samples"]:
        if n < 20:
            raise InputError(f"{where}: grid.samples: {n} is below 20 (a calibration needs "
                             "at least 20 samples)")
        if n > MAX_SAMPLES:
            raise InputError(f"{where}: grid.samples: {str(n)[:40]} is above {MAX_SAMPLES} "
                             "(the most samples a run takes)")
    kw["level"] = _list(grid.get("level", list(d.level)), f"{where}: grid.level", str)
    for x in kw["level"]:
        try:
            calibration_of(x)
        except InputError as e:
            raise InputError(f"{where}: grid.level: {x!r}: {e}") from None
    for k, kind, lo, hi in (("runs", int, 2, MAX_RUNS), ("seed", int, 0, SEED_MAX),
                            ("plan_candidates", int, 20, MAX_CANDIDATES),
                            ("plan_seed", int, 0, SEED_MAX), ("clearance_m", float, 0.0, 1.0)):
        if k in sw:
            v = sw[k]
            if kind is float and isinstance(v, int) and not isinstance(v, bool):
                v = float(v)
            if (not isinstance(v, kind) or isinstance(v, bool) or not lo <= v <= hi
                    or (kind is float and not np.isfinite(v))):
                raise InputError(f"{where}: sweep.{k}: expected {_KIND[kind]} in "
                                 f"[{lo}, {hi}], got {str(sw[k])[:40]}")
            kw[k] = v
    spec = SweepSpec(**kw)
    n_cells = math.prod(len(getattr(spec, a)) for a in AXES)
    if n_cells * spec.runs > MAX_RUNS:
        raise InputError(f"{where}: the grid makes {n_cells:,} cells x {spec.runs} runs = "
                         f"{n_cells * spec.runs:,} runs; a sweep runs at most {MAX_RUNS:,}: "
                         "fewer axis values or runs")
    planned = [n for n in spec.samples if any(x != "random" for x in spec.design)]
    if planned and max(planned) > spec.plan_candidates:
        raise InputError(f"{where}: sweep.plan_candidates ({spec.plan_candidates}) must be at "
                         f"least the largest planned sample count ({max(planned)})")
    for s in spec.scene:
        cached_scene(s)  # InputError if unknown
    for s, e in itertools.product(spec.scene, spec.errors):
        cached_profile(s, e)
    _check_sizes(spec, where)
    return spec


def _check_sizes(spec: SweepSpec, where: str) -> None:
    """InputError (one line) for a cell whose sample count cannot determine its level's
    free parameters (every run would be refused: ``estimation.calibrate``'s rule)."""
    from planecal.estimation.calibrate import candidates
    from planecal.model.levels import layout_for
    for s, level in itertools.product(spec.scene, spec.level):
        scene, st = cached_scene(s), calibration_of(level)
        layout = layout_for(scene.robot, len(scene.plates), st.level, st.compliance)
        p = int(candidates(scene.robot, layout, st, scene.references)[0].sum())
        low = [n for n in spec.samples if n <= p]
        if low:
            raise InputError(f"{where}: grid.samples: {low[0]} samples cannot determine the "
                             f"{p} free parameters of level {level!r} on {s}: give more than "
                             f"{p} (or leave that level out)")


def calibration_of(level: str):
    """The ``CalibrationSettings`` of a grid level: a level (``model.levels``) with an
    optional ``+compliance``."""
    from planecal.estimation.calibrate import CalibrationSettings
    name, plus, extra = level.partition("+")
    if plus and extra != "compliance":
        raise InputError(f"expected a level (offsets, full, 1, 2) with an optional "
                         f"'+compliance', got {level!r}")
    return CalibrationSettings(level=name, compliance=bool(plus))


def _resolve_errors(e: str, path: Path | None, where: str) -> str:
    from planecal.twin.profile import PROFILES
    if e in PROFILES:
        return e
    p = Path(e)
    if not p.is_absolute() and path is not None:
        p = path.parent / p
    if not p.exists():
        raise InputError(f"{where}: grid.errors: {e!r} is neither a profile "
                         f"({', '.join(PROFILES)}) nor an existing file")
    return str(p.resolve())


# ----- seeds ----------------------------------------------------------------------------------

def _crc(obj) -> int:
    return zlib.crc32(json.dumps(obj, sort_keys=True).encode())


def derived_seed(base: int, obj, k: int) -> int:
    """A 32-bit seed fixed by (base, the JSON of obj, k)."""
    return int(np.random.SeedSequence(entropy=base, spawn_key=(_crc(obj), k))
               .generate_state(1, np.uint32)[0])


def cell_id(cell: dict) -> str:
    return "/".join(str(cell[a]) for a in AXES)


def world_seed(spec: SweepSpec, cell: dict, k: int) -> int:
    return derived_seed(spec.seed, {"scene": cell["scene"], "errors": cell["errors"]}, k)


def run_seed(spec: SweepSpec, cell: dict, k: int) -> int:
    return derived_seed(spec.seed, cell, k)


# ----- plans ---------------------------------------------------------------------------------

def plan_poses(spec: SweepSpec, scene: str, design: str, samples: int) -> dict:
    """The pose list of a planned design (``studies.planning.plan`` at the spec's
    candidates and plan seed): {"counts", "plates", "predicted_robot_time_s"}."""
    from planecal.studies.planning import plan
    res = plan(cached_scene(scene), samples, spec.plan_candidates, spec.plan_seed, None,
               cached_world(scene, spec.clearance_m), ordered=design == "planned+ordered")
    return {"counts": res["counts"], "plates": res["plates"],
            "predicted_robot_time_s": res["robot_time_s"]["planned"]}


@dataclass
class Item:
    """One run: its cell, k, seeds, settings and (planned designs) the pose list."""
    cell: dict
    k: int
    world_seed: int
    seed: int
    clearance_m: float
    poses: dict | None = field(default=None)

    def key(self) -> list:
        return [cell_id(self.cell), self.k]


def items(spec: SweepSpec, plans: dict) -> list[Item]:
    """Every run of the sweep, cell after cell (``plans``: (scene, design, samples) -> the
    pose list of each planned design)."""
    out = []
    for cell in spec.cells():
        poses = plans.get((cell["scene"], cell["design"], cell["samples"]))
        for k in range(spec.runs):
            out.append(Item(cell, k, world_seed(spec, cell, k), run_seed(spec, cell, k),
                            spec.clearance_m, poses))
    return out


# ----- one run -------------------------------------------------------------------------------

def run_one(item: Item) -> dict:
    """Rehearse in the twin, calibrate, measure (module docstring). Pure function of the
    item. A run that gives up returns {"failed": reason}."""
    from planecal.estimation.calibrate import calibrate
    from planecal.model.encoder import counts_to_joints
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.collect import (Cursor, DriveAcquirer, MemoryRecorder,
                                           RestAcquirer, Tally, collect)
    from planecal.sampling.driver import Driver
    from planecal.sampling.planner import ListPlanner, Planner
    from planecal.sampling.run import RunSettings
    from planecal.sampling.tour import Clock
    from planecal.model.scene import nominal_params
    from planecal.twin.world import path_dependent
    from planecal.twin import Twin
    from planecal.twin.profile import draw_world

    cell = item.cell
    scene = cached_scene(cell["scene"])
    robot = scene.robot
    world, opts = draw_world(scene, item.world_seed, cached_profile(cell["scene"], cell["errors"]))
    twin = Twin(scene, truth=world, seed=item.seed, options=opts)
    try:
        rs = RunSettings.for_scene(scene, samples=cell["samples"], seed=item.seed)
        rs.clearance_m = item.clearance_m
        checker = cached_world(cell["scene"], item.clearance_m)
        if item.poses is None:
            planner = Planner(scene, rs.pose, checker)
        else:
            planner = ListPlanner(scene, np.array(item.poses["counts"], np.int64),
                                  np.array(item.poses["plates"], int), checker)
        if path_dependent(opts):
            drv = Driver(twin, twin, AlwaysEnabled(), robot)
            drv.start()
            acq = DriveAcquirer(drv, rs.laser, rs.nominal_step_counts, rs.dwell_ticks)
        else:
            acq = RestAcquirer(twin, rs.laser)
        start = twin.current_counts.copy()
        clock = Clock(acq, start, rs.nominal_step_counts, rs.dwell_ticks)
        rec, tally = MemoryRecorder(), Tally()
        collect(planner, clock, rec, rs.samples,
                Cursor(counts_to_joints(robot, start),
                       np.random.default_rng(item.seed).bit_generator.state),
                tally, rs.max_attempts)
    finally:
        twin.close()
    listed = item.poses is not None and tally.samples > 0 \
        and tally.samples + tally.rejected["laser"] >= len(item.poses["counts"])
    if tally.status != "complete" and not listed:
        rej = ", ".join(f"{k} {v}" for k, v in tally.rejected.items() if v)
        return {"failed": f"sampling gave up after {tally.samples} of {rs.samples} samples "
                          f"(rejected: {rej or 'none'}): {tally.reason}"}
    qe, d, plate, direction = rec.arrays()
    try:
        fit = calibrate(robot, qe, d, nominal_params(scene), plate,
                        calibration_of(cell["level"]), direction, scene.references).result
    except InputError as e:
        return {"failed": f"calibration refused: {e}"}
    layout = fit.layout
    offsets = layout.group("joint_offsets").names
    names = [n for n in layout.names_of(fit.free) if n in offsets]
    est = fit.params.to_vector(layout)
    truth = world.params.to_vector(layout)
    idx = layout.indices(names)
    return {"samples": int(len(d)), "names": names, "err": est[idx] - truth[idx],
            "robot_time_s": clock.ticks * robot.tick_s, "ticks": int(clock.ticks),
            "travel_ticks": int(clock.travel_ticks), "read_ticks": int(clock.read_ticks),
            "rejected": dict(tally.rejected), "laser_give_ups": dict(tally.laser_give_ups),
            "converged": bool(fit.converged),
            "rms_mm": float(fit.rms_mm())}


# ----- the sweep -----------------------------------------------------------------------------

def plans_needed(spec: SweepSpec) -> list[tuple]:
    """(scene, design, samples) of every planned design of the grid."""
    return [(s, d, n) for s, d, n in itertools.product(spec.scene, spec.design, spec.samples)
            if d != "random"]


def run_sweep(spec: SweepSpec, out, engine, resume: bool = False, progress=None,
              plan_progress=None) -> dict:
    """Plan the planned designs, run every item through ``engine`` (a started
    ``distributed.Engine``) into the results file ``out``, and summarise. A planned run
whose laser gives up on some poses of its list takes fewer samples (as the sampling run
would); the table says how many were taken on average (``taken``).
    ``plan_progress``: a ``planecal.base.progress.Progress`` over ``plans_needed``."""
    plans = {}
    for scene, design, n in plans_needed(spec):
        if plan_progress:
            plan_progress.update(note=f"{design}, {n} poses on {scene}")
        plans[(scene, design, n)] = plan_poses(spec, scene, design, n)
    if plan_progress:
        plan_progress.close()
    its = items(spec, plans)
    results = engine.map(run_one, its, key=Item.key, out=out, resume=resume,
                         header=spec.header(), progress=progress)
    return summarize(spec, its, results)


def summarize(spec: SweepSpec, its: list[Item], results: list[dict]) -> dict:
    """Per cell: runs, failures, robot time, travel per sample, the offsets' error std and
    RMS, ``offset_std`` (module docstring)."""
    by: dict = {}
    for it, r in zip(its, results):
        by.setdefault(cell_id(it.cell), (it.cell, []))[1].append(r)
    rows = []
    for cid, (cell, rs) in by.items():
        ok = [r for r in rs if "failed" not in r]
        row = {**cell, "cell": cid, "runs": len(ok), "failed": len(rs) - len(ok)}
        if ok:
            names = ok[0]["names"]
            E = np.array([r["err"] for r in ok])
            t = np.array([r["robot_time_s"] for r in ok])
            n = np.array([r["samples"] for r in ok])
            trav = np.array([r["travel_ticks"] for r in ok]) * cached_scene(cell["scene"]).robot.tick_s
            std = E.std(0, ddof=1) if len(ok) > 1 else np.full(len(names), np.nan)
            row.update({
                "names": names,
                "samples_taken": float(n.mean()),
                "robot_time_s": float(t.mean()), "robot_time_min": float(t.mean() / 60),
                "robot_time_per_sample_s": float(np.mean(t / n)),
                "travel_per_sample_s": float(np.mean(trav / n)),
                "std_rad": dict(zip(names, std.tolist())),
                "rms_rad": dict(zip(names, np.sqrt(np.mean(E ** 2, 0)).tolist())),
                "bias_rad": dict(zip(names, E.mean(0).tolist())),
                "offset_std_rad": float(np.sqrt(np.mean(std ** 2))),
                "offset_rms_rad": float(np.sqrt(np.mean(E ** 2))),
                "rms_mm": float(np.mean([r["rms_mm"] for r in ok])),
                "not_converged": int(sum(not r["converged"] for r in ok)),
            })
        rows.append(row)
    return {"format": FORMAT, "spec": spec.header(), "cells": rows}
