"""A run predicted with parameters: ``planecal predict`` (the analytic model's distance per
sample) and ``planecal replay`` (the twin's ray cast per sample, in the world the run was
made in). The run and the parameters are read in their cell (``jobs.results.
read_runs_and_result``: the run's sidecar, a result's provenance, --scene)."""
from __future__ import annotations

import sys
from dataclasses import dataclass

from planecal.base.errors import InputError
from planecal.jobs.results import read_runs_and_result

HEADER = ("index", "measured_mm", "predicted_mm", "error_mm")

REPLAY_FORMAT = "planecal-replay/1"


def robot_agrees(robot_flag, cell, where) -> None:
    """--robot, where given, must be the cell's robot (its name and description)."""
    if robot_flag is None:
        return
    from planecal.model.robot import load_robot
    robot = load_robot(robot_flag)
    if robot.name != cell.robot.name or (robot.digest and cell.robot.digest
                                         and robot.digest != cell.robot.digest):
        raise InputError(f"--robot {robot_flag}: {where} was made for the robot "
                         f"{cell.robot.name!r} (scene {cell.name}), not {robot.name!r}")


def predict(samples, params, scene=None, robot=None) -> int:
    """One tab-separated line per sample: index, measured_mm, predicted_mm, error_mm
    (predicted - measured) on stdout."""
    from planecal.model.measurement import predict as distance

    runs, result = read_runs_and_result([samples], params, scene)
    robot_agrees(robot, runs.scene, samples)
    s, p = runs.samples, result.params
    if s.plate.max() >= p.n_planes:
        raise InputError(f"{samples}: samples refer to plate {s.plate.max() + 1}, "
                         f"{params} holds {p.n_planes} plane(s)")
    d = distance(runs.scene.robot, s.qe, p, s.plate) * 1e3
    out = sys.stdout
    out.write("\t".join(HEADER) + "\n")
    for i, (m, v) in enumerate(zip(s.d_mm, d)):
        out.write(f"{i}\t{m:.4f}\t{v:.4f}\t{v - m:.4f}\n")
    return 0


@dataclass(frozen=True)
class ReplayRequest:
    """``planecal replay``'s options: the sample file, the parameters (the twin's truth),
    --scene, and the world where the files record none (--errors, --truth-seed), --out."""
    samples: str
    params: str
    scene: str | None = None
    errors: str | None = None
    truth_seed: int | None = None
    out: str | None = None


def replay(req: ReplayRequest) -> dict:
    """The replay (``studies.replay``), printed and written to --out: its document."""
    from planecal.io.params import save_json
    from planecal.jobs.runs import run_world
    from planecal.present.replay import format_replay
    from planecal.studies.replay import replay as replay_run, replay_world
    from planecal.twin.profile import load_profile
    from planecal.twin.world import sources_on

    runs, result = read_runs_and_result([req.samples], req.params, req.scene)
    scene, s, params = runs.scene, runs.samples, result.params
    truth_file = req.params if result.doc.get("world") else None
    ref = run_world(runs.runs[0], truth_file, req.errors, req.truth_seed)
    profile = load_profile(ref.errors, scene.robot)
    world = opts = None
    if profile.name != "ideal" or truth_file is not None:
        world, opts = replay_world(scene, params, ref)
    res = {"format": REPLAY_FORMAT,
           **replay_run(scene, params, s.qe, s.d_mm, s.plate, world, opts)}
    res["samples_file"] = str(req.samples)
    res["params_file"] = str(req.params)
    res["errors"] = profile.name
    res["profile"] = str(profile.path)
    res["truth_seed"] = None if world is None else ref.truth_seed
    res["world"] = ref.to_dict()
    if world is None:
        print(f"twin: the ideal world (the nominal model exactly, truth = {req.params})")
    else:
        on = sources_on(scene.robot, world, opts)
        print(f"twin: {ref.describe()} with the cell of {req.params} (errors at rest: "
              f"{', '.join(on) or 'none'}; no noise)")
    print(format_replay(res))
    if req.out:
        save_json(req.out, res)
        print(f"result written to {req.out}")
    return res
