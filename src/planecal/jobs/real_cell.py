"""The real cell's sampling job (``planecal sample``): the sampling run with the FD11 RT
link over UDP (``links.fd11.FD11Link``) and the ZS-LD80 on a serial port
(``links.zs_ld80.ZSLD80``), imported only when it runs; the controller's state file, its
lock and the first contact (``links.sessions``); the enable signal
(``sampling.enable.FollowingMonitor``); the link counters in the run's sidecar
(``real_cell``). The command's docstring (``commands/sample.py``) says what each option
does."""
from __future__ import annotations

import sys
from dataclasses import dataclass, fields
from pathlib import Path

from planecal.base.errors import InputError, RunFailed
from planecal.jobs.sampling import (SamplingRequest, command_model, observer_summary,
                                    pose_list_planner, prepare, rerun_observer, session_for)


@dataclass(frozen=True)
class LinkRequest:
    """The real cell's options (``commands/sample.py``; the same defaults)."""
    rt: str
    rt_port: int = 5555
    local_port: int = 5556
    rt_tick_s: float = 0.01
    rt_resend_s: float = 0.02
    rt_silence_s: float = 0.5
    rt_boot_timeout_s: float = 10.0
    rt_state: str | None = None
    rt_fresh: bool = False
    rt_keep: bool = False
    laser: str = "/dev/ttyUSB0"
    baud: int = 38400
    laser_timeout_s: float = 0.1
    laser_wait_s: float = 0.005
    laser_error_limit: int = 50
    follow_limit_counts: int | None = None
    servo_tau_s: float | None = None

    @classmethod
    def of(cls, values: dict) -> "LinkRequest":
        return cls(**{f.name: values[f.name] for f in fields(cls)})


class TolerantLaser:
    """The loop's `Laser` over ``ZSLD80.poll`` (never blocks a tick longer than the poll's
    wait). ``read()``: the reading; None for out of range and for a read error
    (``total``); ``NO_READING_MM`` for a tick without a reply yet (``no_reply_ticks``:
    skipped by the laser read, ``sampling.laserread``); ``limit`` errors in a row re-raise
    the last one."""

    def __init__(self, laser, limit: int, errors: tuple, no_reading):
        self.laser = laser
        self.limit = limit
        self.errors = errors
        from planecal.sampling.laserread import NO_READING_MM

        self.no_reading = no_reading  # the poll's "no reply yet"
        self.skip = NO_READING_MM     # the laser read's
        self.in_a_row = 0
        self.total = 0
        self.no_reply_ticks = 0

    def read(self):
        try:
            v = self.laser.poll()
        except self.errors:
            self.in_a_row += 1
            self.total += 1
            if self.in_a_row >= self.limit:
                raise
            return None
        if v is self.no_reading:
            self.no_reply_ticks += 1
            return self.skip
        self.in_a_row = 0
        return v

    def close(self):
        self.laser.close()


def _check_link_flags(req: LinkRequest, robot) -> int:
    """The following limit (the link flags checked)."""
    from planecal.sampling.enable import SERVO_TAU_S, follow_limit_counts

    for flag, v in (("rt_resend_s", req.rt_resend_s), ("rt_silence_s", req.rt_silence_s),
                    ("rt_boot_timeout_s", req.rt_boot_timeout_s),
                    ("laser_timeout_s", req.laser_timeout_s)):
        if not (v > 0 and v < float("inf")):
            raise InputError(f"--{flag.replace('_', '-')} must be a positive number of seconds")
    if req.rt_silence_s < req.rt_resend_s or req.rt_boot_timeout_s < req.rt_resend_s:
        raise InputError("--rt-silence-s and --rt-boot-timeout-s must be at least --rt-resend-s")
    if not 0 <= req.laser_wait_s <= req.laser_timeout_s:
        raise InputError("--laser-wait-s must be in 0..--laser-timeout-s")
    tau = SERVO_TAU_S if req.servo_tau_s is None else req.servo_tau_s
    if not (tau > 0 and tau < float("inf")):
        raise InputError("--servo-tau-s must be a positive number of seconds")
    limit = (follow_limit_counts(robot.trip_step_counts, tau, robot.tick_s)
             if req.follow_limit_counts is None else req.follow_limit_counts)
    if limit <= robot.max_step_counts:
        raise InputError(f"--follow-limit-counts must exceed the largest step "
                         f"({robot.max_step_counts} counts), got {limit}")
    return limit


class Controller:
    """The FD11 link with its state file, the controller's lock and the first contact
    (`planecal.links.sessions`): opened before any packet, closed in any case. Made in two
    steps: the link and the first contact (nothing written), then ``take()``: the state
    file's folder and the controller's lock."""

    def __init__(self, req: LinkRequest, out, robot, side: dict | None = None):
        from planecal.links.fd11 import FD11Link, LinkError
        from planecal.links.sessions import (StateFile, default_state_path, plan_contact,
                                             stated_behaviour)
        from planecal.sampling.runfiles import sidecar_path

        self.link = self.lock = self.state = None
        try:
            self.link = FD11Link(req.rt, req.rt_port, req.local_port, tick_s=req.rt_tick_s,
                                 timeout_s=req.rt_resend_s, silence_s=req.rt_silence_s,
                                 boot_timeout_s=req.rt_boot_timeout_s,
                                 max_step_counts=robot.max_step_counts)
        except (LinkError, ValueError) as e:
            raise InputError(f"--rt {req.rt}: {e}") from None
        try:
            out = Path(out)
            path = Path(req.rt_state) if req.rt_state else default_state_path(self.link.remote)
            if path.resolve() in (out.resolve(), sidecar_path(out).resolve()):
                raise InputError(f"--rt-state {path}: is the run's own sample file or sidecar")
            self.path = path
            self.state = StateFile(path)
            override = "fresh" if req.rt_fresh else "keep" if req.rt_keep else None
            earlier = ((side or {}).get("real_cell") or {}).get("rt_state")
            lost = (f"{sidecar_path(out)} (an earlier session, state file {earlier})"
                    if earlier else None)
            self.contact = plan_contact(stated_behaviour(robot.source), self.state.last,
                                        override, self.link.client, where=str(robot.source),
                                        lost=lost)
        except BaseException:
            self.close()
            raise

    def take(self) -> None:
        """The state file's folder and the controller's lock (one client per controller: a
        second run on it would command it too); the link told what the controller holds."""
        from planecal.sampling.runfiles import RunLock
        path = self.path
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InputError(f"--rt-state {path}: cannot create {path.parent} "
                             f"({e.strerror})") from None
        self.lock = RunLock(path, what="the FD11 at "
                            f"{self.link.remote[0]}:{self.link.remote[1]} (state {path})")
        self.link.expect(self.contact, self.state)

    @property
    def recorded_reference(self):
        """The controller's reference as the state file recorded it (None: unknown)."""
        last = self.state.last if self.state is not None else None
        return None if last is None else last.reference

    def wait_for_silence(self) -> float:
        """Keep the silence the first contact needs (a fresh reference after silence)."""
        import time

        wait = self.contact.wait_s
        if wait > 0:
            print(f"note: waiting {wait:.1f} s before the first FD11 packet: {self.contact.why}",
                  file=sys.stderr, flush=True)
            time.sleep(wait)
        return wait

    def record(self, waited_s: float) -> dict:
        """The sidecar's record of the first contact."""
        c = self.contact
        return {"rt_state": str(self.path), "first_delta": c.held.tolist(),
                "first_contact": {"kind": c.kind, "why": c.why, "waited_s": round(waited_s, 3),
                                  "client": self.link.client}}

    def close(self) -> None:
        for part in (self.link, self.state, self.lock):
            if part is not None:
                part.close()


_PEAKS = ("max_lost_in_a_row", "longest_outage_s", "boot_wait_s", "max_late_s")  # maxima


def link_totals(before: dict | None, session: dict) -> dict:
    """The link counters over all sessions: ``before`` (the sidecar's, None for a new run)
    plus this session's (sums; the maxima of the peaks; last session's boot wait kept as
    the largest)."""
    total = dict(session)
    for k, v in (before or {}).items():
        if k in total and isinstance(v, (int, float)):
            total[k] = max(total[k], v) if k in _PEAKS else total[k] + v
    return total


def _record_link(out: Path, real_cell: dict) -> None:
    """Put the session's link counters (``real_cell``'s ``link``, ``link_total``) in the
    sidecar once the session has ended. Best effort: a full disk keeps the last sidecar
    (the run has already said why it stopped)."""
    from planecal.io.params import save_json
    from planecal.sampling.runfiles import sidecar_path

    p = sidecar_path(out)
    try:
        import json
        side = json.loads(p.read_text(encoding="utf-8"))
        side["real_cell"] = {**(side.get("real_cell") or {}), **real_cell}
        save_json(p, side)
    except (OSError, ValueError, AttributeError):
        pass


def sample(sreq: SamplingRequest, req: LinkRequest) -> int:
    """The run on the real cell, its summary printed (JSON on stdout): the exit code (0
    complete, 1 stopped or gave up). The outputs were checked before the run (the output
    guard)."""
    from dataclasses import asdict

    from planecal.safety.collision import CollisionWorld
    from planecal.links.zs_ld80 import NO_READING, ZSLD80, LaserError
    from planecal.sampling.enable import FollowingMonitor
    from planecal.sampling.runfiles import count_samples
    from planecal.sampling.session import print_summary

    run = prepare(sreq)
    sreq, scene, settings, side = run.req, run.scene, run.settings, run.sidecar
    robot = scene.robot
    limit = _check_link_flags(req, robot)
    if side is not None and count_samples(Path(sreq.out)) >= settings.samples:
        print(f"note: {sreq.out} holds {count_samples(Path(sreq.out))} of the run's "
              f"{settings.samples} samples: nothing to do, the controller not contacted "
              "(--samples N asks for more)", file=sys.stderr)
        return 0
    model = command_model(sreq, scene, side)
    checker = CollisionWorld(scene, clearance_m=settings.clearance_m)
    cell = Controller(req, sreq.out, robot, side)  # nothing sent or written; one that cannot tell asks
    observer = raw_laser = None
    try:
        try:  # the laser's port before the controller's state folder and lock
            raw_laser = ZSLD80(req.laser, baudrate=req.baud,
                               timeout_s=req.laser_timeout_s, wait_s=req.laser_wait_s)
        except LaserError as e:
            raise InputError(f"--laser {req.laser}: {e}") from None
        cell.take()
        laser = TolerantLaser(raw_laser, req.laser_error_limit, (LaserError,), NO_READING)
        waited = cell.wait_for_silence()
        observer = rerun_observer(sreq, scene)
        monitor = FollowingMonitor(cell.link, limit, max_step_counts=robot.max_step_counts,
                                   trip_counts=robot.trip_step_counts, tick_s=robot.tick_s)
        before = ((side or {}).get("real_cell") or {}).get("link_total")
        real_cell = {"rt": req.rt, "rt_port": req.rt_port, "laser": req.laser,
                     "follow_limit_counts": limit, **cell.record(waited), "link_total": before}
        code, summary = _run(sreq, run.poses, scene, settings, checker, model, observer,
                             cell.link, laser, monitor, real_cell, before,
                             cell.recorded_reference)
    finally:
        if raw_laser is not None:
            raw_laser.close()
        cell.close()
        if observer is not None:
            observer.close()
    summary["laser_read_errors"] = laser.total
    summary["laser"] = {**asdict(raw_laser.counters), "no_reply_ticks": laser.no_reply_ticks}
    summary.update(observer_summary(observer))
    summary["link"] = real_cell["link"]
    summary["link_total"] = real_cell["link_total"]
    summary["first_contact"] = real_cell["first_contact"]  # with what the controller did
    summary["following"] = {"limit_counts": limit, "max_lag_counts": monitor.max_lag}
    print_summary(summary)
    return code


def _run(req: SamplingRequest, poses, scene, settings, checker, model, observer, link, laser,
         monitor, real_cell, before, recorded) -> tuple[int, dict]:
    """The session (`sampling.session`); a link or laser failure is one line (exit 1); the
    link counters go to the sidecar however it ends, and what the controller's first reply
    showed of its reference (``observed_reference``: "kept" -- the one ``recorded`` in the
    state file --, "new", or None when either is unknown)."""
    from dataclasses import asdict

    import numpy as np

    from planecal.links.fd11 import LinkError
    from planecal.links.zs_ld80 import LaserError
    from planecal.sampling.run import count_samples, sidecar_path
    from planecal.sampling.session import run_session

    session = session_for(req, pose_list_planner(req, poses, scene, settings, checker, model[0],
                                                 (model[1] or {}).get("params")),
                          observer, {"real_cell": real_cell}, hold_while_planning=True,
                          model=model)
    observed = None
    try:
        return run_session(session, scene, settings, monitor, laser, monitor, checker)
    except (LinkError, LaserError) as e:
        n = count_samples(Path(req.out)) if sidecar_path(req.out).exists() else 0
        where = (f"{n} samples so far are in {req.out}; continue with --resume" if n
                 else "nothing sampled")
        raise RunFailed(f"run stopped: {e} ({where})") from None
    finally:
        if recorded is not None and link.fd11_reference is not None:
            observed = "kept" if np.array_equal(link.fd11_reference, recorded) else "new"
        session_link = asdict(link.counters)
        real_cell["link"] = session_link
        real_cell["link_total"] = link_totals(before, session_link)
        real_cell["first_contact"]["observed_reference"] = observed
        # (nothing sent: the session never began -- e.g. another run holds the file)
        if link.counters.sent and sidecar_path(req.out).exists():
            _record_link(Path(req.out), {"link": session_link,
                                          "link_total": real_cell["link_total"],
                                          "first_contact": real_cell["first_contact"]})
