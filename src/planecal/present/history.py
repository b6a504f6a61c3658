"""Renderings of a cell's history (``planecal history list | show``): the list table with
one line per entry, and one entry in full (text or JSON)."""
from __future__ import annotations

import json
from dataclasses import asdict

from planecal.present.tables import table


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


def _mm(v) -> str:
    return "-" if v is None else f"{v:.4f} mm"


def _g(v) -> str:
    return "-" if v is None else f"{v:.3g}"


def list_text(entries, label: str) -> str:
    if not entries:
        return f"history {label}: no entries"
    rows = [[str(e.id), e.created_utc.replace("+00:00", "Z"), e.kind, e.cell or "-",
             e.outcome, str(e.against or ""), what(e), e.note or ""] for e in entries]
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
    lines = [f"history {label}, entry {e.id}: {e.kind} ({e.outcome}, exit {e.exit_code})",
             f"  date (UTC)        {e.created_utc}",
             f"  cell / scene      {e.cell} / {e.scene}",
             f"  robot             {e.robot} (description SHA-256 {e.robot_sha256 or '-'})",
             f"  planecal          {e.planecal_version}",
             f"  world             {json.dumps(e.world) if e.world else '- (not recorded)'}",
             f"  against           {('entry ' + str(e.against)) if e.against else '-'}",
             f"  result SHA-256    {e.result_sha256 or '-'}",
             f"  output            {e.output or '-'}",
             f"  note              {e.note or '-'}",
             f"  what              {what(e)}"]
    if e.inputs:
        lines.append("  inputs:")
        lines += [f"    {i.role:<20} {i.path}  ({i.bytes} bytes, SHA-256 {i.sha256[:16]}...)"
                  for i in e.inputs]
    if e.parameters:
        from planecal.present.drift import in_display, param_label
        rows = []
        for p in e.parameters:
            v, unit = in_display(p.name, p.value)
            sd, _ = in_display(p.name, p.std)
            rows.append([param_label(p.name), v, sd.lstrip("+"), unit, p.status])
        lines.append(table(["parameter", "value", "std", "unit", "status"], rows, "lrrll"))
    return "\n".join(lines)
