"""planecal demo [--scene S] [--samples N] [--seed K] [--dir D] [--errors ideal|realistic|FILE]
[--level offsets|full|nonkinematic] [--compliance] [--rrd FILE] [--force]

The main job on the built-in twin: rehearse a sampling run on the default scene (the
thesis's final cell) in the world of an error profile (default realistic: a robot of the
MC70's class, with the errors a real one has) by running ``planecal rehearse``, calibrate
from the scene's nominal values exactly as ``planecal calibrate`` would (the same
calibration options), then show what the calibration did: the position
error before and after in the calibrated region (ISO 9283 AP on the same twin,
``studies.validation``), and the identified joint offsets against the twin's hidden truth
in units of the reported standard deviations, with why they can sit far from it.

Files land in ``--dir`` (default runs/demo): demo.tsv (+ sidecar), truth.json (with the
world, ``twin.profile.save_truth``), result.json. The demo replaces its own earlier files
(recognised by their format: a run sidecar, a parameter file, a result file) and nothing
else unless --force. Exit 0; 1 when the fit failed: not converged (it stops there), or a
parameter not identifiable (``planecal calibrate``'s failure; the demo still shows the
position error and the offsets, then exits 1).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from planecal.base.errors import RunFailed
from planecal.commands.value_options import MAX_SAMPLES, count, seed
from planecal.base.paths import DEFAULT_SCENE

DEMO_CYCLES = 10  # ISO cycles of the demo's position-error check (validate: 30)


def add_arguments(p):
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150, help="samples to take (default %(default)s)")
    p.add_argument("--seed", type=seed, default=1, help="seed of poses and twin truth (default %(default)s)")
    p.add_argument("--dir", default="runs/demo", help="output directory (default %(default)s)")
    p.add_argument("--errors", default="realistic", metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default %(default)s)")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write Rerun recordings of the run and of the fit (a directory, "
                        "a file name, or 'auto' for recordings/)")
    p.add_argument("--force", action="store_true",
                   help="replace files in --dir even if the demo did not write them")
    from planecal.commands.calibration_options import add_calibration_arguments
    add_calibration_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the scene
    and the error profile; the folder (made with its parents) and the demo's files in it,
    each replaced only when the demo wrote it (its format; the sample file: its sidecar's)."""
    from planecal.commands.io_options import (SIDECAR_FORMAT, Files, profile_inputs,
                                              rrd_output, sample_file_is_ours, scene_inputs)
    from planecal.formats.params import PARAMS_FORMAT, RESULT_FORMAT
    f = Files().read(*scene_inputs(args.scene), *profile_inputs(args.errors, args.scene))
    members = (("demo.tsv", (sample_file_is_ours,)), ("demo.tsv.json", (SIDECAR_FORMAT,)),
               ("demo.tsv.lock", ()), ("truth.json", (PARAMS_FORMAT,)),
               ("result.json", (RESULT_FORMAT,)))
    f.write(args.dir, "--dir", folder=True, parents=True, members=members)
    rrd_output(f, args.rrd)
    return f


def _files(out: Path) -> tuple[Path, Path, Path]:
    return out / "demo.tsv", out / "truth.json", out / "result.json"


WHY_OFF = (
    "Why the offsets can sit several std from the truth: this robot has errors the fit's "
    "model lacks ({sources}). The fit explains what it can of them with the parameters it "
    "has, so the offsets absorb part of them and move away from the true joint zeros. A "
    "reported std measures only what the noise (repeatability, laser) does to an offset, "
    "not the model's mismatch: here the residuals are {ratio:.1f}x the noise. How good the "
    "calibration is, the position error after it says (above); planecal validate breaks "
    "it down by error source.")


def run(args) -> int:
    from planecal.commands.calibration_options import calibration_settings
    from planecal.model.scene import load_scene
    from planecal.twin.profile import load_profile

    from planecal.io.outputs import make_folder

    scene = load_scene(args.scene)  # a bad scene, --errors or --level before any folder
    profile = load_profile(args.errors, scene.robot)
    settings = calibration_settings(args, scene.robot, scene=scene)
    out = make_folder(args.dir, "--dir", parents=True)  # checked before the run (``files``)
    files = _files(out)
    print(f"== rehearsal on the twin ({args.scene}, {args.samples} samples, seed {args.seed}, "
          f"{profile.name} world)", flush=True)
    code = _rehearse(args, *files[:2])
    if code == 2 or code >= 128:  # refused or interrupted: its one line said why
        return code
    if code != 0:
        print("the rehearsal did not complete; calibrating what was sampled")
    cal, samples, why = _calibrate(args, scene, settings, *files)
    world, opts, v = _position_error(args, scene, samples, cal, *files[:2])
    _offsets_against_truth(scene, samples, cal, world, opts)
    print("files: " + ", ".join(str(f) for f in files))
    if why:
        raise RunFailed(why)
    return 0


def _rehearse(args, run_file, truth_file) -> int:
    """The rehearsal is planecal rehearse itself, as a user runs it: its exit code."""
    from planecal.cli import main as planecal_main
    argv = ["rehearse", "--out", str(run_file), "--truth-out", str(truth_file), "--force",
            "--scene", args.scene, "--samples", str(args.samples), "--seed", str(args.seed),
            "--errors", args.errors]
    if args.rrd:
        argv += ["--rrd", args.rrd]
    return planecal_main(argv)


def _calibrate(args, scene, settings, run_file, truth_file, result_file):
    """The calibration from the scene's nominal values, as planecal calibrate does it:
    (Calibration, samples, why it failed or None); its result file written. A fit that did
    not converge ends the demo (RunFailed)."""
    from planecal.estimation.calibrate import calibrate_samples
    from planecal.formats.params import provenance, result_document
    from planecal.io.params import save_json
    from planecal.estimation.accuracy import of_samples
    from planecal.io.samples import read_samples
    from planecal.model.scene import nominal_params
    from planecal.present.calibration import document, text

    samples = read_samples(run_file)
    print(f"\n== calibration (level {settings.label}) from the scene's nominal values "
          f"({len(samples)} samples)")
    cal = calibrate_samples(scene.robot, samples, nominal_params(scene), settings,
                            scene.references)
    doc = result_document(document(cal, scene.robot, of_samples(scene, cal, samples)), provenance(
        [("samples", run_file), ("scene", scene.path), ("robot", scene.robot.source)],
        scene.name, scene.robot.name))
    print(text(doc, samples.n_zero))
    save_json(result_file, doc)
    if args.rrd:
        from planecal.present.rerun import log_fit_to_file
        print(f"fit recording written to {log_fit_to_file(args.rrd, cal, samples, scene)}")
    why = cal.failure()
    if not cal.result.converged:
        print(f"files: {run_file}, {truth_file}, {result_file}")
        raise RunFailed(why)
    if why:  # the offsets are a calibration; a sensor or plane parameter is not pinned
        print(f"\nplanecal calibrate would fail here ({why}); the demo still shows what the "
              "fitted model does")
    return cal, samples, why


def _position_error(args, scene, samples, cal, run_file, truth_file):
    """ISO 9283 AP before and after, in the world the run was made in (its files say
    which): (world, twin options, the validation)."""
    from planecal.estimation.compensate import CalibratedModel
    from planecal.present.validation import change, where_text
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import ValidationSettings, validate
    from planecal.twin.world import recorded_world

    world, opts = recorded_world(scene, run_file, truth_file).build(scene)
    st = ValidationSettings(cycles=DEMO_CYCLES, seed=args.seed, gauge=False)
    v = validate(scene, world, CalibratedModel(scene.robot, cal.params, cal.settings.label),
                 samples.qe, st, CollisionWorld(scene, clearance_m=st.clearance_m),
                 options=opts)
    print(f"\n== position error in the calibrated region (ISO 9283 AP: the worst of five poses "
          f"in a {v['cube']['edge_m'] * 1e3:.0f} mm cube among the samples, {DEMO_CYCLES} "
          f"cycles, on the same twin, at {where_text(v)}, robot frame)")
    b, a = v["ap_before_tool_mm"], v["ap_after_tool_mm"]
    worse = ": the calibration made it worse" if a > b else ""
    print(f"before calibration {b:.3f} mm, after {a:.3f} mm ({change(b, a)}{worse}); the "
          f"twin's own true model {v['ap_oracle_tool_mm']:.3f} mm (backlash, repeatability); "
          f"at the flange {v['ap_before_flange_mm']:.3f} -> {v['ap_after_flange_mm']:.3f} mm; "
          f"repeatability RP {v['rp_after_tool_mm']:.3f} mm")
    return world, opts, v


def _offsets_against_truth(scene, samples, cal, world, opts) -> None:
    """The identified joint offsets against the twin's hidden truth, in reported std, and
    why they can sit far from it."""
    from planecal.twin.world import MISMATCH, SHORT, sources_on

    res = cal.result
    truth = world.params
    print("\n== identified joint offsets against the twin's hidden truth")
    print(f"{'joint':<7} {'truth_mrad':>11} {'nominal_err':>12} {'identified':>11} "
          f"{'error_mrad':>11} {'std_mrad':>9} {'error/std':>9}")
    worst = 0.0
    for i, name in enumerate(res.layout.group("joint_offsets").names):
        t, x = truth.joint_offsets[i], res.params.joint_offsets[i]
        j = res.layout.index(name)
        if not res.free[j]:
            print(f"{name:<7} {t * 1e3:>11.4f} {-t * 1e3:>12.4f} {'fixed':>11} "
                  f"{(x - t) * 1e3:>11.4f} {'-':>9} {'-':>9}")
            continue
        s = res.std[j]
        z = (x - t) / s if np.isfinite(s) else float("nan")
        worst = max(worst, abs(z))
        print(f"{name:<7} {t * 1e3:>11.4f} {-t * 1e3:>12.4f} {x * 1e3:>11.4f} "
              f"{(x - t) * 1e3:>11.4f} {s * 1e3:>9.4f} {z:>9.2f}")
    verdict = "within" if worst <= 3 else "OUTSIDE"
    print(f"\nidentified offsets are {verdict} 3 reported standard deviations of the truth "
          f"(worst {worst:.2f} sigma); model error RMS {res.rms_mm(True):.3f} -> "
          f"{res.rms_mm():.4f} mm")
    mismatch = [f for f in sources_on(scene.robot, world, opts) if f in MISMATCH]
    if mismatch:
        noise = _noise_rms_mm(scene, samples, res, opts)
        print()
        print(WHY_OFF.format(sources=", ".join(SHORT[f] for f in mismatch),
                             ratio=res.rms_mm() / noise if noise > 0 else float("inf")))
    else:
        print("This twin's world has no error the fit's model lacks: the offsets should sit "
              "within a few reported std of the truth, and the position error after "
              "calibration is the noise's.")


def _noise_rms_mm(scene, samples, res, opts) -> float:
    """The rms distance noise per sample of the twin's noise (repeatability, quantisation,
    the laser's buffer mean) on these samples (``estimation.noise.sample_variance``)."""
    from planecal.estimation.noise import repeatability_sigma, sample_sigma_m, sample_variance
    from planecal.model.measurement import predict_with_jacobian

    robot = scene.robot
    rep = robot.repeatability_m if opts.repeatability_mm is None else opts.repeatability_mm * 1e-3
    s = repeatability_sigma(robot, rep) if rep > 0 else 0.0
    _, J = predict_with_jacobian(robot, samples.qe, res.params, samples.plate, res.layout)
    v = sample_variance(robot, J[:, res.layout.slice("joint_offsets")], s,
                        sample_sigma_m(opts.laser_noise_mm), opts.quantization)
    return float(np.sqrt(np.mean(v)) * 1e3)
