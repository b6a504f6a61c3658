"""planecal compare RUN.tsv --rehearsal TWIN.tsv [--params RESULT.json] [--alpha A]
[--suspects NAMES] [--repeatability-mm R] [--count-tolerance N] [--scene S]
[--out VERDICT.json [--force]] [--json] [--report DIR] [--rrd FILE] [--history DB] ...

Twin against real, as a regression test a CI job can act on: two runs of the same poses
(``rehearse --poses P.json`` on the twin and ``sample --poses P.json`` on the cell, or
any two runs of one pose list) compared sample by sample (``planecal.estimation.
agreement``, docs/HISTORY.md): the differences run - rehearsal against the noise model
(the robot's repeatability, robot.json's or --repeatability-mm, through each pose's
Jacobian), the chi-square test of their sum of squares with its p-value, the paired t and
Wilcoxon tests of their mean, the samples beyond the Bonferroni limit, and which model
parameters explain a difference (the Jacobian at --params' values, else the scene's
nominal ones; --suspects, default the joint offsets; any parameter of the whole model).

The runs must be the same poses: the same number of samples and, sample by sample, the
same plate and encoder counts within --count-tolerance (default 2); otherwise one line
naming the first that differs (exit 2).

Prints the verdict (--json: the JSON verdict, format planecal-compare/1, instead),
writes it to --out, a report page with --report DIR and a Rerun recording overlaying the
two runs with --rrd, and records it in the cell's history. Exit 0: agree; 1: differ;
2: bad input.
"""
from __future__ import annotations

import sys

from planecal.base.errors import InputError
from planecal.commands.value_options import count
from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               new_entry, open_history, record)
from planecal.commands.verdict_options import add_verdict_arguments, emit_verdict, verdict_out


def add_arguments(p):
    p.add_argument("run", metavar="RUN.tsv", help="the run (e.g. the real cell's)")
    p.add_argument("--rehearsal", required=True, metavar="TWIN.tsv",
                   help="the rehearsal of the same poses (e.g. on the twin)")
    p.add_argument("--params", default=None, metavar="RESULT.json",
                   help="the parameters whose Jacobian explains a difference (default: the "
                        "scene's nominal values)")
    add_verdict_arguments(p, "the false-alarm rate of the verdict",
                          "parameters that may explain a difference (default: the joint "
                          "offsets delta1..delta6; any of the whole model's)")
    p.add_argument("--repeatability-mm", type=float, default=None,
                   help="the robot's repeatability of the noise model, +- mm at the flange "
                        "(default: robot.json's)")
    p.add_argument("--count-tolerance", type=count(1000, 0), default=2, metavar="N",
                   help="the most a pair's encoder counts may differ and still be one pose "
                        "(default %(default)s)")
    p.add_argument("--scene", default=None,
                   help="the scene (default: the rehearsal's sidecar's, else thesis_final)")
    p.add_argument("--report", metavar="DIR", default=None,
                   help="also write a report page (index.html, PNG figures) into DIR")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="write a Rerun recording that overlays the two runs")
    add_history_arguments(p)


def _scene(args):
    from planecal.model.scene import DEFAULT_SCENE, load_scene
    from planecal.sampling.runfiles import sidecar_path
    if args.scene:
        return load_scene(args.scene)
    if sidecar_path(args.rehearsal).exists():
        from pathlib import Path

        from planecal.sampling.runfiles import load_sidecar
        side = load_sidecar(args.rehearsal)
        for where in (side.get("scene_path"), side.get("scene")):
            if isinstance(where, str) and where and (where == side.get("scene")
                                                     or Path(where).is_file()):
                return load_scene(where)
    return load_scene(DEFAULT_SCENE)


def _noise(args, robot) -> tuple[float, dict]:
    import numpy as np

    from planecal.estimation.noise import repeatability_sigma
    rep = args.repeatability_mm
    if rep is not None and not (np.isfinite(rep) and rep > 0):
        raise InputError(f"--repeatability-mm must be > 0, got {rep:g}")
    r_m = robot.repeatability_m if rep is None else rep * 1e-3
    if not r_m > 0:
        raise InputError(f"{robot.source}: the robot states no repeatability_mm; give "
                         "--repeatability-mm")
    return repeatability_sigma(robot, r_m), {
        "repeatability_mm": r_m * 1e3, "distance_sigma_um": 1.0, "quantization": True,
        "source": "--repeatability-mm" if rep is not None else "robot.json"}


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import (Files, report_output, rrd_output, scene_inputs,
                                              with_sidecars)
    from planecal.present.agreement import COMPARE_FORMAT
    f = Files().read(*with_sidecars([args.run, args.rehearsal]), args.params,
                     *scene_inputs(args.scene))
    f.write(args.out, "--out", COMPARE_FORMAT)
    report_output(f, args.report, "--report")
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.estimation.agreement import compare_runs, pair
    from planecal.estimation.drift import parse_suspects
    from planecal.io.samples import read_samples
    from planecal.model.levels import layout_for
    from planecal.present.agreement import COMPARE_FORMAT, compare_document, compare_text

    given = [args.run, args.rehearsal, args.params]
    out = verdict_out(args, given, COMPARE_FORMAT)
    hist = open_history(args, given + [out])
    scene = _scene(args)
    params = _params(args, scene)
    run_s, reh_s = read_samples(args.run, scene), read_samples(args.rehearsal, scene)
    pr = pair(run_s, reh_s, args.count_tolerance, (str(args.run), str(args.rehearsal)))
    if pr.plate.max(initial=0) >= params.n_planes:
        raise InputError(f"{args.run}: samples on plate {pr.plate.max() + 1}, the parameters "
                         f"hold {params.n_planes} plane(s)")
    js, noise = _noise(args, scene.robot)
    layout = layout_for(scene.robot, params.n_planes, "full", True)
    ag = compare_runs(scene.robot, params, layout, pr, js, 1e-6, args.alpha,
                      parse_suspects(args.suspects, layout))
    noise["pair_sigma_median_mm"] = float(sorted(ag.sigma_m)[len(ag.sigma_m) // 2] * 1e3)
    doc = compare_document(ag, pr, str(args.run), str(args.rehearsal), noise)
    emit_verdict(args, doc, compare_text, out)
    _renderings(args, doc, scene, params)
    _record(args, hist, scene, doc, out)
    return doc["exit_code"]


def _params(args, scene):
    from planecal.io.params import load_params
    from planecal.model.scene import nominal_params
    return load_params(args.params, scene.robot) if args.params else nominal_params(scene)


def _renderings(args, doc: dict, scene, params) -> None:
    """--report and --rrd, from the verdict document."""
    stream = sys.stderr if args.json else sys.stdout  # stdout carries the JSON verdict
    if args.report:
        from planecal.present.report import write_report
        path = write_report(doc, args.report, scene=str(scene.path))
        print(f"report written to {path}", file=stream)
    if args.rrd:
        from planecal.present.rerun.compare import log_compare
        print(f"recording written to {log_compare(args.rrd, doc, scene, params)}",
              file=stream)


def _record(args, hist, scene, doc: dict, out) -> None:
    from planecal.sampling.runfiles import run_world
    prov = command_provenance(scene, [("run", args.run), ("rehearsal", args.rehearsal),
                                      ("params", args.params)])
    summary = {"verdict": doc["verdict"], "samples": doc["test"]["dof"],
               "p_value": doc["test"]["p_value"], "alpha": doc["test"]["alpha"],
               "mean_difference_mm": doc["mean_difference_mm"],
               "explained_by": doc["explained_by"]}
    record(hist, new_entry(args, "compare", doc["verdict"], doc["exit_code"], prov,
                           robot_sha256=scene.robot.digest, summary=summary, document=doc,
                           world={"run": run_world(args.run),
                                  "rehearsal": run_world(args.rehearsal)},
                           output=str(out) if out else None), args.json)
