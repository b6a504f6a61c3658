#!/usr/bin/env python
"""The twin against the real MC70 (seed Table 9), set size by set size.

For each of several truths (the robot: ``--truths``, worlds drawn from an error profile)
and each set size (30, 50, 100, 150 by default), ``--sets`` independent rehearsal sets are
sampled as ``planecal rehearse`` samples them (the twin driven tick by tick, collision
checked, random poses with the run's default settings or the ones given), and each set is
calibrated offsets-only from the nominal values as ``planecal calibrate`` does. Printed
beside the seed's Table 9 per set size:

* the absolute max model error after calibration (Table 9's "Abs. max. model error"):
  median and range over all sets of that size;
* how far the identified delta2..delta5 move between the independent sets of one robot
  (max - min, the median over the truths; Table 9: over its five independent sets).

    python scripts/bench_table9.py [--errors realistic] [--truths 0,1,2,3,4] [--sets 3]
                                   [--sizes 30,50,100,150] [--roll-deg R] [--ik-choice C]

Last line: ``table9_max_error_mm_150: MEDIAN [LO, HI]`` (the real MC70: 0.10-0.19 mm).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

os.environ.setdefault("MUJOCO_GL", "disable")

import numpy as np  # noqa: E402

# seed Table 9 (lines 1808-1823): sets A, B, BB, C, CC (independent), C+CC, all
TABLE9 = {"sizes": [98, 49, 48, 30, 32, 62, 257],
          "max_error_mm": [0.147381, 0.133476, 0.137771, 0.102081, 0.121123, 0.182197, 0.188273],
          "offsets_mrad": np.array([[0.032178, 2.158, 0.80, -4.659, -1.430],
                                    [-1.118, -0.139, -1.192, 0.422, -0.225],
                                    [1.187, 2.878, 2.073, -1.025, 2.593],
                                    [0.140, 1.323, 0.348, 0.944, -0.709]])}


def one_set(scene, world, opts, twin_seed, samples, seed, world_checker, pose):
    """A rehearsal set (the product's sampling run) calibrated offsets-only: (max |model
    error| mm, identified delta2..delta5 rad)."""
    from planecal.estimation.calibrate import calibrate_samples
    from planecal.links.base import AlwaysEnabled
    from planecal.io.samples import read_samples
    from planecal.sampling.driver import Driver
    from planecal.sampling.run import RunSettings, SamplingRun
    from planecal.model.scene import nominal_params
    from planecal.twin import Twin

    twin = Twin(scene, truth=world, seed=twin_seed, options=opts)
    st = RunSettings.for_scene(scene, samples=samples, seed=seed)
    for k, v in pose.items():
        setattr(st.pose, k, v)
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "set.tsv")
        stats = SamplingRun(Driver(twin, twin, AlwaysEnabled(), scene.robot), scene, st, out,
                            world_checker, background=True).run()
        if stats.status != "complete":
            raise SystemExit(f"set (seed {seed}): {stats.status} {stats.reason}")
        s = read_samples(out)
    fit = calibrate_samples(scene.robot, s, nominal_params(scene)).result
    return float(np.abs(fit.residuals_m).max() * 1e3), fit.params.joint_offsets[1:5].copy()


def main(argv=None) -> int:
    from planecal.safety.collision import CollisionWorld
    from planecal.model.scene import load_scene
    from planecal.twin.profile import draw_world, load_profile

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--errors", default="realistic")
    ap.add_argument("--scene", default="thesis_final")
    ap.add_argument("--truths", default="0,1,2,3,4")
    ap.add_argument("--sets", type=int, default=3)
    ap.add_argument("--sizes", default="30,50,100,150")
    ap.add_argument("--roll-deg", type=float, default=None)
    ap.add_argument("--ik-choice", default=None)
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    profile = load_profile(args.errors, scene.robot)
    checker = CollisionWorld(scene, clearance_m=0.01)
    truths = [int(v) for v in args.truths.split(",")]
    sizes = [int(v) for v in args.sizes.split(",")]
    pose = {k: v for k, v in (("roll_deg", args.roll_deg), ("ik_choice", args.ik_choice))
            if v is not None}
    t0 = time.perf_counter()
    res = {n: {"max": [], "spread": []} for n in sizes}
    for t in truths:
        world, opts = draw_world(scene, t, profile)
        for n in sizes:
            offs = []
            for k in range(args.sets):
                seed = 1000 * (t + 1) + 100 * k + n  # an independent set of robot t
                mx, d = one_set(scene, world, opts, t, n, seed, checker, pose)
                res[n]["max"].append(mx)
                offs.append(d)
            res[n]["spread"].append(np.ptp(np.array(offs), axis=0) * 1e3)
        print(f"truth {t} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    print(f"twin ({args.errors} errors, scene {args.scene}, {len(truths)} truths x {args.sets} "
          f"independent sets per size; pose settings {pose or 'the run defaults'}) against "
          f"the real MC70 (seed Table 9)")
    print(f"{'samples':>8} {'twin max error [mm]: median (range)':>38} "
          f"{'twin delta2..5 move between sets [mrad]':>44}")
    for n in sizes:
        m = np.array(res[n]["max"])
        sp = np.median(np.array(res[n]["spread"]), axis=0)
        print(f"{n:>8} {np.median(m):>12.3f} ({m.min():.3f} - {m.max():.3f}) {'':>12}"
              + " ".join(f"{v:6.2f}" for v in sp))
    print("seed Table 9 (one robot, real): max model error 0.102 (30), 0.121 (32), 0.133 (49), "
          "0.138 (48), 0.147 (98), 0.182 (62), 0.188 (257) mm;")
    ind = TABLE9["offsets_mrad"]
    print("  delta2..5 move between its five independent sets by "
          + " ".join(f"{v:.2f}" for v in np.ptp(ind, axis=1)) + " mrad")
    last = sizes[-1]
    m = np.array(res[last]["max"])
    print(f"table9_max_error_mm_{last}: {np.median(m):.3f} [{m.min():.3f}, {m.max():.3f}]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
