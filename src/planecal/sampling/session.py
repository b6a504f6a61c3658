"""A sampling session, shared by ``planecal rehearse`` and ``planecal sample``: the move to
the start, the sampling run, the move to the end, the progress display and a summary.
The commands build the session from their flags (``commands.sampling_options``)."""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from planecal.base.errors import InputError, RunFailed
from planecal.base.progress import Progress
from planecal.sampling.driver import (Driver, EnableDropped, PathBlocked, move_home,
                                      move_to_calibration)
from planecal.sampling.observer import Observer
from planecal.sampling.planner import PlanSource
from planecal.sampling.poses import CommandModel
from planecal.sampling.run import RunSettings, RunStats, SamplingRun
from planecal.sampling.runfiles import RunLock, sidecar_path

START_MOVES = ("here", "calibration", "home")
END_MOVES = ("stay", "calibration", "home")


@dataclass
class Session:
    """What a session does around the run: ``start`` move (here: sample from where the
    robot is), ``end`` move after a complete run, ``resume`` the run in ``out``,
    ``background`` planning, ``hold_while_planning`` (the real cell), a ``planner``
    (default: random poses), the ``model`` the run aims with (default: the scene's nominal
    cell), an ``observer`` and ``extra`` sidecar fields."""
    out: Path
    start: str = "here"
    end: str = "stay"
    resume: bool = False
    background: bool = True
    hold_while_planning: bool = False
    planner: PlanSource | None = None
    model: CommandModel | None = None
    observer: Observer | None = None
    extra: dict | None = None


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


def run_note(st: RunStats) -> str:
    """A sampling run's progress note: rejections and robot time."""
    r = st.rejected
    return (f"rejected {sum(r.values())} (collision {r['collision']}, laser {r['laser']}, "
            f"unreachable {r['unreachable']})  robot time {_clock(st.robot_time_s)}")


def show_run(bar: Progress, st: RunStats) -> None:
    """The run's state on ``bar``: samples taken and ``run_note``."""
    bar.update(st.samples, run_note(st))


def close_run(bar: Progress, st: RunStats) -> None:
    """The last state; for a run that did not complete, why it stopped (an "error" run
    raises, and the command says why in its one line)."""
    show_run(bar, st)
    bar.close(None if st.status in ("complete", "error") else f"run {st.status}: {st.reason}")


def run_session(session: Session, scene, settings: RunSettings, link, laser, enable,
                checker) -> tuple[int, dict]:
    """Start move, the sampling run, end move. Returns (exit code, summary): 0 when the run
    completed, 1 when it stopped or gave up (the files are valid either way)."""
    lock = RunLock(session.out)  # before anything moves: no second run on the same file
    try:
        return _session(session, scene, settings, link, laser, enable, checker, lock)
    finally:
        lock.close()


def _move(kind: str):
    return move_home if kind == "home" else move_to_calibration


def _session(ses: Session, scene, settings, link, laser, enable, checker, lock):
    drv = Driver(link, laser, enable, scene.robot, ses.observer)
    progress = Progress("samples", settings.samples)
    moves, started = {}, False
    try:
        drv.start()
        if ses.start != "here":
            moves["start_ticks"] = _move(ses.start)(drv, scene, checker)
        started = True
    except PathBlocked as e:
        raise InputError(f"--start {ses.start}: {e}") from None
    except EnableDropped:
        raise RunFailed(f"--start {ses.start}: enable dropped on the way; nothing sampled") from None
    finally:
        if not started:  # no run: its bar closed here (an open one takes the process's reports)
            progress.close(last=False)
    run = SamplingRun(drv, scene, settings, ses.out, checker, resume=ses.resume,
                      background=ses.background, hold_while_planning=ses.hold_while_planning,
                      progress=partial(show_run, progress), extra=ses.extra, lock=lock, planner=ses.planner,
                      model=ses.model)
    t0 = time.perf_counter()
    ticks0 = drv.ticks
    try:
        st = run.run()
    finally:
        close_run(progress, run.stats)
    summary = st.summary()
    summary["session_robot_time_s"] = round((drv.ticks - ticks0) * scene.robot.tick_s, 3)
    if st.status == "complete" and ses.end != "stay":
        try:
            summary["end_ticks"] = _move(ses.end)(drv, scene, checker)
        except (PathBlocked, EnableDropped) as e:
            summary["end_move"] = f"not done: {e or 'enable dropped'}"
    summary.update(moves)
    summary["session_wall_time_s"] = round(time.perf_counter() - t0, 3)
    summary["planning_time_s"] = round(st.planning_s, 3)
    summary["out"] = str(ses.out)
    summary["sidecar"] = str(sidecar_path(ses.out))
    return (0 if st.status == "complete" else 1), summary


def print_summary(summary: dict) -> None:
    print(json.dumps(summary, indent=2))
