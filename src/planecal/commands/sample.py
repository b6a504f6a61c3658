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
    from planecal.commands.sampling_options import sampling_request
    from planecal.jobs.real_cell import LinkRequest, sample

    return sample(sampling_request(args), LinkRequest.of(vars(args)))
