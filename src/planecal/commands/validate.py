"""planecal validate [--scene S] [--out V.json] [--errors ideal|realistic|FILE.json]
[--truth-seeds 0,1,2,3,4] [--samples N] [--seed K] [--offsets-all] [--cycles 30]
[--cube-mm E] [--tcp-mm X,Y,Z] [--block-mm L] [--poses POSES.json]
[--breakdown alone|off|none] [--breakdown-truth T] [--jobs J] [--level L]
[--compliance] [--free NAMES] [--calibrated R.json --truth T.json --run RUN.tsv]

ISO 9283 pose accuracy AP and repeatability RP (P1..P5, 30 cycles) in two cubes -- one
centred on a calibration sample (near the samples), and the standard's (the largest cube
inside the samples' flange hull) -- and the gauge-block test (seed 9.3, aimed with the
calibrated model; where it cannot be measured, why, beside the ISO figures) on the twin,
in the world of an error profile (--errors, default realistic). AP is measured where the
tool is: at the tool point (the laser's beam point at its measuring centre; each model
commands its own estimate of it onto the ISO point), with the flange and the scene's named
TCPs (and --tcp-mm's) beside it, in the robot's frame (J1's axis and zero) and the cell
frame. Every truth is commanded by the nominal model, the calibration at --level and at
each level below it (on the same poses), each level's floor (its own model with the
parameters that best fit the twin's true tool points at the samples' poses: the best a
calibration of that level can do) and the twin's own whole true model (the oracle,
backlash by the approach direction: repeatability and whole counts are what it leaves).

With no calibration given: for each truth seed T, draw that world, rehearse a calibration
set on its twin with seed --seed + T (the sampling run's planner with collision checks;
each truth its own draw of the poses and the noise: at --seed 0, truth T's run is
``planecal rehearse --seed T``'s), calibrate it from the nominal values with the
options every calibrating command takes (--level, --compliance, --free, ...: the one
calibration, ``estimation.calibrate``), and validate on the same world; the truths run
on ``studies.distributed.Engine`` (--jobs 1: in this process).
Prints the per-truth figures with the median and the worst truth, then (--breakdown,
default alone) the first truth again without the noise (the same poses rehearsed
noise-free: the noise's share apart) and with each error source of the profile on alone
(off: switched off in turn, the noise off too): what the calibration leaves of each, and
what limits it (docs/ERRORS.md).

With --calibrated, --truth and --run: validate an existing calibration result (any level)
in the world it was made in: the truth file of ``rehearse --truth`` holds that world (the
robot's true geometry, the gear and laser phases), the run's sidecar names its error
profile.

--out writes JSON (format planecal-validate/3; a /1 file, whose ``ap_after_mm`` was the
flange's, is refused by ``planecal report``): ``truths`` (per truth ``ap_before_tool_mm``,
``ap_after_tool_mm``, ``ap_floor_tool_mm``, ``ap_oracle_tool_mm``, ``rp_after_tool_mm``,
the same ``_flange_``, ``_cell_`` and in the standard's cube ``_standard_``, each level's
under ``levels``, the named TCPs', the ISO points' distances to the nearest sample in each
cube, ``gauge_failed``), their medians and worsts (``ap_after_tool_median_mm``, ...),
``breakdown``, ``level``, and the median truth's details under the single-truth keys
(``iso``, ``iso_standard``, ``cube``, ``standard_cube``, ``floors``, ``cell_frame``,
``gauge``, ...).
"""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError
from planecal.commands.value_options import (MAX_ITERATIONS, MAX_SAMPLES, MINUTES, count, seed,
                                             seed_list)


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the truths' runs, or the cell of --calibrated and --run",
                       reads="--run's sidecar and --calibrated's provenance")
    p.add_argument("--out", help="write the result (JSON) here")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write a Rerun recording of the validation (the median truth's)")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier validate result")
    p.add_argument("--errors", default=None, metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default: realistic; with --truth: the "
                        "run's, else ideal for a truth file without a world)")
    p.add_argument("--truth-seeds", type=seed_list, default=None,
                   help="seeds of the truths (worlds) to validate on (default 0,1,2,3,4)")
    p.add_argument("--truth-seed", type=seed, default=None,
                   help="one truth seed (the same as --truth-seeds T)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150, help="rehearsal samples (default 150)")
    p.add_argument("--seed", type=seed, default=0,
                   help="rehearsal seed: truth T's calibration run is rehearsed with seed "
                        "K + T (its poses and noise; at 0 it is `planecal rehearse --seed "
                        "T`'s run)")
    p.add_argument("--offsets-all", action="store_true",
                   help="the ideal world with delta1 and delta6 != 0 as well (the realistic "
                        "one has them)")
    p.add_argument("--cycles", type=count(MAX_ITERATIONS), default=30, help="ISO cycles (default 30)")
    p.add_argument("--cube-mm", type=float, default=None, help="ISO cube edge (default: from the samples)")
    p.add_argument("--tcp-mm", default=None, metavar="X,Y,Z",
                   help="a TCP in the flange frame [mm] to measure AP at too (named 'tcp'), "
                        "besides the tool point, the flange and the scene's named TCPs")
    p.add_argument("--block-mm", type=float, default=100.0, help="gauge block length (default 100)")
    p.add_argument("--gauge-repeats", type=count(MAX_ITERATIONS), default=10)
    p.add_argument("--poses", help="rehearse through this planned pose list (planecal plan) "
                                   "instead of random poses")
    p.add_argument("--aim-samples", type=count(MAX_SAMPLES, 0), default=None, metavar="N",
                   help="with --poses: a first random run of N samples, calibrated at level "
                        "offsets, aims the list before it runs (default 30 for a list planned "
                        "from the nominal cell, 0 for one planned with --params); its samples "
                        "join the calibration")
    p.add_argument("--robot-minutes", type=MINUTES, default=None, metavar="MIN",
                   help="end each truth's calibration run where its next pose might not fit in "
                        "this much robot time (both stages with --poses; default: no budget)")
    p.add_argument("--breakdown", default="alone", choices=("alone", "off", "none"),
                   help="repeat one truth with each error source of the profile on alone "
                        "(alone), or switched off in turn (off), or not (none) "
                        "(default alone)")
    p.add_argument("--breakdown-truth", type=seed, default=None,
                   help="the truth seed of the breakdown (default: the first truth seed)")
    from planecal.commands.calibration_options import add_calibration_arguments
    add_calibration_arguments(p)
    from planecal.commands.engine_options import add_engine_arguments
    add_engine_arguments(p)
    p.add_argument("--calibrated", help="calibration result to validate (with --truth and --run)")
    p.add_argument("--truth", help="the truth file of the world the calibration's run was "
                   "made in (rehearse --truth-out, or the file rehearse --truth ran in)")
    p.add_argument("--run", help="the calibration's sample file (places the ISO cube)")
    from planecal.commands.history_options import add_history_arguments
    add_history_arguments(p)


def _tcp(text):
    if text is None:
        return None
    try:
        v = [float(x) * 1e-3 for x in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 3 or not all(np.isfinite(v)):
        raise InputError(f"--tcp-mm: expected three numbers X,Y,Z, got {text!r}")
    return tuple(v)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import run_scene_inputs
    from planecal.commands.io_options import Files, profile_inputs, rrd_output, with_sidecars
    from planecal.studies.validation import FORMAT, OLD_FORMATS
    f = Files().read(*run_scene_inputs([args.run] if args.run else [], args.scene),
                     *profile_inputs(args.errors, args.scene), args.poses, args.calibrated, args.truth, *with_sidecars([args.run]))
    f.write(args.out, "--out", (FORMAT, *OLD_FORMATS))  # a /1 or /2 file is validate's own too
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.commands.calibration_options import calibration_settings
    from planecal.commands.engine_options import engine_from_args
    from planecal.commands.history_options import open_history
    from planecal.jobs.validate import ValidateRequest, validate
    from planecal.studies.validation import ValidationSettings

    given = [a for a in (args.calibrated, args.truth, args.run) if a]
    if given and len(given) != 3:
        raise InputError("--calibrated, --truth and --run go together")
    if args.truth_seed is not None and args.truth_seeds is not None:
        raise InputError("--truth-seed and --truth-seeds: give one of them")
    hist = open_history(args, given + [args.out])
    st = ValidationSettings(cycles=args.cycles,
                            cube_edge_m=None if args.cube_mm is None else args.cube_mm * 1e-3,
                            tcp_m=_tcp(args.tcp_mm), block_length_m=args.block_mm * 1e-3,
                            gauge_repeats=args.gauge_repeats, seed=args.seed)
    st.check()
    seeds = [args.truth_seed] if args.truth_seed is not None else args.truth_seeds
    doc, scene = validate(ValidateRequest(
        st, lambda robot: calibration_settings(args, robot),
        lambda warmup: engine_from_args(args, warmup=warmup), args.scene, args.out, args.rrd,
        args.errors, None if seeds is None else tuple(seeds), args.samples, args.seed,
        args.offsets_all, args.poses, args.breakdown, args.breakdown_truth, args.calibrated,
        args.truth, args.run, args.quiet, args.aim_samples, args.robot_minutes))
    return _history(args, hist, scene, doc)


def _history(args, hist, scene, doc: dict) -> int:
    """The validation's entry in the cell's history (linked to the calibration it
    validated, where it read one)."""
    from planecal.commands.history_options import (command_provenance, new_entry, record,
                                                   result_link)
    if hist is None:
        return 0
    sha, against = result_link(hist, args.calibrated) if args.calibrated else (None, None)
    prov = command_provenance(scene, [("calibrated", args.calibrated), ("truth", args.truth),
                                      ("run", args.run)])
    world = doc.get("world") or {"errors": doc.get("errors"), "truth_seeds": doc.get("truth_seeds")}
    summary = {k: doc.get(k) for k in ("ap_before_tool_median_mm", "ap_after_tool_median_mm",
                                       "ap_after_tool_worst_mm", "ap_oracle_tool_median_mm",
                                       "ap_floor_tool_median_mm",
                                       "ap_after_tool_standard_median_mm")}
    summary.update(truths=len(doc.get("truths") or []), level=doc.get("level"),
                   where="the tool point (the laser's beam point), robot frame")
    return record(hist, new_entry(args, "validate", "ok", 0, prov, robot_sha256=scene.robot.digest,
                           against=against, result_sha256=sha, world=world, summary=summary,
                           document=doc, output=args.out))


