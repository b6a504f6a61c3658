"""Report of a twin-against-real comparison (``compare --out``, format planecal-compare/1):
the two runs' distances overlaid sample by sample, their difference against the noise
model's band with what explains it, the standardized differences against N(0, 1), and
the tests' table. Everything is read from the verdict document."""
from __future__ import annotations

import numpy as np

from planecal.present.drift import SUSPECT_HEADERS, suspect_rows
from planecal.present.report.figures import AFTER, BEFORE, new_figure, save
from planecal.present.report.inputs import Context
from planecal.present.report.page import Page

RUN, REHEARSAL = "#d62728", "#1f77b4"


def _col(doc, key) -> np.ndarray:
    return np.array([s[key] for s in doc["samples"]], float)


def fig_distances(out, doc):
    k = _col(doc, "sample")
    fig, axes = new_figure(9.0, 3.6)
    ax = axes[0, 0]
    ax.plot(k, _col(doc, "rehearsal_mm"), "s", mfc="white", color=REHEARSAL, ms=7,
            label=f"rehearsal ({doc['rehearsal']})")
    ax.plot(k, _col(doc, "run_mm"), "o", color=RUN, ms=4, label=f"run ({doc['run']})")
    ax.set_xlabel("sample (the same pose in both runs)")
    ax.set_ylabel("measured distance [mm]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=9)
    ax.set_title("The two runs, pose by pose", fontsize=11)
    return save(fig, out, "distances", "Distances of both runs",
                "The laser distance each run measured at each pose (the same encoder counts "
                "in both). Open squares: the rehearsal; dots: the run. Differences of a "
                "tenth of a millimetre hardly show at this scale: the next figure shows them.")


def fig_differences(out, doc):
    k = _col(doc, "sample")
    d, s, fit = _col(doc, "difference_mm"), _col(doc, "sigma_mm"), _col(doc, "explained_mm")
    lim = doc["z_limit"]
    fig, axes = new_figure(9.0, 4.4)
    ax = axes[0, 0]
    ax.fill_between(k, -lim * s, lim * s, color="#cccccc", alpha=0.6, step="mid",
                    label=f"noise band ±{lim:.2f} σ (σ of the pair from the noise model)")
    ax.axhline(0.0, color="#555", lw=0.8)
    flagged = np.abs(d) > lim * s
    ax.plot(k[~flagged], d[~flagged], "o", color=AFTER, ms=5, label="difference run − rehearsal")
    if flagged.any():
        ax.plot(k[flagged], d[flagged], "o", color=BEFORE, ms=6, label="beyond the band")
    if doc.get("explanation"):
        names = ", ".join(p["label"] for p in doc["explanation"]["parameters"])
        ax.plot(k, fit, "-", color="#2ca02c", lw=1.5, label=f"explained by {names}")
    ax.set_xlabel("sample")
    ax.set_ylabel("difference [mm]")
    ax.grid(True, alpha=0.3)
    fig.legend(loc="outside lower center", ncols=2, fontsize=8)
    t = doc["test"]
    ax.set_title(f"Difference per sample: chi² = {t['chi2']:.1f} on {t['dof']} samples, "
                 f"p = {t['p_value']:.3g} → {doc['verdict'].upper()}", fontsize=11)
    return save(fig, out, "differences", "Difference per sample",
                "The run's distance minus the rehearsal's at each pose, against the band the "
                "noise model gives the pair (the robot's repeatability through the pose's "
                "Jacobian, the sensor, quantisation), Bonferroni-wide over the samples. The "
                "line is the difference the named parameters explain.")


def fig_z(out, doc):
    z = _col(doc, "z")
    fig, axes = new_figure(6.0, 3.6)
    ax = axes[0, 0]
    top = max(4.0, float(np.abs(z).max()) * 1.05)
    bins = np.linspace(-top, top, 25)
    ax.hist(z, bins=bins, color=AFTER, alpha=0.7, label="standardized differences z")
    x = np.linspace(-top, top, 400)
    width = bins[1] - bins[0]
    ax.plot(x, len(z) * width * np.exp(-0.5 * x ** 2) / np.sqrt(2 * np.pi), "-", color="#333",
            label="N(0, 1): the runs agree")
    ax.set_xlabel("z = difference / σ")
    ax.set_ylabel("samples")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return save(fig, out, "z", "Standardized differences",
                "Where the two worlds agree, z follows N(0, 1) (less wide where the noise "
                "model overstates the noise).")


def build(ctx: Context) -> Page:
    doc, out = ctx.doc, ctx.out_dir
    t = doc["test"]
    page = Page("Twin against real: two runs of the same poses",
                f"Run {doc['run']} against rehearsal {doc['rehearsal']}: {t['dof']} samples. "
                f"Verdict: {doc['verdict'].upper()} (exit {doc['exit_code']}).")
    sec = page.section("Verdict")
    sec.finding(
        f"chi-square test of the standardized differences: sum z² = {t['chi2']:.1f} on "
        f"{t['dof']} samples, p = {t['p_value']:.3g} at alpha {t['alpha']:g}: the runs "
        + ("differ by more than their noise." if doc["verdict"] == "differ"
           else "differ by their noise only."), ok=doc["verdict"] == "agree")
    nm = doc["noise_model"]
    sec.table(["test", "value"], [
        ["mean difference (run − rehearsal)", f"{doc['mean_difference_mm']:+.4f} mm"],
        ["RMS difference", f"{doc['rms_difference_mm']:.4f} mm"],
        ["chi-square p (the verdict)", f"{t['p_value']:.3g}"],
        ["paired t-test of the mean, p", f"{doc['paired_t_test_p']:.3g}"],
        ["Wilcoxon signed-rank, p", f"{doc['wilcoxon_signed_rank_p']:.3g}"],
        ["noise model: repeatability", f"{nm['repeatability_mm']:g} mm ({nm['source']})"],
        ["samples beyond the band", ", ".join(map(str, doc["flagged_samples"])) or "none"],
        ["largest count difference of a pair", str(doc["max_count_difference"])]], left=1)
    sec = page.section("The runs")
    for fig in (fig_distances(out, doc), fig_differences(out, doc), fig_z(out, doc)):
        sec.figure(fig)
    sec = page.section("What explains the difference")
    sec.text("Each suspect fitted alone to the differences (the run's value minus the "
             "rehearsal's, the rest held), weighted by the noise model:")
    sec.table(SUSPECT_HEADERS, suspect_rows(doc["suspects"]), left=1)
    e = doc.get("explanation")
    if e:
        sec.finding("Explained by " + "; ".join(p["label"] for p in e["parameters"])
                    + (" (what is left is noise)." if e["explains"]
                       else " and something no suspect holds."), ok=e["explains"])
    elif doc["verdict"] == "differ":
        sec.finding("No suspect explains the difference: an error source without a parameter, "
                    "or noise above the model's.")
    return page
