"""`planecal sample`: the sampling run (seed 7.1) on the real cell.

    planecal sample --rt HOST [--laser PORT] [--samples N] [--seed K] [--cone-deg A]
                    [--fixed-distance-mm D] --out RUN.tsv [--resume] ...

The same loop as ``planecal rehearse`` (``planecal.sampling.run``) with the FD11 RT link
over UDP (``planecal.links.fd11.FD11Link``) and the ZS-LD80 on a serial port
(``planecal.links.zs_ld80.ZSLD80``), imported only when this command runs. Collision
checking (``planecal.collision``) is always on; the operator still watches the robot
(seed 7.3.1): the model knows only what the scene file describes.

Dead-man switch: the PC cannot read the teach pendant's enabling device. The enable signal
is ``planecal.sampling.enable.FollowingMonitor``: when the robot stops following the
command (commanded minus current counts above ``--lag-tolerance-counts`` on a joint for
``--lag-ticks`` ticks in a row, which is what happens when the switch is released while a
path is sent), no further step is sent and the run stops cleanly; continue with
``--resume`` once the switch is held again (the FD11 reference is re-read where the robot
stands).

The RT link never goes quiet: while a pose is planned, and during the laser read, the hold
delta keeps being sent every 10 ms.

Laser: a single garbled or missing reply counts as an out-of-range reading;
``--laser-error-limit`` failures in a row stop the run (cable, port, power).
Exit 0 when all samples were taken, 1 when the run stopped or gave up (files valid).
"""
from __future__ import annotations

import argparse
from pathlib import Path

from planecal.errors import InputError


def add_arguments(p: argparse.ArgumentParser) -> None:
    from planecal.commands.sampling_options import add_sampling_arguments

    p.add_argument("--rt", required=True, metavar="HOST", help="FD11 RT system address")
    p.add_argument("--rt-port", type=int, default=5555, help="FD11 UDP port (default 5555)")
    p.add_argument("--local-port", type=int, default=5556,
                   help="local UDP port for the replies (default 5556; 0 = any)")
    p.add_argument("--rt-tick-s", type=float, default=0.01,
                   help="minimum interval between ticks (default 0.01; 0 for an emulator "
                        "on a virtual clock)")
    p.add_argument("--laser", default="/dev/ttyUSB0", metavar="PORT",
                   help="ZS-LD80 serial port (default /dev/ttyUSB0)")
    p.add_argument("--baud", type=int, default=38400, help="laser baud rate (default 38400)")
    p.add_argument("--laser-error-limit", type=int, default=50,
                   help="stop after this many laser read errors in a row (default 50)")
    p.add_argument("--lag-tolerance-counts", type=int, default=600,
                   help="enable drops when a joint lags the command by more than this "
                        "(default 600 counts)...")
    p.add_argument("--lag-ticks", type=int, default=5,
                   help="...for this many ticks in a row (default 5)")
    add_sampling_arguments(p)


class TolerantLaser:
    """A Laser wrapper: a read error counts as an out-of-range reading (None); ``limit``
    errors in a row re-raise the last one."""

    def __init__(self, laser, limit: int, errors: tuple):
        self.laser = laser
        self.limit = limit
        self.errors = errors
        self.in_a_row = 0
        self.total = 0

    def read(self):
        try:
            v = self.laser.read()
        except self.errors:
            self.in_a_row += 1
            self.total += 1
            if self.in_a_row >= self.limit:
                raise
            return None
        self.in_a_row = 0
        return v

    def close(self):
        self.laser.close()


def run(args) -> int:
    from planecal.commands.rehearse import make_checker
    from planecal.links.fd11 import FD11Link, LinkError
    from planecal.links.zs_ld80 import ZSLD80, LaserError
    from planecal.sampling.enable import FollowingMonitor
    from planecal.sampling.run import count_samples, sidecar_path
    from planecal.commands.sampling_options import (command_model, pose_list_planner, prepare,
                                                    rerun_observer, session_from_args)
    from planecal.sampling.session import print_summary, run_session

    if args.lag_tolerance_counts <= 0 or args.lag_ticks <= 0:
        raise InputError("--lag-tolerance-counts and --lag-ticks must be positive")
    if args.laser_error_limit < 1:
        raise InputError("--laser-error-limit must be at least 1")
    scene, settings, side = prepare(args)
    model = command_model(args, scene, side)
    checker = make_checker(scene, settings.clearance_m)
    observer = rerun_observer(args.rrd, scene) if args.rrd else None
    try:
        link = FD11Link(args.rt, args.rt_port, args.local_port, tick_s=args.rt_tick_s)
    except (LinkError, ValueError) as e:
        raise InputError(f"--rt {args.rt}: {e}") from None
    try:
        try:
            raw_laser = ZSLD80(args.laser, baudrate=args.baud)
        except LaserError as e:
            raise InputError(f"--laser {args.laser}: {e}") from None
        laser = TolerantLaser(raw_laser, args.laser_error_limit, (LaserError,))
        monitor = FollowingMonitor(link, args.lag_tolerance_counts, args.lag_ticks)
        extra = {"real_cell": {"rt": args.rt, "rt_port": args.rt_port, "laser": args.laser,
                               "lag_tolerance_counts": args.lag_tolerance_counts,
                               "lag_ticks": args.lag_ticks}}
        session = session_from_args(args, pose_list_planner(args, scene, settings, checker,
                                                            model[0]),
                                    observer, extra, hold_while_planning=True, model=model)
        try:
            code, summary = run_session(session, scene, settings, monitor, laser, monitor,
                                        checker)
        except (LinkError, LaserError) as e:
            n = count_samples(Path(args.out)) if sidecar_path(args.out).exists() else 0
            where = (f"{n} samples so far are in {args.out}; continue with --resume" if n
                     else "nothing sampled")
            raise InputError(f"run stopped: {e} ({where})") from None
        finally:
            laser.close()
    finally:
        link.close()
        if observer is not None:
            observer.close()
    summary["laser_read_errors"] = laser.total
    if args.rrd:
        summary["rrd"] = str(observer.path)
    summary["link"] = {k: int(v) for k, v in vars(link.counters).items()}
    print_summary(summary)
    return code
