"""planecal demo [--scene S] [--samples N] [--seed K] [--dir D] [--rrd FILE]

The main job on the built-in twin: rehearse a sampling run on the default scene (the
thesis's final cell), calibrate from the scene's nominal values exactly as
``planecal calibrate`` would, and show how close the identified joint offsets are to the
twin's hidden truth, in units of the reported standard deviations.

Files land in ``--dir`` (default runs/demo): demo.tsv (+ sidecar), truth.json, result.json.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from planecal.errors import InputError
from planecal.scene import DEFAULT_SCENE


def add_arguments(p):
    p.add_argument("--scene", default=DEFAULT_SCENE, help="scene (default %(default)s)")
    p.add_argument("--samples", type=int, default=150, help="samples to take (default %(default)s)")
    p.add_argument("--seed", type=int, default=1, help="seed of poses and twin truth (default %(default)s)")
    p.add_argument("--dir", default="runs/demo", help="output directory (default %(default)s)")
    p.add_argument("--errors", default="realistic", metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default %(default)s)")
    p.add_argument("--rrd", nargs="?", const="auto", default=None,
                   help="also write Rerun recordings of the run and of the fit (a directory, "
                        "a file name, or nothing for recordings/)")


def run(args) -> int:
    from planecal.commands import rehearse
    from planecal.commands.calibrate import build_problem, format_report, result_dict
    from planecal.fit import FitOptions, solve
    from planecal.formats.params import RESULT_FORMAT
    from planecal.params import load_params, save_json
    from planecal.samples import read_samples
    from planecal.scene import load_scene, nominal_params

    out = Path(args.dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"--dir {out}: cannot create ({e.strerror})") from None
    run_file, truth_file = out / "demo.tsv", out / "truth.json"
    rp = argparse.ArgumentParser(prog="planecal rehearse")
    rehearse.add_arguments(rp)
    argv = ["--out", str(run_file), "--truth-out", str(truth_file), "--force",
            "--scene", args.scene, "--samples", str(args.samples), "--seed", str(args.seed),
            "--errors", args.errors]
    if args.rrd:
        argv += ["--rrd", args.rrd]
    print(f"== rehearsal on the twin ({args.scene}, {args.samples} samples, seed {args.seed})")
    code = rehearse.run(rp.parse_args(argv))
    if code != 0:
        print("the rehearsal did not complete; calibrating what was sampled")
    samples = read_samples(run_file)
    scene = load_scene(args.scene)
    nominal = nominal_params(scene)
    print(f"\n== calibration from the scene's nominal values ({len(samples)} samples)")
    res = solve(build_problem(samples, scene, nominal, None, FitOptions()))
    print(format_report(res, samples.n_zero))
    save_json(out / "result.json", {"format": RESULT_FORMAT, **result_dict(res)})
    if args.rrd:
        from planecal.rerun_log import log_fit_to_file
        print(f"fit recording written to {log_fit_to_file(args.rrd, res, samples, scene)}")
    truth = load_params(truth_file)
    print("\n== identified joint offsets against the twin's hidden truth")
    print(f"{'joint':<7} {'truth_mrad':>11} {'nominal_err':>12} {'identified':>11} "
          f"{'error_mrad':>11} {'std_mrad':>9} {'error/std':>9}")
    worst = 0.0
    offsets = res.layout.group("joint_offsets").names
    for i, name in enumerate(offsets):
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
          f"(worst {worst:.2f} sigma); residual RMS {res.rms_mm(True):.3f} -> {res.rms_mm():.4f} mm")
    print(f"files: {run_file}, {truth_file}, {out / 'result.json'}")
    return 0
