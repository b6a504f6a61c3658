"""Renderings of a cell's history (``planecal history list | show``): the list table with
one line per entry, and one entry in full (text or JSON)."""
from __future__ import annotations

import json
import math
import re
from dataclasses import asdict

from planecal.present.tables import table

_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f]")


def shown(v) -> str:
    """A stored text as one line: control characters (a newline a hand put in a note)
    escaped, so a list keeps one line per entry."""
    if v is None:
        return ""
    return _CONTROL.sub(lambda m: m.group(0).encode("unicode_escape").decode(), str(v))


def what(e) -> str:
    """An entry's key figures in a few words, from its summary."""
    s = e.summary or {}
    if e.kind == "calibrate":
        return (f"level {s.get('level')}{' + compliance' if s.get('compliance') else ''}, "
                f"{s.get('samples_used')} samples, RMS {_mm(s.get('residual_rms_mm'))}"
                + (f"; {s['failure']}" if s.get("failure") else ""))
    from planecal.present.drift import param_label
    if e.kind == "check":
        moved = ", ".join(param_label(n) for n in s.get("moved") or [])
        return (f"{s.get('exceedances')}/{s.get('run_samples')} above the median, p "
                f"{_g(s.get('p_value'))}, RMS {_mm(s.get('run_rms_mm'))}"
                + (f"; moved: {moved}" if moved else ""))
    if e.kind == "compare":
        moved = ", ".join(param_label(n) for n in s.get("explained_by") or [])
        return (f"{s.get('samples')} samples, chi2 p {_g(s.get('p_value'))}, mean diff "
                f"{_mm(s.get('mean_difference_mm'))}" + (f"; explained by {moved}" if moved
                                                          else ""))
    if e.kind in ("export", "rollback"):
        fmt = s.get("format", "")
        src = f"entry {e.against}" if e.against else "a result file"
        return f"{fmt} of {src}" + (f" -> {e.output}" if e.output else " (printed)")
    if e.kind == "validate":
        return (f"AP at the tool point {_mm(s.get('ap_before_tool_median_mm'))} nominal -> "
                f"{_mm(s.get('ap_after_tool_median_mm'))} calibrated (median over "
                f"{s.get('truths')} truth(s); the true model "
                f"{_mm(s.get('ap_oracle_tool_median_mm'))})")
    return ""


def _number(v) -> float | None:
    """A summary's figure if it is one (a finite number), else None: what a hand or another
    tool put there is never printed as a number."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return float(v)


def _mm(v) -> str:
    v = _number(v)
    return "-" if v is None else f"{v:.4f} mm"


def _g(v) -> str:
    v = _number(v)
    return "-" if v is None else f"{v:.3g}"


def damage(e) -> str:
    """What an entry holds that planecal does not write, in a few words ('' for nothing)."""
    if not e.problems:
        return ""
    fields = list(dict.fromkeys(p.split(":", 1)[0] for p in e.problems))
    return "damaged: " + ", ".join(fields[:4]) + (", ..." if len(fields) > 4 else "")


def list_text(entries, label: str) -> str:
    if not entries:
        return f"history {label}: no entries"
    rows = [[str(e.id), shown(e.created_utc.replace("+00:00", "Z")), shown(e.kind),
             shown(e.cell) or "-", shown(e.outcome), str(e.against or ""),
             shown("; ".join(x for x in (what(e), damage(e)) if x)), shown(e.note)]
            for e in entries]
    return (f"history {label}: {len(entries)} entries\n"
            + table(["#", "date (UTC)", "kind", "cell", "outcome", "against", "what", "note"],
                    rows, "rllllrll"))


def entry_document(e) -> dict:
    """One entry as JSON (``history show --json``)."""
    d = asdict(e)
    d["inputs"] = [asdict(i) for i in e.inputs]
    d["parameters"] = [asdict(p) for p in e.parameters]
    return d


def show_text(e, label: str) -> str:
    s = shown
    lines = [f"history {label}, entry {e.id}: {s(e.kind)} ({s(e.outcome)}, exit {e.exit_code})",
             f"  date (UTC)        {s(e.created_utc)}",
             f"  cell / scene      {s(e.cell)} / {s(e.scene)}",
             f"  robot             {s(e.robot)} (description SHA-256 "
             f"{s(e.robot_sha256) or '-'})",
             f"  planecal          {s(e.planecal_version)}",
             f"  world             {s(json.dumps(e.world)) if e.world else '- (not recorded)'}",
             f"  against           {('entry ' + str(e.against)) if e.against else '-'}",
             f"  result SHA-256    {s(e.result_sha256) or '-'}",
             f"  output            {s(e.output) or '-'}",
             f"  note              {s(e.note) or '-'}",
             f"  what              {s(what(e))}"]
    lines += [f"  DAMAGED           {s(p)}" for p in e.problems]
    if e.inputs:
        lines.append("  inputs:")
        lines += [f"    {s(i.role):<20} {s(i.path)}  ({i.bytes} bytes, SHA-256 "
                  f"{s(i.sha256)[:16]}...)" for i in e.inputs]
    if e.parameters:
        lines.append(table(["parameter", "value", "std", "unit", "status"],
                           [_parameter_row(p) for p in e.parameters], "lrrll"))
    return "\n".join(lines)


def _parameter_row(p) -> list[str]:
    from planecal.present.drift import in_display, param_label
    try:
        v, unit = in_display(p.name, p.value)
        sd, _ = in_display(p.name, p.std)
    except KeyError:  # a name no parameter group gives (a hand's): SI, as stored
        v = "-" if p.value is None else f"{p.value:+.6g}"
        sd = "-" if p.std is None else f"{p.std:.6g}"
        unit = p.unit or ""
    return [shown(param_label(p.name)), v, sd.lstrip("+"), shown(unit), shown(p.status)]
