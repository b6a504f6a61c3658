"""Report of a Monte Carlo study (``montecarlo --out``).

Figures: per parameter group the histograms of the runs' errors (estimate − truth) against
the density they should follow if the estimator reaches the Cramer-Rao bound (each run's
error ~ N(0, CRB_run), so the expected density is the mean of those normals over the
runs); the chi-square statistics against the chi2(k) density; the ratios of the
empirical spread to the bound and to the reported std, and the bias in units of the
bound, with their standard errors; with ``--slope``, the spread against the number of
samples on log-log axes with the N^-1/2 reference.
"""
from __future__ import annotations

import numpy as np

from matplotlib.ticker import NullLocator

from planecal.present.report.figures import (AFTER, BEFORE, TABLE_UNITS, display_scale, grid_shape,
                                     groups, hide_unused, integer_y, label, log_ticks,
                                     new_figure, num, parameter_unit, save)
from planecal.present.report.inputs import Context
from planecal.present.report.page import Page

CHI2 = (("chi2_offsets_reported", "offsets, the fit's reported covariance"),
        ("chi2_offsets_sandwich", "offsets, the sandwich covariance"),
        ("chi2_all_reported", "all free parameters, reported covariance"))


def _slug(group: str) -> str:
    return group.replace(" ", "_")


def fig_errors(out, group, names, free, E, C, params):
    """Histograms of the errors of ``names`` (columns of E, runs x free) against the
    mixture of the runs' N(0, CRB) densities."""
    from scipy import stats
    R = len(E)
    rows, cols = grid_shape(len(names))
    fig, axes = new_figure(3.6 * cols + 0.6, 2.9 * rows + 0.5, rows, cols)
    bins = int(np.clip(2 * np.sqrt(R), 5, 40))
    for ax, n in zip(axes.flat, names):
        i = free.index(n)
        ok = np.isfinite(E[:, i]) & np.isfinite(C[:, i])  # the runs that fitted it
        e, c = E[ok, i], C[ok, i]
        if not e.size:
            ax.text(0.5, 0.5, f"{label(n)}: no run fitted it", ha="center", va="center",
                    transform=ax.transAxes, fontsize=9)
            ax.set_axis_off()
            continue
        scale, unit = display_scale(parameter_unit(n), np.concatenate([e, 4 * c]))
        half = max(np.max(np.abs(e)), 4 * np.max(c)) * scale * 1.02
        edges = np.linspace(-half, half, bins + 1)
        ax.hist(e * scale, bins=edges, color=AFTER, alpha=0.75, edgecolor="white",
                label=f"{len(e)} runs")
        # expected runs per bin: the mixture's probability of each bin (exact for any
        # binning, also when the runs' bounds differ a lot, as delta5's do)
        cdf = np.mean([stats.norm.cdf(edges, 0.0, ci * scale) for ci in c], axis=0)
        ax.stairs(len(e) * np.diff(cdf), edges, color="black", linewidth=1.5,
                  label="expected runs per bin (CRB)")
        ax.set_xlabel(f"error of {label(n)} [{unit}]")
        ax.set_ylabel("runs")
        integer_y(ax)
        ax.set_title(f"{label(n)}: empirical std / CRB {params[n]['ratio_emp_to_crb']:.2f}",
                     fontsize=10)
    hide_unused(axes, len(names))
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    fig.suptitle(f"Errors over the runs against the Cramer-Rao density: {group}")
    return save(fig, out, f"errors_{_slug(group)}", f"Errors: {group}",
                "Histogram of estimate − truth per run; the black steps are the runs per bin "
                "expected if every run reaches its own Cramer-Rao bound (each run's error "
                "N(0, CRB of the run); the runs' designs differ, so this is a mixture).")


def fig_normalized(out, free, E, C, params):
    """Each run's error divided by its own run's bound, all parameters: N(0, 1) if the
    bound holds run by run (what std(e/CRB) in the table measures)."""
    from scipy import stats
    R = len(E)
    with np.errstate(invalid="ignore", divide="ignore"):
        Z = np.asarray(E, float) / np.asarray(C, float)
    rows, cols = grid_shape(len(free), 4)
    fig, axes = new_figure(3.0 * cols + 0.4, 2.5 * rows + 0.7, rows, cols)
    for ax, n in zip(axes.flat, free):
        z = Z[:, free.index(n)]
        z = z[np.isfinite(z)]
        if not z.size:  # no run fitted it (another base set each run): say so
            ax.text(0.5, 0.5, f"{label(n)}: no run fitted it", ha="center", va="center",
                    transform=ax.transAxes, fontsize=9)
            ax.set_axis_off()
            continue
        # each panel on its own axis: a parameter whose errors sit far out must not squeeze
        # the others into one bar
        half = max(4.0, float(np.max(np.abs(z))) * 1.02)
        edges = np.linspace(-half, half, int(np.clip(2 * np.sqrt(len(z)), 5, 40)) + 1)
        ax.hist(z, bins=edges, color=AFTER, alpha=0.75, edgecolor="white",
                label=f"{R} runs")
        ax.stairs(len(z) * np.diff(stats.norm.cdf(edges)), edges, color="black",
                  linewidth=1.5, label="expected runs per bin, N(0, 1)")
        ax.set_title(f"{label(n)}: std {params[n]['normalized_std']:.2f}", fontsize=9)
        integer_y(ax)
    for ax in axes[-1]:
        ax.set_xlabel("error / CRB of its run")
    for ax in axes[:, 0]:
        ax.set_ylabel("runs")
    hide_unused(axes, len(free))
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    fig.suptitle("Errors in units of their own run's Cramer-Rao bound")
    return save(fig, out, "errors_normalized", "Normalised errors",
                "Each run's error divided by the Cramer-Rao std of that run: standard normal "
                "if the bound holds run by run, however different the runs' designs are.")


def fig_chi2(out, res):
    from scipy import stats
    avail = [(k, what) for k, what in CHI2 if isinstance(res.get(k), dict)
             and res[k].get("values")]
    if not avail:
        return None
    fig, axes = new_figure(4.2 * len(avail) + 0.4, 3.8, 1, len(avail))
    for ax, (k, what) in zip(axes.flat, avail):
        c = res[k]
        T = np.asarray(c["values"], float)
        dof = int(c["dof"])
        top = max(np.max(T), stats.chi2.ppf(0.995, dof)) * 1.02
        edges = np.linspace(0, top, int(np.clip(2 * np.sqrt(len(T)), 5, 40)) + 1)
        ax.hist(T, bins=edges, color=AFTER, alpha=0.75, edgecolor="white",
                label="runs (histogram)")
        x = np.linspace(0, top, 400)
        ax.plot(x, len(T) * (edges[1] - edges[0]) * stats.chi2.pdf(x, dof), color="black",
                linewidth=1.3, label="χ²(k) density, k from the title")
        ax.axvline(c["mean"], color=BEFORE, linestyle="--", linewidth=1.2,
                   label="mean over the runs")
        ax.set_xlabel("statistic T = eᵀ C⁻¹ e")
        ax.set_ylabel("runs")
        integer_y(ax)
        ax.set_title(f"{what}\nmean {c['mean']:.2f} (expected {dof} ± {c['standard_error']:.2f}), "
                     f"KS p {c['ks_pvalue']:.3f}: "
                     + ("consistent" if c.get("passes") else "NOT consistent"), fontsize=9)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=3)
    fig.suptitle("Chi-square consistency of the covariance")
    return save(fig, out, "chi2", "Chi-square",
                "Per run T = eᵀC⁻¹e of the errors e with covariance C; T follows χ²(k) if C is "
                "the estimator's true covariance. The dashed line is the mean over the runs.")


def fig_ratios(out, res):
    params = res["params"]
    names = list(params)
    R = res["runs"]
    rse = float(res.get("relative_standard_error_of_std", 1 / np.sqrt(2 * (R - 1))))
    x = np.arange(len(names))
    fig, axes = new_figure(max(7.0, 0.6 * len(names) + 2.5), 6.4, 2, 1, sharex=True)
    ax = axes[0, 0]
    ax.axhspan(0.85, 1.15, color="#2ca02c", alpha=0.12, label="±15 % (target)")
    ax.axhline(1.0, color="#555", linewidth=0.8)
    for dx, key, color, what in ((-0.12, "ratio_emp_to_crb", AFTER, "empirical / CRB"),
                                 (0.12, "ratio_emp_to_reported", BEFORE,
                                  "empirical / reported std")):
        r = np.array([params[n][key] for n in names])
        ax.errorbar(x + dx, r, yerr=r * rse, fmt="o", color=color, capsize=3, label=what)
    ax.set_ylabel("ratio of standard deviations")
    ax.set_title(f"Spread over {R} runs against the bound and the reported std "
                 f"(error bars: ±1 standard error, {rse:.0%})", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    ax = axes[1, 0]
    b = np.array([params[n]["bias"] / params[n]["crb_std"] for n in names])
    se = np.array([params[n]["empirical_std"] / params[n]["crb_std"] / np.sqrt(R) for n in names])
    ax.axhspan(-0.2, 0.2, color="#2ca02c", alpha=0.12, label="±0.2 (target)")
    ax.axhline(0.0, color="#555", linewidth=0.8)
    ax.errorbar(x, b, yerr=se, fmt="o", color=AFTER, capsize=3, label="bias / CRB ± 1 s.e.")
    ax.set_ylabel("bias / CRB")
    ax.set_xticks(x, [label(n) for n in names])
    ax.set_xlabel("parameter")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "ratios", "Spread and bias against the bound",
                "Top: empirical std over the runs divided by the Cramer-Rao bound (RMS over "
                "runs) and by the std the fit reports; a std from R runs is known to "
                "1/sqrt(2(R−1)). Bottom: mean error in units of the bound, with its standard "
                "error (empirical std / sqrt(R)).")


def fig_slope(out, sl):
    offs = list(sl["slopes"])
    N = np.array([r["samples"] for r in sl["rows"]], float)
    rows, cols = grid_shape(len(offs), 2)
    fig, axes = new_figure(4.6 * cols + 0.6, 3.4 * rows + 0.5, rows, cols)
    for ax, p in zip(axes.flat, offs):
        emp = np.array([r[p]["empirical_std"] for r in sl["rows"]])
        crb = np.array([r[p]["crb_std"] for r in sl["rows"]])
        scale, unit = display_scale(parameter_unit(p), np.concatenate([emp, crb]))
        ax.loglog(N, emp * scale, "o", color=AFTER, label="empirical std")
        ax.loglog(N, crb * scale, "s--", color=BEFORE, mfc="white", label="Cramer-Rao bound")
        ref = crb[0] * scale * np.sqrt(N[0] / N)
        ax.loglog(N, ref, ":", color="#555", label=r"$\propto N^{-1/2}$ through the first bound")
        ax.set_xlabel("samples per run N")
        ax.set_ylabel(f"std of {label(p)} [{unit}]")
        ax.set_title(f"{label(p)}: slope {sl['slopes'][p]['empirical']:+.2f} empirical, "
                     f"{sl['slopes'][p]['crb']:+.2f} bound", fontsize=10)
        lo = min(emp.min() * scale, crb.min() * scale, ref.min())
        hi = max(emp.max(), crb.max()) * scale
        ax.set_ylim(lo / 1.15, hi * 1.15)
        log_ticks(ax, "y")
        ax.set_xticks(N, [f"{int(v)}" for v in N])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.grid(True, which="both", alpha=0.3)
    hide_unused(axes, len(offs))
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=3)
    fig.suptitle(f"Spread against the number of samples ({sl['runs_per_point']} runs per point)")
    return save(fig, out, "slope", "Spread against samples",
                "Empirical spread and Cramer-Rao bound of the joint offsets on log-log axes; "
                "the dotted line has the N^-1/2 slope expected of a consistent estimator.")


def build(ctx: Context) -> Page:
    res = ctx.doc
    st = res.get("settings", {})
    free = list(res["free"])
    E = np.array([[np.nan if v is None else v for v in row]
                  for row in res.get("run_errors", [])], float)
    C = np.array([[np.nan if v is None else v for v in row]
                  for row in res.get("run_crb_std", [])], float)
    out = ctx.out_dir
    page = Page("Monte Carlo study",
                f"Scene {st.get('scene', '?')}, mode {st.get('mode', '?')}: {res['runs']} runs of "
                f"{res.get('samples_per_run', float('nan')):.0f} samples; fit "
                + ("weighted by the noise model" if st.get("weighted") else "unweighted")
                + f"; noise model {res.get('sigma_model_mm', float('nan')) * 1e3:.3g} µm rms "
                f"per sample, fit sigma {res.get('sigma_fit_mm', float('nan')) * 1e3:.3g} µm.")
    sec = page.section("Errors against the Cramer-Rao bound")
    if E.ndim == 2 and E.shape[1] == len(free) and C.shape == E.shape:
        for group, names in groups(free).items():
            sec.figure(fig_errors(out, group, names, free, E, C, res["params"]))
        sec.figure(fig_normalized(out, free, E, C, res["params"]))
    else:
        sec.note("The result holds no per-run errors (keys 'run_errors', 'run_crb_std'): no "
                 "histograms.")
    sec = page.section("Spread, bias and the reported std")
    sec.figure(fig_ratios(out, res))
    rows = []
    for n, p in res["params"].items():
        k, unit = TABLE_UNITS[parameter_unit(n)]
        rows.append([n, unit, num(p["bias"] * k, 3), num(p["empirical_std"] * k),
                     num(p["crb_std"] * k), num(p["crb_white_std"] * k),
                     num(p["sandwich_std"] * k), num(p["reported_std"] * k),
                     f"{p['ratio_emp_to_crb']:.3f}", f"{p['ratio_emp_to_reported']:.3f}",
                     f"{p['normalized_std']:.3f}", f"{p['bias_over_crb']:.3f}"])
    sec.table(["parameter", "unit", "bias", "empirical std", "CRB", "CRB white", "sandwich",
               "reported", "emp/CRB", "emp/reported", "std(e/CRB)", "|bias|/CRB"], rows, left=2)
    sec.text(f"A std from {res['runs']} runs is known to "
             f"±{res.get('relative_standard_error_of_std', float('nan')):.0%} (one standard "
             f"error). CRB: (JᵀV⁻¹J)⁻¹ with the pose-dependent noise; CRB white: mean(v)(JᵀJ)⁻¹; "
             f"sandwich: the unweighted fit's covariance; std(e/CRB): std of each run's error "
             f"divided by its own run's bound.")
    v = res.get("verdict", {})
    for key, what in (("efficient_within_15pct_of_crb", "spread within 15 % of the CRB"),
                      ("reported_std_within_15pct", "reported std within 15 % of the spread"),
                      ("bias_under_fifth_of_crb", "bias under a fifth of the CRB")):
        d = v.get(key)
        if isinstance(d, dict) and d:
            bad = [n for n, ok in d.items() if not ok]
            sec.finding(f"{what}: " + ("all offsets" if not bad else
                                       f"NOT for {', '.join(bad)}"), ok=not bad)
    sec = page.section("Chi-square")
    fig = fig_chi2(out, res)
    if fig is None:
        sec.note("No chi-square values in the result (too few runs or no identifiable offsets).")
    sec.figure(fig)
    for key, what in CHI2:
        c = res.get(key)
        if isinstance(c, dict):
            sec.finding(f"{what}: mean {c['mean']:.2f} for {c['dof']} dof "
                        f"(±{c['standard_error']:.2f}), KS p {c['ks_pvalue']:.3f}, "
                        f"{c['share_below_chi2_95']:.0%} below the 95 % quantile: "
                        + ("PASS" if c["passes"] else "FAIL"), ok=bool(c["passes"]))
    sl = res.get("slope")
    if isinstance(sl, dict) and sl.get("rows"):
        sec = page.section("Spread against the number of samples")
        sec.figure(fig_slope(out, sl))
    sec = page.section("Runs")
    rj = res.get("rejected_total", {})
    sec.table(["", ""], [
        ["runs completed", res["runs"]],
        ["runs failed", len(res.get("failed_runs", []))],
        ["fits not converged", res.get("not_converged", "–")],
        ["rejected poses (collision, laser, unreachable)",
         f"{rj.get('collision', '–')}, {rj.get('laser', '–')}, {rj.get('unreachable', '–')}"],
        ["not identifiable with every parameter free",
         ", ".join(res.get("not_identifiable_all_free", [])) or "none"]], left=1)
    for f in res.get("failed_runs", []):
        sec.finding(f"run with seed {f['seed']} left out: {f['reason']}")
    return page
