"""The demo job (``planecal demo``): the main job on the built-in twin, end to end. A
rehearsal (``jobs.rehearse``: the sampling run on the twin, its truth file written), the
calibration of that run in its own cell (``jobs.calibrate.calibrate_runs``: the pipeline
``planecal calibrate`` and the API take), then what the calibration did: ISO 9283 AP
before and after in the calibrated region on the same twin (``studies.validation``), and
the identified joint offsets against the twin's hidden truth in reported standard
deviations, with why they can sit far from it."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from planecal.base.errors import RunFailed

DEMO_CYCLES = 10  # ISO cycles of the demo's position-error check (validate: 30)


@dataclass(frozen=True)
class DemoRequest:
    """The demo's options (``commands/demo.py``): the scene, the run's size and seed, the
    folder, the error profile, the recordings; ``settings``: the calibration's settings
    for the scene (the flags', checked against it)."""
    settings: Callable
    scene: str | None = None
    samples: int = 150
    seed: int = 1
    dir: str = "runs/demo"
    errors: str = "realistic"
    rrd: str | None = None


def demo_files(out: Path) -> tuple[Path, Path, Path]:
    """The demo's files in its folder: the run, the truth, the result."""
    return out / "demo.tsv", out / "truth.json", out / "result.json"


WHY_OFF = (
    "Why the offsets can sit several std from the truth: this robot has errors the fit's "
    "model lacks ({sources}). The fit explains what it can of them with the parameters it "
    "has, so the offsets absorb part of them and move away from the true joint zeros. A "
    "reported std measures only what the noise (repeatability, laser) does to an offset, "
    "not the model's mismatch: here the residuals are {ratio:.1f}x the noise. How good the "
    "calibration is, the position error after it says (above); planecal validate breaks "
    "it down by error source.")


def demo(req: DemoRequest) -> int:
    """The demo (module docstring): its exit code (0; 2 or an interruption's when the
    rehearsal was refused or interrupted; RunFailed when the fit failed). The folder and
    its files were checked before the run (the output guard)."""
    from planecal.io.outputs import make_folder
    from planecal.jobs.rehearse import RehearseRequest, rehearse
    from planecal.jobs.sampling import SamplingRequest
    from planecal.model.scene import DEFAULT_SCENE, load_scene
    from planecal.twin.profile import load_profile

    scene = load_scene(req.scene or DEFAULT_SCENE)  # a bad scene, --errors or --level first
    profile = load_profile(req.errors, scene.robot)
    settings = req.settings(scene)
    out = make_folder(req.dir, "--dir", parents=True)
    files = demo_files(out)
    print(f"== rehearsal on the twin ({req.scene or DEFAULT_SCENE}, {req.samples} samples, "
          f"seed {req.seed}, {profile.name} world)", flush=True)
    code = rehearse(RehearseRequest(
        SamplingRequest(str(files[0]), str(scene.path), req.samples, req.seed, force=True,
                        rrd=req.rrd), req.errors, truth_out=str(files[1])))
    if code != 0:
        print("the rehearsal did not complete; calibrating what was sampled")
    done, why = _calibrate(req, settings, *files)
    world, opts, _ = _position_error(req, done, files[1])
    _offsets_against_truth(done, world, opts)
    print("files: " + ", ".join(str(f) for f in files))
    if why:
        raise RunFailed(why)
    return 0


def _calibrate(req: DemoRequest, settings, run_file, truth_file, result_file):
    """The calibration from the cell's nominal values, as planecal calibrate does it:
    (``jobs.calibrate.Calibrated``, why it failed or None); its result file written. A
    fit that did not converge ends the demo (RunFailed)."""
    from planecal.jobs.calibrate import calibrate_runs
    from planecal.jobs.runs import read_runs
    from planecal.present.calibration import text

    runs = read_runs([run_file])
    print(f"\n== calibration (level {settings.label}) from the scene's nominal values "
          f"({len(runs.samples)} samples)")
    done = calibrate_runs(runs, settings)
    print(text(done.doc, runs.samples.n_zero))
    done.result.write(result_file)
    if req.rrd:
        from planecal.present.rerun import log_fit_to_file
        print(f"fit recording written to "
              f"{log_fit_to_file(req.rrd, done.calibration, runs.samples, runs.scene)}")
    why = done.failure()
    if not done.calibration.result.converged:
        print(f"files: {run_file}, {truth_file}, {result_file}")
        raise RunFailed(why)
    if why:  # the offsets are a calibration; a sensor or plane parameter is not pinned
        print(f"\nplanecal calibrate would fail here ({why}); the demo still shows what the "
              "fitted model does")
    return done, why


def _position_error(req: DemoRequest, done, truth_file):
    """ISO 9283 AP before and after, in the world the run was made in (its files say
    which): (world, twin options, the validation)."""
    from planecal.estimation.compensate import CalibratedModel
    from planecal.jobs.runs import run_world
    from planecal.present.validation import change, where_text
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.validation import ValidationSettings, validate

    scene, samples, cal = done.runs.scene, done.runs.samples, done.calibration
    world, opts = run_world(done.runs.runs[0], truth_file).build(scene)
    st = ValidationSettings(cycles=DEMO_CYCLES, seed=req.seed, gauge=False,
                            standard_cube=False)
    v = validate(scene, world, CalibratedModel(scene.robot, cal.params, cal.settings.label),
                 samples.qe, st, CollisionWorld(scene, clearance_m=st.clearance_m),
                 cal.result, opts, samples.direction)  # its level's floor beside it
    print(f"\n== position error in the calibrated region (ISO 9283 AP: the worst of five poses "
          f"in a {v['cube']['edge_m'] * 1e3:.0f} mm cube among the samples, {DEMO_CYCLES} "
          f"cycles, on the same twin, at {where_text(v)}, robot frame)")
    b, a = v["ap_before_tool_mm"], v["ap_after_tool_mm"]
    worse = ": the calibration made it worse" if a > b else ""
    print(f"before calibration {b:.3f} mm, after {a:.3f} mm ({change(b, a)}{worse}); the "
          f"level's floor {v['ap_floor_tool_mm']:.3f} mm (the best its model does), the "
          f"twin's own true model {v['ap_oracle_tool_mm']:.3f} mm (repeatability, whole "
          f"counts); "
          f"at the flange {v['ap_before_flange_mm']:.3f} -> {v['ap_after_flange_mm']:.3f} mm; "
          f"repeatability RP {v['rp_after_tool_mm']:.3f} mm")
    return world, opts, v


def _offsets_against_truth(done, world, opts) -> None:
    """The identified joint offsets against the twin's hidden truth, in reported std, and
    why they can sit far from it."""
    from planecal.twin.world import MISMATCH, SHORT, sources_on

    scene, samples, res = done.runs.scene, done.runs.samples, done.calibration.result
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
