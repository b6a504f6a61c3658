"""planecal plan [--scene S] [--samples N] [--candidates M] [--seed K] --out POSES.json
[--target-std-urad X | --target-ap-mm X] [--params R.json] [--no-order]
[--measure R [--jobs J | --scheduler tcp://HOST:PORT]] [--level offsets|full|nonkinematic] [--compliance]
[--free NAMES] [--design d-optimal|tool [--robot-minutes X] [--max-reads K]]

``--design tool`` (issue 31; ``studies.tool_plan``): the whole model's design for the
level's calibration, within --robot-minutes of robot time (default: what the sampling
run's own random poses take for --samples): poses, several readings at a pose (up to
--max-reads, each after a short move away and back, from alternating sides: the backlash
measured from both flanks) and the tour, chosen for the predicted position error at the
tool point per robot second; printed beside the random run of the same robot time. A list
planned from the nominal cell is aimed at run time with a first calibration of the cell
(``rehearse``/``sample --poses P.json --params FIRST.json``).

D-optimal sample poses: N of M collision-free candidates (the sampling run's pose
distribution) maximising det(J^T J) at the nominal parameters (greedy + Fedorov exchange),
ordered into the collision-checked tour that minimises robot time under the step limit
(``sampling.tour.order``; ``--no-order`` keeps the design's order). With a target the
sample count is the smallest (up to --samples) whose predicted offsets' std (the largest
of the free offsets, urad) or predicted position error at the tool point (mm: the laser's
beam point at the scene's standoff, robot frame, 1 sigma RMS over the candidates), times
a margin of 1.25, meets it. --params R.json (an earlier calibration of this cell, from
``calibrate --out``) aims the poses with its sensor pose, planes and offsets, so they
measure on the real cell as planned (the nominal sensor pose is millimetres off), and
adds the model's mismatch it showed to the tool-point prediction (its ``accuracy`` block:
the share of its predicted tool-point error beyond the noise-only one, held as it is,
since more poses do not average a systematic error down); without it the predictions are
the noise model's alone, which a real robot's model mismatch exceeds several times.
The offsets' std (table, --target-std-urad) is the noise model's in either case. Prints the robot time of the run before and after ordering (and of
the random run), its travel per sample,  the predicted std (twin noise model) for the
planned set and for the poses the sampling run itself would visit with the same seed
("random"); with --measure R also the measured spread on the twin over R runs each
(planned poses replayed with fresh noise vs fresh random rehearsals, same truth). POSES.json holds the counts and plates
(format planecal-poses/1); planecal.studies.rehearsal.rehearse_planned runs them through
the sampling loop. The --measure runs go through planecal.studies.distributed (--jobs 1:
in this process; default: a local Dask cluster; --scheduler: a cluster you run).
"""
from __future__ import annotations

from planecal.base.errors import InputError
from planecal.commands.value_options import MAX_CANDIDATES, MAX_RUNS, MAX_SAMPLES, count, seed


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the planned poses", reads=None)
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150,
                   help="poses to choose (default 150; with a target: the most it may choose)")
    t = p.add_mutually_exclusive_group()
    t.add_argument("--target-std-urad", type=float, default=None, metavar="X",
                   help="choose the sample count: the fewest samples whose predicted std of "
                        "every free joint offset (delta2..delta5) is <= X urad")
    t.add_argument("--target-ap-mm", type=float, default=None, metavar="X",
                   help="choose the sample count: the fewest samples whose predicted "
                        "position error at the tool point (the laser's beam point; 1 sigma, "
                        "RMS over the candidate poses), times a margin of 1.25, is <= X mm")
    p.add_argument("--params", default=None, metavar="R.json",
                   help="an earlier calibration result of this cell: aim the poses with it "
                        "and add the model's mismatch it showed to the tool-point "
                        "prediction")
    p.add_argument("--design", choices=["d-optimal", "tool"], default="d-optimal",
                   help="d-optimal (default): N poses maximising det(J^T J); tool: the whole "
                        "model's design, readings and approach sides chosen for the tool "
                        "point's error per robot second (docs/STUDIES.md)")
    p.add_argument("--robot-minutes", type=float, default=None, metavar="X",
                   help="--design tool: the robot time the list may take (default: the "
                        "random run of --samples)")
    p.add_argument("--max-reads", type=count(100), default=4, metavar="K",
                   help="--design tool: readings of one pose at most (default 4)")
    p.add_argument("--no-order", action="store_true",
                   help="keep the design's order (do not order the poses for robot time)")
    p.add_argument("--candidates", type=count(MAX_CANDIDATES), default=1500, help="candidate poses (default 1500)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the candidates")
    p.add_argument("--out", required=True, help="pose list to write (JSON)")
    from planecal.commands.calibration_options import add_calibration_arguments
    add_calibration_arguments(p)
    p.add_argument("--measure", type=count(MAX_RUNS, 0), default=0, metavar="R",
                   help="measure planned vs random spread on the twin over R runs each")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier pose list")
    from planecal.commands.engine_options import add_engine_arguments
    add_engine_arguments(p)
    from planecal.commands.report_options import add_report_argument
    add_report_argument(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, report_output, scene_inputs
    from planecal.formats.poses import POSES_FORMAT
    f = Files().read(*scene_inputs(args.scene)).write(args.out, "--out", POSES_FORMAT)
    if args.params:
        f.read(args.params, role="--params")
    report_output(f, args.report, "--report")
    return f


def run(args) -> int:
    import contextlib
    from pathlib import Path

    from planecal.safety.collision import CollisionWorld
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.commands.calibration_options import calibration_settings
    from planecal.model.layout import display_of
    from planecal.present.tables import table
    from planecal.studies.planning import plan, plan_target

    from planecal.jobs.report import write_command_report

    if args.design == "tool":
        return run_tool(args)
    if args.robot_minutes is not None:
        raise InputError("--robot-minutes is a budget of --design tool")
    target = plan_target(args.samples, args.candidates, args.target_std_urad, args.target_ap_mm)
    if args.measure and args.measure < 2:
        raise InputError(f"--measure needs at least 2 runs, got {args.measure}")
    scene = load_scene(args.scene)
    settings = calibration_settings(args, scene.robot, scene=scene)
    model, mismatch = aim(args.params, scene)
    with contextlib.ExitStack() as stack:
        engine = None
        if args.measure:  # the engine's options checked and its scheduler reached first
            import functools

            from planecal.commands.engine_options import engine_from_args
            from planecal.studies.distributed import warm_twin
            engine = stack.enter_context(engine_from_args(
                args, warmup=functools.partial(warm_twin, str(scene.path))))
        from planecal.base.progress import Progress
        from planecal.studies.planning import PLAN_STAGES
        bar = Progress("plan", PLAN_STAGES, unit=" stages", hold=target is not None)
        bar.update(done=0, note="collision model")
        try:
            res = plan(scene, args.samples, args.candidates, args.seed, settings,
                       CollisionWorld(scene, clearance_m=0.01),
                       target_std_urad=args.target_std_urad, target_ap_mm=args.target_ap_mm,
                       ordered=not args.no_order, progress=bar, model=model,
                       mismatch=mismatch)
            if args.params:
                res["aimed_with"] = str(Path(args.params).resolve())
        finally:
            bar.close()
        if engine is not None:
            res["measured"] = measure(scene, res, args.measure, engine, settings)
    rows = []
    for n in res["free"]:
        k, unit = display_of(n)
        row = [n, unit, f"{res['predicted_std_random'][n] * k:.4g}",
               f"{res['predicted_std_planned'][n] * k:.4g}",
               f"{res['predicted_std_random'][n] / res['predicted_std_planned'][n]:.2f}"]
        if args.measure:
            m = res["measured"]
            row += [f"{m['random'][n] * k:.4g}", f"{m['planned'][n] * k:.4g}",
                    f"{m['random'][n] / m['planned'][n]:.2f}"]
        rows.append(row)
    heads = ["param", "unit", "pred random", "pred planned", "ratio"]
    if args.measure:
        heads += ["meas random", "meas planned", "ratio"]
    print(f"{res['samples']} of {res['candidates']} candidates on {scene.name}: log det "
          f"random {res['logdet_random']:.2f}, planned {res['logdet_planned']:.2f} "
          f"(D-efficiency x{res['d_efficiency_gain']:.2f}); {res['exchange_swaps']} exchanges "
          f"in {res['exchange_passes']} passes")
    print(table(heads, rows))
    print(format_robot_time(res))
    if args.measure:
        print(f"measured: {args.measure} twin runs each (std of the estimates over the runs)")
    save_json(args.out, res)
    print(f"pose list written to {args.out}")
    write_command_report(args.report, args.out, scene=scene)
    return 0


def run_tool(args) -> int:
    """``--design tool``: the whole model's design (``studies.tool_plan``)."""
    from pathlib import Path

    from planecal.base.progress import Progress
    from planecal.commands.calibration_options import calibration_settings
    from planecal.io.params import save_json
    from planecal.jobs.report import write_command_report
    from planecal.model.scene import load_scene
    from planecal.studies.tool_plan import TOOL_STAGES, plan_tool, random_minutes
    for flag, given in (("--target-std-urad", args.target_std_urad),
                        ("--target-ap-mm", args.target_ap_mm), ("--measure", args.measure),
                        ("--no-order", args.no_order)):
        if given:
            raise InputError(f"{flag} is an option of --design d-optimal")
    scene = load_scene(args.scene)
    settings = calibration_settings(args, scene.robot, scene=scene)
    model, _ = aim(args.params, scene)
    bar = Progress("plan", TOOL_STAGES, unit=" stages")
    try:
        minutes = args.robot_minutes
        bar.update(done=0, note=f"the random run of {args.samples} samples: its robot time"
                   if minutes is None else f"a budget of {minutes:g} robot minutes")
        if minutes is None:
            minutes = random_minutes(scene, args.samples, args.seed, model)
        res = plan_tool(scene, minutes, args.candidates, args.seed, settings, model,
                        args.max_reads, bar)
        if args.params:
            res["aimed_with"] = str(Path(args.params).resolve())
    finally:
        bar.close()
    print(format_tool(res))
    save_json(args.out, res)
    print(f"pose list written to {args.out}")
    write_command_report(args.report, args.out, scene=scene)
    return 0


def format_tool(res: dict) -> str:
    """The tool design's lines: what it reads, its robot time and prediction beside the
    random run of the same robot time."""
    t, ap = res["robot_time_s"], res["predicted_tool_mm"]
    reads = res["reads_per_pose"]
    both = sum(1 for r in reads if r > 1)
    out = [f"{res['samples']} readings at {res['poses']} of {res['candidates']} candidate poses "
           f"on {res['scene']} (level {res['level']}: {len(res['free'])} free), at most "
           f"{res['max_reads']} a pose, {both} poses read from both sides",
           f"robot time {t['planned'] / 60:.1f} min (budget {t['budget'] / 60:.1f}; laser "
           f"reads at {t['read_ticks_per_sample']} ticks); the random run of the same robot "
           f"time: {res['random_samples']} samples",
           f"predicted position error at the tool point ({ap['where']}): planned "
           f"{ap['planned']:.4g} mm, random {ap['random']:.4g} mm"]
    if res.get("dropped"):
        out.append(str(res["dropped"]))
    if res.get("aimed_with") is None:
        out.append("planned from the nominal cell: aim it with a first calibration of the "
                   "cell when it runs (rehearse/sample --poses ... --params FIRST.json)")
    return "\n".join(out)


def aim(path, scene):
    """(``CommandModel``, ``Mismatch``) of --params' result, or (None, None)."""
    if not path:
        return None, None
    from planecal.io.params import load_json
    from planecal.jobs.results import read_result
    from planecal.sampling.poses import CommandModel
    from planecal.studies.planning import Mismatch
    params = read_result(path, scene).params  # of this cell (its provenance's)
    if params.n_planes != len(scene.plates):
        raise InputError(f"{path}: {params.n_planes} plane(s), the scene {scene.name} has "
                         f"{len(scene.plates)}: a result of another cell")
    return CommandModel(params, scene.robot.qe0.copy()), Mismatch.of_result(load_json(path),
                                                                             path)


def format_robot_time(res: dict) -> str:
    """The plan's robot-time lines (and the target, if it chose the sample count)."""
    t = res["robot_time_s"]
    n = res["samples"]
    tp, tr = res["travel_per_sample_s"], res["robot_time_per_sample_s"]
    out = []
    if res.get("dropped"):  # poses the run could not reach from the others: not listed
        out.append(f"{res['dropped']}; the list holds the {n} the run visits")
    mm = res.get("mismatch")
    basis = (f"the noise model's with the model's mismatch {mm['source']} showed, "
             f"{mm['mismatch_mm']:.3g} mm, in quadrature (held: more poses do not average it "
             "down)" if mm else "the noise model's alone: a real robot's model mismatch "
             "adds several times this; --params R.json of a first calibration adds it")
    if res.get("target"):
        g = res["target"]
        what = ("largest free offset std" if g["kind"] == "std"
                else "position error at the tool point")
        out.append(f"target: predicted {what} x{g['margin']:g} (margin) <= {g['value']:g} "
                   f"{g['unit']}: {n} samples")
    ap = res["predicted_tool_mm"]
    out.append(f"predicted position error at the tool point ({ap['where']}): random "
               f"{ap['random']:.4g} mm, planned {ap['planned']:.4g} mm; predictions: {basis}")
    out.append(f"robot time (laser reads at {t['read_ticks_per_sample']} ticks): random "
               f"{t['random']:.0f} s, planned {t['planned_unordered']:.0f} s in the design's "
               f"order, {t['planned']:.0f} s "
               + ("ordered" if res.get("ordered") else "(not ordered)")
               + f" = {t['planned'] / 60:.1f} min; per sample {tr['planned']:.2f} s, of which "
               f"travel {tp['planned']:.2f} s (random: {tr['random']:.2f} s, travel "
               f"{tp['random']:.2f} s)")
    return "\n".join(out)


def measure(scene, res: dict, runs: int, engine, settings) -> dict:
    from dataclasses import replace

    from planecal.studies.montecarlo import MCSettings, analyze, run_many
    free = tuple(res["free"])
    base = MCSettings(scene=str(scene.path), samples=res["samples"], runs=runs, free=free,
                      level=settings.level, compliance=settings.compliance,
                      geometry_prior=settings.geometry_prior, free_scale=settings.free_scale)
    poses = tuple((tuple(int(v) for v in c), int(k)) for c, k in zip(res["counts"], res["plates"]))
    planned = analyze(run_many(replace(base, poses=poses), engine, label="planned poses"), base)
    rand = analyze(run_many(base, engine, label="random poses"), base)
    out = {"runs": runs}
    for name, a in (("planned", planned), ("random", rand)):
        out[name] = {n: a["params"][n]["empirical_std"] for n in a["params"]}
        out[name + "_crb"] = {n: a["params"][n]["crb_std"] for n in a["params"]}
        out[name + "_bias"] = {n: a["params"][n]["bias"] for n in a["params"]}
        out[name + "_samples_per_run"] = a["samples_per_run"]
    return out
