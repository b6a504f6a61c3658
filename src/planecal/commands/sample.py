"""`planecal sample`: the sampling run (seed 7.1) on the real cell.

    planecal sample --rt HOST [--laser PORT] [--samples N] [--seed K] [--cone-deg A]
                    [--fixed-distance-mm D] --out RUN.tsv [--resume] ...

The same loop as ``planecal rehearse`` (``planecal.sampling.run``) with the FD11 RT link
over UDP (``planecal.links.fd11.FD11Link``) and the ZS-LD80 on a serial port
(``planecal.links.zs_ld80.ZSLD80``), imported only when this command runs. Collision
checking (``planecal.safety.collision``) is always on; the operator still watches the robot
(seed 7.3.1): the model knows only what the scene file describes.

Dead-man switch: the PC cannot read the teach pendant's enabling device. The enable signal
is ``planecal.sampling.enable.FollowingMonitor``: it drops as soon as one more step could put
the command more than ``--follow-limit-counts`` ahead of the robot (default 211 counts, the
largest gap the servo takes up within the FD11's 60 counts a tick, from ``--servo-tau-s``;
enable.py derives it), which a released switch shows at the first reply after the robot
stopped. No further step is sent and the run stops cleanly; continue with ``--resume``
once the switch is held again.

The FD11 link (``planecal.links.fd11``) rides out lost replies: it resends the same delta
every ``--rt-resend-s`` and gives up only after ``--rt-silence-s`` without a reply
(``--rt-boot-timeout-s`` for the first contact, while the RT system may still be booting).
The summary's ``link`` reports the session's lost replies and outages, ``link_total``
those of every session of the run; both are written to the sidecar's ``real_cell`` when
the session ends (stopped, failed or complete).

The first packet (``planecal.links.sessions``): what the controller does with its
reference between client sessions is a stated property of the cell (robot.json
``controller.sessions``): it keeps it (the first packet repeats the last delta it
received), takes a fresh one after a silence (the run waits that silence out, then sends
delta 0) or takes one for each new client address. The controller's state -- the last
delta sent in a session it answered, its reference, the time of the last packet and the
client -- is kept in one file per controller (``--rt-state``, default
``$PLANECAL_STATE_DIR`` or ``~/.local/state/planecal/fd11-IP-PORT.state``), read by every
run against it. Where the behaviour is not stated and the controller was left at a delta
other than 0, the run asks (one line, exit 2): ``--rt-fresh`` states that the controller
took a fresh reference (e.g. the RT system was restarted), ``--rt-keep`` that it kept it.
The link refuses a first packet farther than the step limit from what the controller
holds, and checks the first reply before any motion (one line, exit 1, nothing more sent).

The RT link never goes quiet: while a pose is planned, and during the laser read, the hold
delta keeps being sent every 10 ms. The laser is polled once a tick without blocking it
(``ZSLD80.poll``: at most ``--laser-wait-s``); a tick whose reply has not come yet gives no
reading.

Laser: a garbled or missing reply, and a tick without a reply yet, count as an
out-of-range reading; ``--laser-error-limit`` errors in a row stop the run (cable, port,
power).
Exit 0 when all samples were taken; 1 when the run stopped, gave up, lost its link or
could not write its files (one line saying why; the files are valid and ``--resume``
continues); 2 for bad input or usage; 130 interrupted (SIGINT, SIGHUP), 143 terminated
(SIGTERM): the sidecar says ``stopped`` and which signal. Bounds: docs/LINKS.md.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planecal.base.errors import InputError, RunFailed
from planecal.commands.value_options import MAX_TRIES, count, host, port, port_or_zero


def add_arguments(p: argparse.ArgumentParser) -> None:
    from planecal.commands.sampling_options import add_sampling_arguments

    p.add_argument("--rt", type=host, required=True, metavar="HOST",
                   help="FD11 RT system address")
    p.add_argument("--rt-port", type=port, default=5555, help="FD11 UDP port (default 5555)")
    p.add_argument("--local-port", type=port_or_zero, default=5556,
                   help="local UDP port for the replies (default 5556; 0 = any)")
    p.add_argument("--rt-tick-s", type=float, default=0.01,
                   help="minimum interval between ticks (default 0.01; 0 for an emulator "
                        "on a virtual clock)")
    p.add_argument("--rt-resend-s", type=float, default=0.02,
                   help="resend the same delta when no reply came within this (default 0.02)")
    p.add_argument("--rt-silence-s", type=float, default=0.5,
                   help="give up when the link has been silent this long (default 0.5)")
    p.add_argument("--rt-boot-timeout-s", type=float, default=10.0,
                   help="how long the first contact may wait for a booting RT system "
                        "(default 10)")
    p.add_argument("--rt-state", default=None, metavar="FILE",
                   help="the controller's state file: last delta, reference, time of the last "
                        "packet (default: one per controller, $PLANECAL_STATE_DIR or "
                        "~/.local/state/planecal/fd11-IP-PORT.state)")
    who = p.add_mutually_exclusive_group()
    who.add_argument("--rt-fresh", action="store_true",
                     help="state for this run that the controller took a fresh reference "
                          "(e.g. the RT system was restarted): first packet delta 0")
    who.add_argument("--rt-keep", action="store_true",
                     help="state for this run that the controller kept its reference: the "
                          "first packet repeats the last delta it received")
    p.add_argument("--laser", default="/dev/ttyUSB0", metavar="PORT",
                   help="ZS-LD80 serial port (default /dev/ttyUSB0)")
    p.add_argument("--baud", type=count(10_000_000, 50), default=38400, help="laser baud rate (default 38400)")
    p.add_argument("--laser-timeout-s", type=float, default=0.1,
                   help="a laser request unanswered this long is an error (default 0.1)")
    p.add_argument("--laser-wait-s", type=float, default=0.005,
                   help="the longest a tick waits for the laser's reply (default 0.005)")
    p.add_argument("--laser-error-limit", type=count(MAX_TRIES), default=50,
                   help="stop after this many laser read errors in a row (default 50)")
    p.add_argument("--follow-limit-counts", type=count(MAX_TRIES), default=None,
                   help="the most the command may run ahead of the robot (default: derived "
                        "from --servo-tau-s, 211 counts)")
    p.add_argument("--servo-tau-s", type=float, default=None,
                   help="the FD11 servo's time constant (default 0.03)")
    add_sampling_arguments(p)


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


def _check_link_flags(args, robot) -> int:
    """The following limit (the link flags checked)."""
    from planecal.sampling.enable import SERVO_TAU_S, follow_limit_counts

    for flag in ("rt_resend_s", "rt_silence_s", "rt_boot_timeout_s", "laser_timeout_s"):
        v = getattr(args, flag)
        if not (v > 0 and v < float("inf")):
            raise InputError(f"--{flag.replace('_', '-')} must be a positive number of seconds")
    if args.rt_silence_s < args.rt_resend_s or args.rt_boot_timeout_s < args.rt_resend_s:
        raise InputError("--rt-silence-s and --rt-boot-timeout-s must be at least --rt-resend-s")
    if not 0 <= args.laser_wait_s <= args.laser_timeout_s:
        raise InputError("--laser-wait-s must be in 0..--laser-timeout-s")
    tau = SERVO_TAU_S if args.servo_tau_s is None else args.servo_tau_s
    if not (tau > 0 and tau < float("inf")):
        raise InputError("--servo-tau-s must be a positive number of seconds")
    limit = (follow_limit_counts(robot.trip_step_counts, tau, robot.tick_s)
             if args.follow_limit_counts is None else args.follow_limit_counts)
    if limit <= robot.max_step_counts:
        raise InputError(f"--follow-limit-counts must exceed the largest step "
                         f"({robot.max_step_counts} counts), got {limit}")
    return limit


class Controller:
    """The FD11 link with its state file, the controller's lock and the first contact
    (`planecal.links.sessions`): opened before any packet, closed in any case. Made in two
    steps: the link and the first contact (nothing written), then ``take()``: the state
    file's folder and the controller's lock."""

    def __init__(self, args, robot, side: dict | None = None):
        from planecal.links.fd11 import FD11Link, LinkError
        from planecal.links.sessions import (StateFile, default_state_path, plan_contact,
                                             stated_behaviour)
        from planecal.sampling.runfiles import sidecar_path

        self.link = self.lock = self.state = None
        try:
            self.link = FD11Link(args.rt, args.rt_port, args.local_port, tick_s=args.rt_tick_s,
                                 timeout_s=args.rt_resend_s, silence_s=args.rt_silence_s,
                                 boot_timeout_s=args.rt_boot_timeout_s,
                                 max_step_counts=robot.max_step_counts)
        except (LinkError, ValueError) as e:
            raise InputError(f"--rt {args.rt}: {e}") from None
        try:
            out = Path(args.out)
            path = Path(args.rt_state) if args.rt_state else default_state_path(self.link.remote)
            if path.resolve() in (out.resolve(), sidecar_path(out).resolve()):
                raise InputError(f"--rt-state {path}: is the run's own sample file or sidecar")
            self.path = path
            self.state = StateFile(path)
            override = "fresh" if args.rt_fresh else "keep" if args.rt_keep else None
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


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the run's
    files (``sampling_options.run_files``) and a state file given by --rt-state."""
    from planecal.commands.io_options import lock_output
    from planecal.commands.sampling_options import run_files
    from planecal.links.sessions import is_state_file
    f = run_files(args)
    if args.rt_state:
        f.write(args.rt_state, "--rt-state", (is_state_file,),
                hint="give the controller's state file")
        lock_output(f, args.rt_state, "--rt-state")
    return f


def run(args) -> int:
    from dataclasses import asdict

    from planecal.safety.collision import CollisionWorld
    from planecal.commands.sampling_options import (command_model, observer_summary, prepare,
                                                    rerun_observer)
    from planecal.links.zs_ld80 import NO_READING, ZSLD80, LaserError
    from planecal.sampling.enable import FollowingMonitor
    from planecal.sampling.runfiles import count_samples
    from planecal.sampling.session import print_summary

    scene, settings, side = prepare(args)
    robot = scene.robot
    limit = _check_link_flags(args, robot)
    if side is not None and count_samples(Path(args.out)) >= settings.samples:
        print(f"note: {args.out} holds {count_samples(Path(args.out))} of the run's "
              f"{settings.samples} samples: nothing to do, the controller not contacted "
              "(--samples N asks for more)", file=sys.stderr)
        return 0
    model = command_model(args, scene, side)
    checker = CollisionWorld(scene, clearance_m=settings.clearance_m)
    cell = Controller(args, robot, side)  # nothing sent or written; one that cannot tell asks
    observer = raw_laser = None
    try:
        try:  # the laser's port before the controller's state folder and lock
            raw_laser = ZSLD80(args.laser, baudrate=args.baud,
                               timeout_s=args.laser_timeout_s, wait_s=args.laser_wait_s)
        except LaserError as e:
            raise InputError(f"--laser {args.laser}: {e}") from None
        cell.take()
        laser = TolerantLaser(raw_laser, args.laser_error_limit, (LaserError,), NO_READING)
        waited = cell.wait_for_silence()
        observer = rerun_observer(args, scene)
        monitor = FollowingMonitor(cell.link, limit, max_step_counts=robot.max_step_counts,
                                   trip_counts=robot.trip_step_counts, tick_s=robot.tick_s)
        before = ((side or {}).get("real_cell") or {}).get("link_total")
        real_cell = {"rt": args.rt, "rt_port": args.rt_port, "laser": args.laser,
                     "follow_limit_counts": limit, **cell.record(waited), "link_total": before}
        code, summary = _run(args, scene, settings, checker, model, observer, cell.link, laser,
                             monitor, real_cell, before, cell.recorded_reference)
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


def _run(args, scene, settings, checker, model, observer, link, laser, monitor, real_cell,
         before, recorded) -> tuple[int, dict]:
    """The session (`sampling.session`); a link or laser failure is one line (exit 1); the
    link counters go to the sidecar however it ends, and what the controller's first reply
    showed of its reference (``observed_reference``: "kept" -- the one ``recorded`` in the
    state file --, "new", or None when either is unknown)."""
    from dataclasses import asdict

    import numpy as np

    from planecal.commands.sampling_options import pose_list_planner, session_from_args
    from planecal.links.fd11 import LinkError
    from planecal.links.zs_ld80 import LaserError
    from planecal.sampling.run import count_samples, sidecar_path
    from planecal.sampling.session import run_session

    session = session_from_args(args, pose_list_planner(args, scene, settings, checker,
                                                        model[0]),
                                observer, {"real_cell": real_cell}, hold_while_planning=True,
                                model=model)
    observed = None
    try:
        return run_session(session, scene, settings, monitor, laser, monitor, checker)
    except (LinkError, LaserError) as e:
        n = count_samples(Path(args.out)) if sidecar_path(args.out).exists() else 0
        where = (f"{n} samples so far are in {args.out}; continue with --resume" if n
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
        if link.counters.sent and sidecar_path(args.out).exists():
            _record_link(Path(args.out), {"link": session_link,
                                          "link_total": real_cell["link_total"],
                                          "first_contact": real_cell["first_contact"]})
