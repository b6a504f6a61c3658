"""The Run: a sampling run's sample file and its sidecar, read as one artifact.

A run is written by the sampling session (``sampling.run.SamplingRun``: the sample file,
flushed per sample, and the sidecar ``RUN.tsv.json``, format ``planecal-run/1``) with the
record of where it was made that the job adds (``twin_record``: the twin's world as a
``twin.world.WorldRef`` and its noise seed; or the real cell's link record). It is read
here only (``read_run``, ``read_runs``): the cell from the sidecar (``jobs.cell``: a
``--scene`` that contradicts it is refused, a file without a sidecar takes ``--scene`` or
the default scene), the samples checked against that cell (its laser window and plates),
the approach directions, the world and the link record.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from planecal.base.errors import InputError
from planecal.io.samples import Samples, join_samples, read_samples
from planecal.jobs.cell import CellClaim, resolve_cell
from planecal.model.scene import Scene
from planecal.sampling.runfiles import load_sidecar, sidecar_path
from planecal.twin.world import WorldRef


def twin_record(ref: WorldRef, seed: int) -> dict:
    """The sidecar's ``twin`` block of a run on the twin: its world (``WorldRef``'s
    record) and the twin's noise seed (its truth's too, unless a truth file gave it)."""
    return {"seed": int(seed), **ref.to_dict()}


def read_sidecar(path) -> dict | None:
    """The run's sidecar (validated, ``formats.run``), or None where the sample file has
    none (written by hand, or by another program)."""
    return load_sidecar(path) if sidecar_path(path).exists() else None


def run_claim(path, side: dict | None) -> CellClaim | None:
    """The cell a run's sidecar records (None without one)."""
    if side is None:
        return None
    return CellClaim(str(sidecar_path(path)), side.get("scene"), side.get("scene_path"),
                     side.get("robot"), Path(path).parent)


@dataclass(frozen=True)
class Run:
    """One sample file with its sidecar: the samples (checked against ``scene``, with
    their approach directions), the cell they were taken in, and the sidecar (None: a
    file without one)."""
    path: Path
    samples: Samples
    scene: Scene
    sidecar: dict | None = None

    @property
    def world(self) -> WorldRef | None:
        """The twin's world the run was made in; None for a real cell's run or a file
        without a sidecar."""
        twin = (self.sidecar or {}).get("twin")
        return None if twin is None else WorldRef.from_dict(twin, str(sidecar_path(self.path)))

    @property
    def twin_seed(self) -> int | None:
        """The twin's noise seed (None: not a twin's run)."""
        twin = (self.sidecar or {}).get("twin")
        return None if twin is None else int(twin["seed"])

    def record(self) -> dict | None:
        """Where the run was made, as the cell's history records it: ``{"twin": {seed,
        errors, truth_seed, truth_file, truth_sha256, exact}}`` or ``{"real_cell": {rt,
        rt_port, laser}}``; None for a file without a sidecar."""
        world = self.world
        if world is not None:
            return {"twin": twin_record(world, self.twin_seed)}
        real = (self.sidecar or {}).get("real_cell")
        if isinstance(real, dict):
            return {"real_cell": {k: real.get(k) for k in ("rt", "rt_port", "laser")}}
        return None


@dataclass(frozen=True)
class Runs:
    """Several runs of one cell, their samples joined in the order given (a calibration's
    inputs)."""
    runs: tuple[Run, ...]
    scene: Scene
    samples: Samples

    @property
    def paths(self) -> list[Path]:
        return [r.path for r in self.runs]

    def record(self) -> dict | list | None:
        """The worlds the runs were made in (``Run.record``): one, a list, or None."""
        worlds = [w for w in (r.record() for r in self.runs) if w is not None]
        unique = [w for k, w in enumerate(worlds) if w not in worlds[:k]]
        return None if not unique else unique[0] if len(unique) == 1 else unique


def read_runs(paths, scene=None, claims=()) -> Runs:
    """Several runs of one cell (``jobs.cell.resolve_cell``): each sidecar's cell, those
    of ``claims`` (a result read beside them) and ``scene`` (--scene) must agree; files
    without a sidecar take the cell of the others, else ``scene``, else the default. The
    samples are checked against the cell (laser window, plates)."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("no sample file given")
    sides = [read_sidecar(p) for p in paths]
    cell = resolve_cell([run_claim(p, s) for p, s in zip(paths, sides)] + list(claims), scene)
    runs = tuple(Run(p, read_samples(p, cell), cell, s) for p, s in zip(paths, sides))
    return Runs(runs, cell, runs[0].samples if len(runs) == 1
                else join_samples([r.samples for r in runs]))


def read_run(path, scene=None, claims=()) -> Run:
    """One run (``read_runs``)."""
    return read_runs([path], scene, claims).runs[0]


def run_world(run: Run | None, truth_file=None, errors: str | None = None,
              truth_seed: int | None = None, default: str = "realistic") -> WorldRef:
    """The world a run was made in, from what travels with its files: the truth file
    (``rehearse --truth-out``: its world and error profile) and the run's sidecar (its
    twin's ``WorldRef``). ``errors`` and ``truth_seed`` given by hand must agree with them
    (InputError naming both); where nothing is recorded they choose the world
    (``default`` profile, seed 0)."""
    from planecal.base.paths import file_sha256
    from planecal.twin.profile import truth_file_errors

    ref = run.world if run is not None else None
    rec = {} if ref is None else {**ref.to_dict(), "where": str(sidecar_path(run.path))}
    if truth_file is not None:
        t_err = truth_file_errors(truth_file)
        if t_err is not None and rec.get("errors") not in (None, t_err):
            raise InputError(f"{truth_file}: drawn in the {t_err} world, but {rec['where']} "
                             f"says the run was made in the {rec['errors']} world")
        digest = file_sha256(truth_file)
        if rec.get("truth_sha256") not in (None, digest):
            # a truth file edited in place (say, a drift injected) is another world: the
            # run was made in the one its sidecar hashed, not in this file's
            raise InputError(f"{truth_file}: not the truth file the run {run.path} was "
                             f"made in (its SHA-256 differs from the recorded "
                             f"{rec['truth_sha256'][:12]}...): edited since? Edit a copy "
                             "to make a new world (rehearse --truth COPY.json)")
        rec.update(errors=t_err or rec.get("errors"), truth_file=str(truth_file),
                   truth_sha256=digest, where=str(truth_file))
    for flag, key, given in (("--errors", "errors", errors),
                             ("--truth-seed", "truth_seed", truth_seed)):
        if given is None:
            continue
        if rec.get(key) is not None and str(rec[key]) != str(given):
            raise InputError(f"{flag} {given}: {rec['where']} records "
                             f"{key.replace('_', ' ')} {rec[key]}: the run was made there")
        rec[key] = given
    rec.pop("where", None)
    if rec.get("truth_file") is None and rec.get("truth_seed") is None:
        rec["truth_seed"] = 0
    return WorldRef.from_dict(rec, "the run's world", default)
