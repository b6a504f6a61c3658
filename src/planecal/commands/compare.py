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
The cell is the runs' (their sidecars) and --params' (its provenance), which must agree;
a --scene that contradicts them is refused.

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

from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               new_entry, open_history, record)
from planecal.commands.value_options import count
from planecal.commands.verdict_options import add_verdict_arguments, emit_verdict, verdict_out


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
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
    add_scene_argument(p, "the runs", reads="the runs' sidecars and --params' provenance")
    p.add_argument("--report", metavar="DIR", default=None,
                   help="also write a report page (index.html, PNG figures) into DIR")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="write a Rerun recording that overlays the two runs")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import run_scene_inputs
    from planecal.commands.io_options import Files, report_output, rrd_output, with_sidecars
    from planecal.present.agreement import COMPARE_FORMAT
    f = Files().read(*with_sidecars([args.run, args.rehearsal]), args.params,
                     *run_scene_inputs([args.rehearsal, args.run], args.scene))
    f.write(args.out, "--out", COMPARE_FORMAT)
    report_output(f, args.report, "--report")
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.jobs.verdicts import CompareRequest, compare
    from planecal.present.agreement import COMPARE_FORMAT, compare_text

    given = [args.run, args.rehearsal, args.params]
    out = verdict_out(args, given, COMPARE_FORMAT)
    hist = open_history(args, given + [out])
    done = compare(CompareRequest(args.run, args.rehearsal, args.params, args.alpha,
                                  args.suspects, args.repeatability_mm, args.count_tolerance,
                                  args.scene))
    emit_verdict(args, done.verdict, compare_text, out)
    _renderings(args, done)
    _record(args, hist, done, out)
    return done.verdict["exit_code"]


def _renderings(args, done) -> None:
    """--report and --rrd, from the verdict document."""
    stream = sys.stderr if args.json else sys.stdout  # stdout carries the JSON verdict
    if args.report:
        from planecal.present.report import write_report
        path = write_report(done.verdict, args.report, scene=str(done.scene.path))
        print(f"report written to {path}", file=stream)
    if args.rrd:
        from planecal.present.rerun.compare import log_compare
        print(f"recording written to "
              f"{log_compare(args.rrd, done.verdict, done.scene, done.params)}", file=stream)


def _record(args, hist, done, out) -> None:
    doc = done.verdict
    prov = command_provenance(done.scene, [("run", args.run), ("rehearsal", args.rehearsal),
                                           ("params", args.params)])
    summary = {"verdict": doc["verdict"], "samples": doc["test"]["dof"],
               "p_value": doc["test"]["p_value"], "alpha": doc["test"]["alpha"],
               "mean_difference_mm": doc["mean_difference_mm"],
               "explained_by": doc["explained_by"]}
    record(hist, new_entry(args, "compare", doc["verdict"], doc["exit_code"], prov,
                           robot_sha256=done.scene.robot.digest, summary=summary, document=doc,
                           world=done.world, output=str(out) if out else None), args.json)
