"""``--report DIR`` on a command whose result ``planecal report`` reads (calibrate,
bootstrap, plan, ...): the same option everywhere (its writer: ``jobs.report.
write_command_report``)."""
from __future__ import annotations


def add_report_argument(p) -> None:
    """``--report DIR`` for a command whose result ``planecal report`` reads."""
    p.add_argument("--report", metavar="DIR", default=None,
                   help="also write a report (index.html and PNG figures) into DIR")
