"""The sampling options ``planecal rehearse`` and ``planecal sample`` share: their flags,
the request they make (``jobs.sampling.SamplingRequest``: the run settings, the pose list,
the observer and the session are the job's) and the files a run reads and writes (the
output guard's declaration)."""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from planecal.base.errors import InputError
from planecal.commands.value_options import (MAX_SAMPLES, MAX_TRIES, MINUTES, count, port,
                                             port_or_zero, seed)
from planecal.sampling.poses import IK_CHOICES, PLATE_CHOICES
from planecal.sampling.runfiles import sidecar_path


def finite_float(text: str) -> float:
    """argparse type: a finite number (``nan``, ``inf`` refused with the option named)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return v


def add_sampling_arguments(p: argparse.ArgumentParser, default_samples: int = 150) -> None:
    p.add_argument("--out", required=True, metavar="RUN.tsv",
                   help="sample file to write (its sidecar is RUN.tsv.json)")
    p.add_argument("--scene", default=None, help="scene name or JSON path (default thesis_final)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=None,
                   help=f"number of samples (default {default_samples}; with --resume: a new target)")
    p.add_argument("--seed", type=seed, default=None, help="random seed of the poses (default 0)")
    p.add_argument("--cone-deg", type=finite_float, default=None,
                   help="half-angle of the beam cone about the plate normal (default: the scene's)")
    p.add_argument("--fixed-distance-mm", type=finite_float, default=None,
                   help="measure at this distance instead of a random one")
    p.add_argument("--distance-mm", type=finite_float, nargs=2, default=None, metavar=("LO", "HI"),
                   help="range of random distances (default: the scene's)")
    p.add_argument("--roll-deg", type=finite_float, default=None,
                   help="random rotation about the beam within +-this (default 180: any)")
    p.add_argument("--margin-mm", type=finite_float, default=None,
                   help="keep the laser spot this far inside the plate edges (default 25)")
    p.add_argument("--plate-choice", choices=PLATE_CHOICES, default=None,
                   help="multi-plate scenes: plate per sample (default round_robin)")
    p.add_argument("--ik-choice", choices=IK_CHOICES, default=None,
                   help="IK solution per pose: wrist = the wrist branch changes at random, "
                        "p 0.1 per pose (seed 7.1.2: large joint changes), nearest = the "
                        "nearest to the current configuration (default wrist)")
    p.add_argument("--clearance-mm", type=finite_float, default=None,
                   help="collision clearance (default 10)")
    p.add_argument("--laser-max-reads", type=count(MAX_TRIES), default=None,
                   help="give a pose up after this many laser reads without a stable buffer "
                        "(default 1000)")
    p.add_argument("--max-attempts", type=count(MAX_TRIES), default=None,
                   help="stop after this many poses rejected in a row (default 500)")
    p.add_argument("--robot-minutes", type=MINUTES, default=None, metavar="MIN",
                   help="end the run, complete, where its next pose might not fit in this much "
                        "robot time (its moves and the laser's longest read; on the real "
                        "cell the hold while a plan is made counts too, and the wait for "
                        "the last plan can overrun it); default: no budget; with --resume: "
                        "a new budget, counting every session")
    p.add_argument("--start", choices=("here", "calibration", "home"), default="here",
                   help="move there before sampling (default: sample from where the robot is)")
    p.add_argument("--end", choices=("stay", "calibration", "home"), default="stay",
                   help="move there after a complete run (default stay)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out with the scene and settings of its sidecar")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out")
    p.add_argument("--decimal-comma", action="store_true",
                   help="write distances with a decimal comma (92,520000), as the seed's "
                        "LabVIEW tools do; readers accept both; a resumed run keeps its file's")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="record the run for Rerun (planecal view FILE opens it)")
    p.add_argument("--live", action="store_true",
                   help="stream the run to a Rerun viewer as it happens (the recording's "
                        "blueprint): a web viewer on --live-web-port, the stream on "
                        "127.0.0.1:--live-port; the real-time loop never waits for it")
    p.add_argument("--live-port", type=port, default=9876,
                   help="--live: the stream's gRPC port on 127.0.0.1 (default %(default)s)")
    p.add_argument("--live-web-port", type=port_or_zero, default=9090,
                   help="--live: the web viewer's port (0: none, connect a native viewer: "
                        "rerun rerun+http://127.0.0.1:PORT/proxy) (default %(default)s)")
    p.add_argument("--params", default=None, metavar="RESULT.json",
                   help="aim with this calibration result (its sensor pose, planes and joint "
                        "offsets) instead of the scene's nominal values: live validation "
                        "(seed 8.2, 8.4)")
    p.add_argument("--encoder-offsets", default=None, metavar="FD11.json",
                   help="the encoder offsets loaded into the controller (planecal export "
                        "--out): joint angles become counts with them; with --params its "
                        "joint offsets are taken as realised by them, not added again")
    p.add_argument("--poses", default=None, metavar="POSES.json",
                   help="visit this planned pose list (planecal plan) instead of random poses; "
                        "--samples defaults to its length")
    p.add_argument("--foreground", action="store_true",
                   help="plan poses in this process only (default: plan the next pose in a "
                        "forked process while the robot moves)")


def sampling_request(args):
    """The sampling run's request (``jobs.sampling.SamplingRequest``) of the flags."""
    from planecal.jobs.sampling import SamplingRequest
    return SamplingRequest.of(vars(args))


def recorded_files(side: dict | None) -> list:
    """The files a run's sidecar records (scene, pose list, aiming model, truth file, error
    profile file): what a resumed run reads."""
    if not isinstance(side, dict):
        return []
    twin = side.get("twin") if isinstance(side.get("twin"), dict) else {}
    cmd = side.get("command") if isinstance(side.get("command"), dict) else {}
    out = [side.get("scene_path"), side.get("poses"), cmd.get("params"),
           cmd.get("encoder_offsets"), twin.get("truth_file"), twin.get("errors")]
    return [p for p in out if isinstance(p, str) and p and ("/" in p or p.endswith(".json"))]


def run_files(args):
    """What a sampling run reads and writes (``commands.io_options``), for the output guard:
    the sample file, its sidecar and lock, the recording; the pose list, the aiming model
    and the scene, or on --resume those its sidecar records."""
    from planecal.commands.io_options import (SIDECAR_FORMAT, Files, lock_output, rrd_output,
                                              sample_file_is_ours, scene_inputs)
    from planecal.formats.base import read_json

    out = Path(args.out)
    side = None
    if args.resume:
        try:
            side = read_json(sidecar_path(out), "run sidecar")
        except InputError:
            side = None  # its reader says why, later
        side = side if isinstance(side, dict) else None
    f = Files().read(args.poses, args.params, args.encoder_offsets, *recorded_files(side),
                     *scene_inputs(args.scene if side is None else side.get("scene_path")))
    hint = "use --resume to continue that run or --force to overwrite it"
    f.write(out, "--out", (sample_file_is_ours,), keep=args.resume, hint=hint)
    f.write(sidecar_path(out), "--out's sidecar", SIDECAR_FORMAT, keep=args.resume, hint=hint)
    lock_output(f, out, "--out")
    rrd_output(f, args.rrd)
    return f


