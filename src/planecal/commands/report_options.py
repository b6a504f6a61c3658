"""``--report DIR`` on a command whose result ``planecal report`` reads (calibrate,
bootstrap, plan, ...): the same option and the same writer everywhere."""
from __future__ import annotations


def add_report_argument(p) -> None:
    """``--report DIR`` for a command whose result ``planecal report`` reads."""
    p.add_argument("--report", metavar="DIR", default=None,
                   help="also write a report (index.html and PNG figures) into DIR")


def write_command_report(report_dir, result, samples=None, scene=None) -> None:
    """The report of a command's result (a dict or a file) into ``report_dir``, if given."""
    if not report_dir:
        return
    from planecal.present.report import write_report
    path = write_report(result, report_dir, samples=samples, scene=scene)
    print(f"report written to {path}")
