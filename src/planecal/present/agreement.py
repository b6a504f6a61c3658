"""Every rendering of a twin-against-real comparison (``planecal compare``): the JSON
verdict a CI job reads (``compare_document``, format ``planecal-compare/1``) and the
terminal text made from it only (``compare_text``). The HTML page
(``present.report.compare``) and the Rerun view (``present.rerun.compare``) read the same
document."""
from __future__ import annotations

from planecal.estimation.agreement import Agreement, Paired
from planecal.present.drift import SUSPECT_HEADERS, in_display, param_label, suspect_rows
from planecal.present.tables import table

COMPARE_FORMAT = "planecal-compare/1"


def compare_document(ag: Agreement, pr: Paired, run: str, rehearsal: str,
                     noise: dict) -> dict:
    e = ag.explanation
    return {
        "format": COMPARE_FORMAT, "run": run, "rehearsal": rehearsal,
        "verdict": "agree" if ag.agree else "differ", "exit_code": 0 if ag.agree else 1,
        "difference": "run - rehearsal (measured distances)",
        "noise_model": noise,
        "test": {"name": "chi-square test of the standardized differences",
                 "statistic": "sum of z_i^2, z_i = difference_i / sigma_i",
                 "chi2": ag.chi2, "dof": ag.dof, "p_value": ag.p, "alpha": ag.alpha},
        "paired_t_test_p": ag.t_p, "wilcoxon_signed_rank_p": ag.wilcoxon_p,
        "mean_difference_mm": float(ag.difference_m.mean() * 1e3),
        "rms_difference_mm": float((ag.difference_m ** 2).mean() ** 0.5 * 1e3),
        "max_count_difference": pr.max_count_difference,
        "z_limit": ag.z_limit, "flagged_samples": [i + 1 for i in ag.flagged],
        "samples": [{"sample": i + 1, "plate": int(pr.plate[i]) + 1,
                     "run_mm": float(pr.run_m[i] * 1e3),
                     "rehearsal_mm": float(pr.rehearsal_m[i] * 1e3),
                     "difference_mm": float(ag.difference_m[i] * 1e3),
                     "sigma_mm": float(ag.sigma_m[i] * 1e3), "z": float(ag.z[i]),
                     "explained_mm": float(ag.fitted_m[i] * 1e3)}
                    for i in range(len(pr.run_m))],
        "suspects": [{"name": s.name, "label": param_label(s.name), "amount": s.amount,
                      "std": s.std, "z": s.z, "significant": s.significant,
                      "p_after": s.p_after, "explains": s.explains,
                      "meaning": "the run's value minus the rehearsal's, the rest held"}
                     for s in ag.suspects],
        "no_effect": ag.no_effect,
        "explained_by": [] if e is None or ag.agree else list(e.names),
        "explanation": None if e is None or ag.agree else {
            "parameters": [{"name": n, "label": param_label(n), "amount": v, "std": sd}
                           for n, v, sd in zip(e.names, e.amounts, e.stds)],
            "p_after": e.p_after, "explains": e.explains,
            "alternatives": list(e.alternatives)},
    }


def compare_text(doc: dict) -> str:
    t, nm = doc["test"], doc["noise_model"]
    lines = [
        f"compare {doc['run']} (run) with {doc['rehearsal']} (rehearsal): "
        f"{t['dof']} samples of the same poses (counts within "
        f"{doc['max_count_difference']})",
        f"difference run - rehearsal: mean {doc['mean_difference_mm']:+.4f} mm, RMS "
        f"{doc['rms_difference_mm']:.4f} mm; noise model: repeatability "
        f"{nm['repeatability_mm']:g} mm ({nm['source']}), a pair's std "
        f"{nm['pair_sigma_median_mm']:.4f} mm (median)",
        f"chi-square test: sum z^2 = {t['chi2']:.1f} on {t['dof']} samples, p = "
        f"{t['p_value']:.3g} (alpha {t['alpha']:g}); paired t-test of the mean p = "
        f"{doc['paired_t_test_p']:.3g}; Wilcoxon signed-rank p = "
        f"{doc['wilcoxon_signed_rank_p']:.3g}",
        f"samples beyond |z| > {doc['z_limit']:.2f}: "
        + (", ".join(map(str, doc["flagged_samples"])) or "none")]
    lines.append("AGREE: the runs differ by their noise only (exit 0)" if doc["verdict"] ==
                 "agree" else "DIFFER: the runs differ by more than their noise (exit 1)")
    lines.append("suspects, each alone (the run's value minus the rehearsal's):")
    lines.append(table(SUSPECT_HEADERS, suspect_rows(doc["suspects"]), "lrrrll"))
    e = doc.get("explanation")
    if doc["verdict"] == "differ":
        if e:
            parts = []
            for p in e["parameters"]:
                v, unit = in_display(p["name"], p["amount"])
                sd, _ = in_display(p["name"], p["std"])
                parts.append(f"{p['label']} {v} +- {sd.lstrip('+')} {unit}")
            lines.append("explained by: " + "; ".join(parts) + (
                f" (what is left is noise, p = {e['p_after']:.3g})" if e["explains"] else
                " (and something no suspect holds: an error source without a parameter)"))
            if e["alternatives"]:
                lines.append("as well explained by " + ", ".join(
                    param_label(n) for n in e["alternatives"]) + " alone: these poses "
                    "cannot tell them apart")
        else:
            lines.append("no suspect explains the difference: an error source without a "
                         "parameter (gear error, backlash, compliance), or noise above the "
                         "model's")
    return "\n".join(lines)
