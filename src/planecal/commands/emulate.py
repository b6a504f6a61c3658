"""`planecal emulate`: serve the twin behind the real wire formats.

Starts the FD11 RT emulator (UDP) and the ZS-LD80 emulator (a pseudo-terminal), both
backed by one MuJoCo twin, prints where they listen and runs until Ctrl-C. Point
`planecal sample` at them (``--host``/ports and the printed serial device) to rehearse
the real-cell code path end to end. Formats: `planecal.links.fd11`, `planecal.links.zs_ld80`.
"""
from __future__ import annotations

import argparse

from planecal.errors import InputError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scene", default=None, help="twin scene name or JSON path (twin default)")
    p.add_argument("--seed", type=int, default=None, help="random seed of the twin's truth and noise")
    p.add_argument("--truth", default=None, metavar="T.json",
                   help="the twin's true parameters (JSON, as written by the twin; with its "
                        "world, as rehearse --truth writes it)")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default realistic: a robot of the MC70's "
                        "class; ideal: the nominal robot; or a profile file)")
    p.add_argument("--host", default="127.0.0.1", help="address the FD11 emulator binds")
    p.add_argument("--rt-port", type=int, default=5555,
                   help="UDP port receiving delta packets (FD11 remote port, default 5555)")
    p.add_argument("--reply-port", type=int, default=5556,
                   help="UDP port replies are sent to on the sender's host (default 5556; "
                        "0 = the sender's own port)")


def _make_twin(args):
    try:
        import planecal.twin as twin_mod
    except ModuleNotFoundError as e:
        if e.name and e.name.startswith("planecal.twin"):
            raise InputError("the MuJoCo twin (planecal.twin) is not available in this "
                             "version; cannot emulate") from None
        raise InputError(f"the MuJoCo twin cannot be loaded: missing module {e.name}") from None
    Twin = getattr(twin_mod, "Twin", None)
    if Twin is None:
        raise InputError("planecal.twin has no Twin class; cannot emulate")
    from planecal.commands.rehearse import make_twin
    from planecal.scene import DEFAULT_SCENE, load_scene
    from planecal.twin.profile import DEFAULT_PROFILE, load_profile, load_world
    scene = load_scene(args.scene or DEFAULT_SCENE)
    seed = 0 if args.seed is None else args.seed
    errors = args.errors or DEFAULT_PROFILE
    if args.truth is not None:  # that world, the profile's joint and laser errors
        return Twin(scene, truth=load_world(scene, args.truth), seed=seed,
                    options=load_profile(errors, scene.robot).options())
    return make_twin(scene, seed, errors)


def run(args) -> int:
    from planecal.links.emulators import serve

    twin = _make_twin(args)
    reply_port = None if args.reply_port == 0 else args.reply_port

    def ready(emus) -> None:
        for line in emus.describe():
            print(line, flush=True)
        print("running; Ctrl-C to stop", flush=True)

    try:
        serve(twin, twin, host=args.host, rt_port=args.rt_port, reply_port=reply_port,
              on_ready=ready)
    except OSError as e:
        raise InputError(str(e)) from None
    finally:
        close = getattr(twin, "close", None)
        if close is not None:
            close()
    return 0
