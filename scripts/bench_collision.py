#!/usr/bin/env python
"""How often the collision checker rejects a pose that the real link shapes would clear,
and whether it ever accepts a path on which they touch.

usage: python scripts/bench_collision.py [--scenes S ...] [--seeds K ...] [--samples N]
                                         [--clearance-mm C] [--compare-margin-mm M]

The draws are those of real sampling runs: the run's ``Planner`` (sampling/planner.py) with
the scene's settings (``RunSettings.for_scene``) and the product checker
(``CollisionWorld``, default clearance), started at the scene's calibration position as
``planecal rehearse`` starts, until N poses are accepted per scene and seed. A laser
rejection moves the robot too, so the start configurations are the run's, without a
twin (a run whose laser rejects some poses plans that many more). Each draw the checker
sees (a reachable target) is the target configuration and the straight joint path from
the previous accepted pose.

The oracle (tests/mujoco_oracle.py, ``ExactOracle``) gives exact distances of the visual
link and tool shapes (the model of the real robot) and the nominal cell with MuJoCo's
``mj_geomDistance``, along the path so densely that no point moves more than 1 mm between
samples where a pair is within the clearance. Verdicts:
* a rejection is FALSE when the visual shapes keep at least the clearance at the target
  and everywhere along the path (to the oracle's 0.5 mm: half its 1 mm step);
* an acceptance is COLLIDING when the visual shapes touch (distance <= 0) anywhere on it.
``--compare-margin-mm M`` also judges the same draws with a checker whose collision
envelope has margin M (e.g. 10, the margin before the envelope was measured), side by side.

Last lines: ``false_rejection_rate: X`` (false rejections / draws checked, a fraction) and
``accepted_colliding_paths: N``. Progress goes to stderr.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the test oracle

import numpy as np  # noqa: E402

from mujoco_oracle import ExactOracle  # noqa: E402
from planecal.safety.collision import CollisionWorld  # noqa: E402
from planecal.model.encoder import counts_to_joints, joints_to_counts  # noqa: E402
from planecal.sampling.planner import Planner  # noqa: E402
from planecal.sampling.run import RunSettings  # noqa: E402
from planecal.model.scene import load_scene  # noqa: E402


def draws(scene, seed: int, samples: int, checker):
    """(q_start, q_target, accepted, reason) for every draw the checker judged, in the
    order of a sampling run with ``samples`` samples; and the number of draws in all."""
    settings = RunSettings.for_scene(scene, samples=samples, seed=seed)
    planner = Planner(scene, settings.pose, checker)
    rng_state = np.random.default_rng(seed).bit_generator.state
    robot = scene.robot
    q0 = counts_to_joints(robot, joints_to_counts(robot, scene.calibration_q))
    out, total = [], 0
    for i in range(samples):
        plan = planner.plan(q0, i, rng_state, settings.max_attempts)
        total += len(plan.rejections) + (plan.q is not None)
        for kind, q, reason in plan.rejections:
            if kind == "collision":
                out.append((q0, q, False, reason))
        if plan.q is None:
            break
        # the motion the run makes: straight, or a detour's legs through its via-points
        qs = [q0] + [q for q, _ in plan.via] + [plan.q]
        for a, b in zip(qs[:-1], qs[1:]):
            out.append((a, b, True, None))
        rng_state = plan.rng_after
        q0 = plan.q
    return out, total


def verdict(checker, q0, q1) -> bool:
    return checker.check_config(q1).ok and checker.check_path(q0, q1).ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["thesis_final", "three_plates"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--samples", type=int, default=150, help="samples per run (default 150)")
    ap.add_argument("--clearance-mm", type=float, default=10.0)
    ap.add_argument("--compare-margin-mm", type=float, default=None,
                    help="also judge the draws with this collision margin, side by side")
    args = ap.parse_args(argv)
    c = args.clearance_mm * 1e-3
    compare = args.compare_margin_mm is not None
    tot = Counter()
    blamed = Counter()
    t_start = time.perf_counter()
    print(f"{'scene':<14}{'seed':>5}{'draws':>7}{'checked':>8}{'rejected':>9}{'false':>7}"
          f"{'accepted':>9}{'colliding':>10}" + (f"{'| cmp rej':>10}{'false':>7}{'coll':>6}"
                                                 if compare else "") + f"{'time s':>8}")
    for name in args.scenes:
        scene = load_scene(name)
        checker = CollisionWorld(scene, clearance_m=c)
        other = None
        if compare:
            from planecal.model import geometry
            m = args.compare_margin_mm * 1e-3
            other = CollisionWorld(scene, clearance_m=c,
                                   links=geometry.robot_link_meshes(scene.robot, "collision",
                                                                    margin_m=m),
                                   tools=geometry.tool_meshes(scene, "collision", margin_m=m))
        oracle = ExactOracle(scene, clearance_m=c)
        for seed in args.seeds:
            t0 = time.perf_counter()
            dr, n_all = draws(scene, seed, args.samples, checker)
            row = Counter(draws=n_all, checked=len(dr))
            for k, (q0, q1, ok, reason) in enumerate(dr):
                ok2 = verdict(other, q0, q1) if compare else ok
                d_target = oracle.distances(q1).min()
                clear_target = d_target >= c
                if ok or ok2:  # an acceptance: look for contact along the whole path
                    pm = oracle.path_min(q0, q1, threshold=c, stop_below=0.0)
                else:  # rejections only: does the path keep the clearance?
                    pm = oracle.path_min(q0, q1, threshold=c, stop_below=c) if clear_target else None
                clear = clear_target and pm is not None and pm.distance >= c
                touch = min(d_target, pm.distance if pm else np.inf) <= 0.0
                row["rejected"] += not ok
                row["false"] += (not ok) and clear
                row["accepted"] += ok
                row["colliding"] += ok and touch
                row["cmp_rejected"] += not ok2
                row["cmp_false"] += (not ok2) and clear
                row["cmp_colliding"] += ok2 and touch
                if (not ok) and clear:
                    blamed[reason] += 1
                if k % 25 == 0:
                    print(f"\r  {name} seed {seed}: {k + 1}/{len(dr)} draws judged",
                          end="", file=sys.stderr, flush=True)
            print("\r" + " " * 60 + "\r", end="", file=sys.stderr)
            dt = time.perf_counter() - t0
            print(f"{name:<14}{seed:>5}{row['draws']:>7}{row['checked']:>8}{row['rejected']:>9}"
                  f"{row['false']:>7}{row['accepted']:>9}{row['colliding']:>10}"
                  + (f"{row['cmp_rejected']:>10}{row['cmp_false']:>7}{row['cmp_colliding']:>6}"
                     if compare else "") + f"{dt:>8.1f}", flush=True)
            tot.update(row)
    n = max(tot["checked"], 1)
    print(f"total: {tot['draws']} draws, {tot['checked']} judged by the checker, "
          f"{tot['rejected']} rejected ({tot['rejected'] / n:.3f}), {tot['false']} of them false; "
          f"{tot['accepted']} accepted, {tot['colliding']} colliding")
    if compare:
        print(f"compare (margin {args.compare_margin_mm:g} mm): {tot['cmp_rejected']} rejected, "
              f"{tot['cmp_false']} false (rate {tot['cmp_false'] / n:.3f}), "
              f"{tot['cmp_colliding']} accepted colliding")
    if blamed:
        print("false rejections by the checker's reason:")
        for reason, k in blamed.most_common(8):
            print(f"  {k:5d}  {reason}")
    print(f"wall time: {time.perf_counter() - t_start:.1f} s (load {os.getloadavg()[0]:.2f})")
    print(f"false_rejection_rate: {tot['false'] / n:.4f}")
    print(f"accepted_colliding_paths: {tot['colliding']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
