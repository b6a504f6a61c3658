"""The rehearsal job (``planecal rehearse``): a whole sampling run on the MuJoCo twin, in
the world of an error profile or a truth file, writing a Run (the sample file and its
sidecar, with the twin's world: ``jobs.runs.twin_record``)."""
from __future__ import annotations

import os
from dataclasses import dataclass

from planecal.base.errors import InputError
from planecal.jobs.runs import twin_record
from planecal.jobs.sampling import (SamplingRequest, command_model, fixed_distance_summary,
                                    observer_summary, pose_list_planner, prepare,
                                    rerun_observer, session_for)
from planecal.twin.world import WorldRef


@dataclass(frozen=True)
class RehearseRequest:
    """The sampling run's request and the twin's: its error profile (None: the default,
    or a truth file's), the truth file to run in (``truth_in``) and to write
    (``truth_out``), the twin's seed (None: the run's) and ``exact`` (no random noise)."""
    sampling: SamplingRequest
    errors: str | None = None
    truth_in: str | None = None
    truth_out: str | None = None
    twin_seed: int | None = None
    exact: bool = False


def world_ref(req: RehearseRequest, side, seed: int) -> tuple[WorldRef, int]:
    """(the world the run is made in, the twin's noise seed): a resumed run's (its sidecar
    names it; an option that contradicts it is refused), or the truth file's
    (--truth), or the error profile's draw for --twin-seed (default --seed)."""
    from planecal.base.paths import file_sha256
    from planecal.twin.profile import DEFAULT_PROFILE, truth_file_errors
    if side is not None:
        t = side.get("twin") or {}
        ref = WorldRef.from_dict({"seed": seed, **t}, "the run's sidecar")
        for flag, given, rec in (("--errors", req.errors, ref.errors),
                                 ("--truth", req.truth_in, ref.truth_file)):
            if given is not None and str(given) != str(rec):
                raise InputError(f"{flag} {given}: the run in {req.sampling.out} was made in "
                                 f"{ref.describe()}; --resume continues it there")
        return ref, int(t.get("seed", seed))
    twin_seed = seed if req.twin_seed is None else req.twin_seed
    if req.truth_in is not None:
        recorded = truth_file_errors(req.truth_in)
        if req.errors is not None and recorded is not None and req.errors != recorded:
            raise InputError(f"--errors {req.errors}: {req.truth_in} was drawn in the "
                             f"{recorded} world")
        return WorldRef(req.errors or recorded or DEFAULT_PROFILE, None, str(req.truth_in),
                        file_sha256(req.truth_in), req.exact), twin_seed
    return WorldRef(req.errors or DEFAULT_PROFILE, twin_seed, exact=req.exact), twin_seed


def rehearse(req: RehearseRequest) -> int:
    """The run on the twin (``sampling.session.run_session``), its summary printed (JSON
    on stdout): the exit code (0 complete, 1 stopped or gave up). The outputs were checked
    before the run (the output guard)."""
    from planecal.links.base import AlwaysEnabled
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling.session import print_summary, run_session
    from planecal.twin.profile import save_truth
    from planecal.twin.world import make_twin

    run = prepare(req.sampling)
    sreq, scene, settings = run.req, run.scene, run.settings
    ref, twin_seed = world_ref(req, run.sidecar, settings.seed)
    twin = make_twin(scene, ref, twin_seed)
    checker = CollisionWorld(scene, clearance_m=settings.clearance_m)
    if req.truth_out:
        try:
            save_truth(req.truth_out, twin, ref.errors, ref.truth_seed)
        except OSError as e:
            raise InputError(f"--truth-out {req.truth_out}: cannot write ({e.strerror})") from None
    observer = rerun_observer(sreq, scene, twin)
    model = command_model(sreq, scene, run.sidecar)
    planner = pose_list_planner(sreq, run.poses, scene, settings, checker, model[0],
                                (model[1] or {}).get("params"))
    session = session_for(sreq, planner, observer, extra={"twin": twin_record(ref, twin_seed)},
                          model=model)
    try:
        code, summary = run_session(session, scene, settings, twin, twin, AlwaysEnabled(),
                                    checker)
    finally:
        if observer is not None:
            observer.close()
        twin.close()
    wall = summary["session_wall_time_s"]
    robot_s = summary["session_robot_time_s"]
    summary["speedup"] = round(robot_s / wall, 1) if wall > 0 else None
    summary["twin_seed"] = twin_seed
    summary["errors"] = str(ref.errors)
    if sreq.foreground:
        summary["collision"] = checker.summary()
    summary["cpu_count"] = os.cpu_count()
    if req.truth_out:
        summary["truth"] = str(req.truth_out)
    if req.truth_in:
        summary["world"] = ref.describe()
    if settings.pose.fixed_distance_mm is not None:
        summary["fixed_distance"] = fixed_distance_summary(sreq.out, settings, model[1])
    summary.update(observer_summary(observer))
    print_summary(summary)
    return code
