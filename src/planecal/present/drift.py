"""Every rendering of a drift check (``planecal check``) and of a history diff: the JSON
verdict a CI job reads (``check_document``), the terminal text made from it only
(``check_text``), and the diff table (``diff_rows``, ``diff_text``). Parameters are named
in robot terms: "J3 (delta3)", values in the layout's display units."""
from __future__ import annotations

import re

from planecal.estimation.drift import Change, DriftCheck
from planecal.present.tables import table

CHECK_FORMAT = "planecal-check/1"


def param_label(name: str) -> str:
    """A parameter in robot terms: 'J3 (delta3)' for a joint offset, else its name."""
    m = re.fullmatch(r"delta(\d+)", name)
    return f"J{m.group(1)} ({name})" if m else name


def in_display(name: str, v: float | None) -> tuple[str, str]:
    """(value in the parameter's display unit, the unit): rad in mrad, m in mm."""
    from planecal.model.layout import quantity_of
    if v is None:
        return "-", ""
    q = quantity_of(name)
    scale, unit = {"rad": (1e3, "mrad"), "m": (1e3, "mm")}.get(
        q["unit"], (q["display_scale"], q["display_unit"]))
    return f"{v * scale:+.4f}", unit


SUSPECT_HEADERS = ["parameter", "amount", "std", "z", "significant", "p after it"]


def suspect_rows(suspects: list[dict]) -> list[list[str]]:
    """The suspects of a check or compare document as table rows (display units)."""
    rows = []
    for s in suspects:
        v, unit = in_display(s["name"], s["amount"])
        sd, _ = in_display(s["name"], s["std"])
        rows.append([s["label"], f"{v} {unit}", f"{sd.lstrip('+')} {unit}", f"{s['z']:+.1f}",
                     "yes" if s["significant"] else "", f"{s['p_after']:.3g}"])
    return rows


def check_document(chk: DriftCheck, run: str, result: str, weighted: bool,
                   against: int | None = None, reference_runs=()) -> dict:
    """The check's JSON verdict (format ``planecal-check/1``; docs/HISTORY.md)."""
    t, e = chk.test, chk.explanation if chk.drifted else None
    unit = "weighted" if weighted else "m"
    return {
        "format": CHECK_FORMAT, "run": run, "result": result, "against_entry": against,
        "verdict": "drifted" if chk.drifted else "in_control",
        "reference": {"kind": "runs" if reference_runs else "calibration",
                      "runs": [str(p) for p in reference_runs], "samples": t.n,
                      "meaning": "earlier in-control runs of this result" if reference_runs
                      else "the calibration's residuals"},
        "exit_code": 1 if chk.drifted else 0,
        "test": {"name": "exceedance test (two-sample median test, distribution-free)",
                 "statistic": "run samples above the reference's median studentized "
                              "|model error|",
                 "reference_samples": t.n, "run_samples": t.m, "threshold": t.threshold,
                 "threshold_unit": unit, "exceedances": t.exceed,
                 "expected": t.expected, "expected_std": t.std, "p_value": t.p,
                 "alpha": t.alpha, "attained_false_alarm_rate": t.attained_alpha,
                 "critical_exceedances": t.critical},
        "model_error": {"sign": "predicted - measured", "run_rms_mm": chk.run_rms_m * 1e3,
                        "run_mean_mm": chk.run_mean_m * 1e3,
                        "calibration_rms_mm": chk.calibration_rms_m * 1e3},
        "suspects": [{"name": s.name, "label": param_label(s.name), "amount": s.amount,
                      "std": s.std, "z": s.z, "significant": s.significant,
                      "p_after": s.p_after, "explains": s.explains,
                      "meaning": "the run's value minus the result's, the rest held"}
                     for s in chk.suspects],
        "z_limit": chk.z_limit, "chi2_limit": chk.chi2_limit, "no_effect": chk.no_effect,
        "moved": chk.moved,
        "gross_errors": [{"sample": i + 1, "model_error_mm": r * 1e3, "studentized": v}
                         for i, r, v in chk.gross],
        "gross_error_limit": chk.gross_limit,
        "explanation": None if e is None else {
            "parameters": [{"name": n, "label": param_label(n), "amount": v, "std": sd}
                           for n, v, sd in zip(e.names, e.amounts, e.stds)],
            "p_after": e.p_after, "explains": e.explains,
            "alternatives": list(e.alternatives),
            "meaning": "chosen one by one, each explaining most of what the ones before "
                       "leave; amounts fitted jointly (the run's value minus the result's)"},
    }


def check_text(doc: dict) -> str:
    """The terminal report of a check document."""
    t, me = doc["test"], doc["model_error"]
    thr = (f"{t['threshold'] * 1e3:.4f} mm" if t["threshold_unit"] == "m"
           else f"{t['threshold']:.4f} (weighted)")
    lines = [
        f"drift check of {doc['run']} ({t['run_samples']} samples) against {doc['result']}"
        + (f" (history entry {doc['against_entry']})" if doc.get("against_entry") else ""),
        "reference: " + (f"{len(doc['reference']['runs'])} earlier in-control runs of the "
                         f"result ({t['reference_samples']} samples)"
                         if doc["reference"]["kind"] == "runs" else
                         f"the calibration's {t['reference_samples']} residuals"),
        f"model error (predicted - measured) with the result's parameters: run RMS "
        f"{me['run_rms_mm']:.4f} mm, mean {me['run_mean_mm']:+.4f} mm; calibration RMS "
        f"{me['calibration_rms_mm']:.4f} mm",
        f"exceedance test: {t['exceedances']} of the run's {t['run_samples']} studentized "
        f"|model errors| above the reference's median {thr} (expected {t['expected']:.1f} "
        f"+- {t['expected_std']:.1f} with no drift); p = {t['p_value']:.3g}",
        f"alpha {t['alpha']:g}: false-alarm rate {t['attained_false_alarm_rate']:.4f} (the "
        f"test's attained size: drifted from {t['critical_exceedances']} exceedances on)"]
    gross = doc.get("gross_errors") or []
    if gross:
        lines.append("gross errors (over 10x the reference's largest studentized error: a "
                     "reading or a pose gone wrong, or a drift far beyond the calibration's "
                     "scale): " + ", ".join(f"sample {g['sample']} {g['model_error_mm']:+.4f} mm"
                                            for g in gross[:10])
                     + (f" and {len(gross) - 10} more" if len(gross) > 10 else ""))
    if doc["verdict"] == "in_control":
        lines.append("IN CONTROL: the run errs as the reference did (exit 0)")
    else:
        lines.append("DRIFTED: the run errs more than the reference did (exit 1)")
    lines.append(f"suspects, each alone with the rest held at the result's values (the run's "
                 f"value minus the result's; significant where |z| > {doc['z_limit']:.2f}):")
    lines.append(table(SUSPECT_HEADERS, suspect_rows(doc["suspects"]), "lrrrll"))
    if doc["no_effect"]:
        lines.append(f"no effect on these samples: {', '.join(doc['no_effect'])}")
    lines += _explanation_lines(doc)
    return "\n".join(lines)


def _explanation_lines(doc: dict) -> list[str]:
    e = doc.get("explanation")
    if doc["verdict"] != "drifted":
        return []
    if not e:
        return ["no suspect explains the drift: something else moved (a plate, the sensor: "
                "name it with --suspects), or something the model has no parameter for"]
    parts = []
    for p in e["parameters"]:
        v, unit = in_display(p["name"], p["amount"])
        sd, _ = in_display(p["name"], p["std"])
        parts.append(f"{p['label']} {v} +- {sd.lstrip('+')} {unit}")
    out = [f"MOVED: {'; '.join(parts)}" + (
        f" (after it the run is in control, p = {e['p_after']:.3g})" if e["explains"] else
        " (the run still errs after it: something the suspects do not hold moved too)")]
    if e["alternatives"]:
        out.append(f"as well explained by {', '.join(param_label(n) for n in e['alternatives'])}"
                   f" alone (chi-square within {doc['chi2_limit']:.2f}): these poses cannot "
                   "tell them apart; a run with more varied poses can")
    return out


def diff_rows(changes: list[Change]) -> list[list[str]]:
    rows = []
    for c in changes:
        va, unit = in_display(c.name, c.a)
        vb, _ = in_display(c.name, c.b)
        d, _ = in_display(c.name, c.change)
        sd, _ = in_display(c.name, c.std)
        rows.append([param_label(c.name), unit, va, vb, d, sd.lstrip("+"),
                     "-" if c.z is None else f"{c.z:+.1f}",
                     "SIGNIFICANT" if c.significant else ""])
    return rows


def diff_text(a: int, b: int, changes: list[Change], limit: float, alpha: float) -> str:
    head = (f"history diff {a} -> {b}: change = B - A, std = sqrt(std_A^2 + std_B^2) (two "
            f"independent calibrations); significant where |z| > {limit:.2f} (alpha {alpha:g} "
            f"over the {sum(c.std is not None for c in changes)} parameters with a std)")
    body = table(["parameter", "unit", f"A ({a})", f"B ({b})", "change", "std", "z", ""],
                 diff_rows(changes), "llrrrrrl")
    sig = [param_label(c.name) for c in changes if c.significant]
    tail = ("significant: " + ", ".join(sig)) if sig else "no significant change"
    return "\n".join([head, body, tail])


def diff_document(a: int, b: int, changes: list[Change], limit: float, alpha: float) -> dict:
    return {"a": a, "b": b, "alpha": alpha, "z_limit": limit,
            "changes": [{"name": c.name, "label": param_label(c.name), "a": c.a, "b": c.b,
                         "std_a": c.std_a, "std_b": c.std_b, "change": c.change,
                         "std": c.std, "z": c.z, "significant": c.significant}
                        for c in changes],
            "significant": [c.name for c in changes if c.significant]}
