"""`planecal emulate`: serve the twin behind the real wire formats.

Starts the FD11 RT emulator (UDP) and the ZS-LD80 emulator (a pseudo-terminal), both
backed by one MuJoCo twin, prints where they listen and runs until Ctrl-C. Point
`planecal sample` at them (``--host``/ports and the printed serial device) to rehearse
the real-cell code path end to end. Formats: `planecal.links.fd11`, `planecal.links.zs_ld80`.
The twin's world is drawn from ``--errors`` (ideal|realistic|FILE.json, default realistic,
as ``rehearse``) and ``--seed``, or read from ``--truth`` (a truth file ``rehearse --truth``
wrote; the profile then gives the twin's noise and servo).

It serves any number of client sessions in a row (``sample``, ``sample --resume``, ...).
``--reference`` says what the emulated controller does with its reference between them,
in the words of robot.json's ``controller.sessions`` (`planecal.links.sessions`; the
seed reads both ways): ``keep`` keeps the one it started with, so a client must carry on
from the last delta it sent; ``fresh_after_silence`` takes the robot's counts as a new
reference at a request after ``--silence-s`` (default 2) without any, so the first delta
must be 0; ``fresh_each_client`` does so at a request from another client address. The
default is what the scene's robot.json states, else ``fresh_after_silence``.

Faults, all deterministic (`planecal.links.emulators`): ``--drop-replies P`` (alias
``--drop-rate``) loses each reply with probability P (``--fault-seed``, alias
``--drop-seed``), ``--boot-silence-s S`` ignores every request for S seconds after start,
``--laser-silent-every K`` leaves every K-th laser request unanswered,
``--release-after-ticks N`` (or ``--release-after-moves N``, ticks that command motion)
releases the dead-man switch (held again when the next session starts). On exit it prints
its counters in one line (``served: fd11 {...} laser {...}``), whichever signal ends it
(SIGINT, SIGTERM, SIGHUP). Bounds: docs/LINKS.md.
"""
from __future__ import annotations

import argparse

from planecal.base.errors import InputError
from planecal.commands.value_options import MAX_TRIES, count, host, port_or_zero, seed


def add_arguments(p: argparse.ArgumentParser) -> None:
    from planecal.formats.robot import REFERENCE_BEHAVIOURS

    p.add_argument("--scene", default=None, help="twin scene name or JSON path (twin default)")
    p.add_argument("--seed", type=seed, default=None, help="random seed of the twin's truth and noise")
    p.add_argument("--truth", default=None, metavar="T.json",
                   help="the twin's hidden truth (a parameter file, e.g. written by "
                        "`rehearse --truth-out`; default: drawn from --errors and --seed)")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile: realistic (default: a robot of the MC70's "
                        "class), ideal (the nominal robot), or a profile file")
    p.add_argument("--host", type=host, default="127.0.0.1",
                   help="address the FD11 emulator binds (0.0.0.0: every interface)")
    p.add_argument("--rt-port", type=port_or_zero, default=5555,
                   help="UDP port receiving delta packets (FD11 remote port, default 5555)")
    p.add_argument("--reply-port", type=port_or_zero, default=5556,
                   help="UDP port replies are sent to on the sender's host (default 5556; "
                        "0 = the sender's own port)")
    p.add_argument("--reference", choices=REFERENCE_BEHAVIOURS, default=None,
                   help="what the controller does with its reference between client "
                        "sessions: keep it, take the robot's counts after --silence-s of "
                        "silence, or at each new client address (default: what the scene's "
                        "robot.json states, else fresh_after_silence)")
    p.add_argument("--silence-s", "--session-gap-s", dest="session_gap_s", type=float,
                   default=None, metavar="S",
                   help="silence after which a request begins a new session (and, with "
                        "fresh_after_silence, a new reference) (default: robot.json's, else 2)")
    p.add_argument("--drop-replies", "--drop-rate", dest="drop_replies", type=float,
                   default=0.0, metavar="P",
                   help="fault: lose each FD11 reply with probability P (default 0)")
    p.add_argument("--fault-seed", "--drop-seed", dest="fault_seed", type=seed, default=0,
                   help="seed of the random faults (default 0)")
    p.add_argument("--boot-silence-s", type=float, default=0.0,
                   help="fault: the RT system answers nothing for this long after start")
    p.add_argument("--laser-silent-every", type=count(MAX_TRIES, 0), default=0, metavar="K",
                   help="fault: every K-th laser request goes unanswered")
    p.add_argument("--release-after-ticks", type=count(2**40, 0), default=0, metavar="N",
                   help="fault: the dead-man switch is released after N ticks")
    p.add_argument("--release-after-moves", type=count(2**40, 0), default=0, metavar="N",
                   help="fault: the dead-man switch is released after N ticks that command "
                        "motion (hold ticks not counted: reproducible on any machine)")


def _faults(args):
    import math

    from planecal.links.emulators import FD11Faults, LaserFaults

    if not 0.0 <= args.drop_replies < 1.0:
        raise InputError(f"--drop-replies must be in [0, 1), got {args.drop_replies}")
    if args.session_gap_s is not None and not (math.isfinite(args.session_gap_s)
                                               and args.session_gap_s > 0):
        raise InputError(f"--silence-s must be a positive number, got {args.session_gap_s}")
    if not (math.isfinite(args.boot_silence_s) and args.boot_silence_s >= 0):
        raise InputError(f"--boot-silence-s must be a number >= 0, got {args.boot_silence_s}")
    return (FD11Faults(drop_probability=args.drop_replies, seed=args.fault_seed,
                       boot_s=args.boot_silence_s,
                       release_after_ticks=args.release_after_ticks,
                       release_after_moves=args.release_after_moves),
            LaserFaults(silent_every=args.laser_silent_every))


def _make_twin(args):
    """The twin behind the wire: the world of --truth (its error profile, or --errors), or
    the profile's draw for --seed; the world builder ``rehearse`` uses."""
    from planecal.model.scene import load_scene
    from planecal.twin.profile import DEFAULT_PROFILE, truth_file_errors
    from planecal.twin.world import WorldRef, file_sha256, make_twin

    seed = 0 if args.seed is None else args.seed
    scene = load_scene(args.scene) if args.scene else load_scene()
    if args.truth is not None:
        errors = args.errors or truth_file_errors(args.truth) or DEFAULT_PROFILE
        ref = WorldRef(errors, None, str(args.truth), file_sha256(args.truth))
    else:
        ref = WorldRef(args.errors or DEFAULT_PROFILE, seed)
    return make_twin(scene, ref, seed)


def _reference(args, robot) -> tuple[str, float]:
    """The emulated controller's reference behaviour and silence: the flags, else what the
    robot states, else fresh_after_silence after 2 s."""
    from planecal.links.emulators import SESSION_GAP_S
    from planecal.links.sessions import stated_behaviour

    stated = stated_behaviour(robot.source)
    mode = args.reference or (stated.reference if stated else "fresh_after_silence")
    gap = args.session_gap_s
    if gap is None:
        gap = stated.silence_s if stated and stated.silence_s else SESSION_GAP_S
    return mode, gap


def run(args) -> int:
    from planecal.links.emulators import serve

    fd11_faults, laser_faults = _faults(args)
    twin = _make_twin(args)
    reference_mode, session_gap_s = _reference(args, twin.scene.robot)
    print(f"twin: scene {twin.scene.name}, errors {args.errors or 'realistic'}, seed "
          f"{twin.seed}" + (f", truth {args.truth}" if args.truth else ""), flush=True)
    reply_port = None if args.reply_port == 0 else args.reply_port

    served = []

    def ready(emus) -> None:
        served.append(emus)
        for line in emus.describe():
            print(line, flush=True)
        print("running; Ctrl-C to stop", flush=True)

    try:
        serve(twin, twin, host=args.host, rt_port=args.rt_port, reply_port=reply_port,
              on_ready=ready, fd11_faults=fd11_faults, laser_faults=laser_faults,
              reference_mode=reference_mode, session_gap_s=session_gap_s)
    except OSError as e:
        raise InputError(str(e)) from None
    finally:
        twin.close()
        if served:  # what was served, faults included (the threads have stopped)
            print(counters_line(served[0]), flush=True)
    return 0


def counters_line(emus) -> str:
    """``served: fd11 {...} laser {...}``: the emulators' counters as JSON, one line."""
    import json
    from dataclasses import asdict

    return (f"served: fd11 {json.dumps(asdict(emus.fd11.counters))} "
            f"laser {json.dumps(asdict(emus.laser.counters))}")
