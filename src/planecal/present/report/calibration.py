"""Report of a calibration result (``calibrate --out``, ``demo``'s result.json).

Figures: the seed's four graphs (7.3.2: the distance distribution of the data set, the
convergence of the model error per iteration, the model error distribution with the
initial and with the new parameters), the model error per sample before and after by
plate, the joint offsets with their std, the scaled singular values of the Jacobian and
the correlation matrix. Tables: the parameters with std and correction; the
identifiability findings as text.

The result file holds the parameters, not the samples: the per-sample figures recompute
the model error with ``planecal.model.measurement.predict`` from the initial and final
parameters on the samples given (or recorded in the result's provenance), with their
approach directions (level 3's backlash), and show them only when the recomputed RMS
reproduces the file's ``residual_rms_mm`` and ``residual_rms_initial_mm`` (so a wrong
sample file or wrong initial values are said, not drawn).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.present.calibration import MODEL_ERROR, findings, parameter_rows
from planecal.present.calibration import label as result_label
from planecal.present.report.figures import (AFTER, BEFORE, COLORS, TABLE_UNITS, display_scale, label,
                                     integer_y, log_ticks, new_figure, num, save)
from planecal.present.report.inputs import Context, load_scene_for, recorded_inputs
from planecal.present.report.page import Page

# the recomputed RMS must match the file's to this (relative; the fit's own last step
# below the improvement limit is far smaller)
RMS_MATCH = 1e-3
ANNOTATE_ALL_MAX, STRONG = 20, 0.9  # all correlations shown up to 20 parameters, beyond |rho|>=0.9


def _fmt(v: float | None, scale: float = 1.0, digits: int = 4) -> str:
    return num(None if v is None else v * scale, digits)


# ----- the inputs the per-sample figures need ---------------------------------------------------

def _samples(ctx: Context, notes: list[str]):
    from planecal.io.samples import Samples, read_many
    if isinstance(ctx.samples, Samples):
        return ctx.samples
    paths = [Path(p) for p in ctx.samples] if ctx.samples else []
    if not paths:
        paths, why = recorded_inputs(ctx, "samples")
        notes.extend(why)
    if not paths:
        notes.append("no sample file given (planecal report RESULT.json --samples RUN.tsv ...) "
                     "and none recorded in the result: the distance and model-error figures "
                     "need the samples")
        return None
    s = read_many([str(p) for p in paths])
    for p in paths:
        ctx.record("samples", p)
    return s


def _initial(ctx: Context, scene, n_planes: int, notes: list[str]):
    """The fit's initial parameters and where they come from."""
    from planecal.io.params import load_params, params_from_dict
    from planecal.model.scene import nominal_params
    doc = ctx.doc
    if isinstance(doc.get("initial"), dict):
        return params_from_dict(doc["initial"], "result: initial"), "the result's 'initial'"
    paths, why = recorded_inputs(ctx, "initial")
    notes.extend(why)
    if paths:
        ctx.record("initial", paths[0])
        return load_params(paths[0]), str(paths[0])
    if scene is not None and len(scene.plates) == n_planes:
        return nominal_params(scene), f"the nominal values of scene {scene.name}"
    return None, None


def _rms_mm(r, used) -> float:
    return float(np.sqrt(np.mean(r[used] ** 2)) * 1e3)


def _matches(rms: float, want) -> bool:
    return isinstance(want, (int, float)) and abs(rms - want) <= RMS_MATCH * max(abs(want), 1e-9)


# ----- figures ---------------------------------------------------------------------------------

def _plate_names(scene, n_planes: int) -> list[str]:
    if scene is not None and len(scene.plates) == n_planes:
        return [p.name for p in scene.plates]
    return [f"plate {k + 1}" for k in range(n_planes)]


def _hist_labels(plates):
    return plates if len(plates) > 1 else ["samples"]


def fig_distances(out, s, plates, scene):
    d = s.d_mm
    fig, ax = new_figure(7, 4)
    ax = ax[0, 0]
    edges = np.histogram_bin_edges(d, bins="auto")
    groups = [d[s.plate == k] for k in range(len(plates))]
    ax.hist(groups, bins=edges, stacked=True, label=_hist_labels(plates),
            color=COLORS[:len(plates)], edgecolor="white", linewidth=0.5)
    if scene is not None:
        for i, x in enumerate(scene.laser_range_mm):
            ax.axvline(x, color="#555", linestyle="--", linewidth=1,
                       label="laser window" if i == 0 else None)
        ax.set_xlim(min(scene.laser_range_mm[0], edges[0]) - 1,
                    max(scene.laser_range_mm[1], edges[-1]) + 1)
    ax.set_xlabel("measured distance [mm]")
    ax.set_ylabel("samples")
    integer_y(ax)
    ax.set_title(f"Distance distribution of the data set ({len(d)} samples)")
    if len(plates) > 1 or scene is not None:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "distances", "Distances",
                "The laser distances of the samples (seed 7.3.2, first graph)"
                + ("; dashed: the scene's laser window." if scene is not None else "."))


def fig_convergence(out, history):
    it = np.array([h["iteration"] for h in history])
    rms = np.array([h["rms_m"] for h in history]) * 1e3
    mx = np.array([h["max_m"] for h in history]) * 1e3
    fig, ax = new_figure(7, 4)
    ax = ax[0, 0]
    ax.semilogy(it, mx, "o-", color=BEFORE, label="max |model error|")
    ax.semilogy(it, rms, "s-", color=AFTER, label="RMS model error")
    ax.set_xlabel("iteration")
    ax.set_ylabel("model error [mm]")
    ax.set_xticks(it)
    log_ticks(ax, "y")
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Convergence of the model error")
    ax.legend(loc="upper right")
    return save(fig, out, "convergence", "Convergence",
                "Maximum absolute and RMS model error over the samples used, per iteration "
                "(seed 7.3.2, second graph); logarithmic axis, iteration 0 is the initial model.")


def _error_hist(ax, r_m, s, used, plates, scale, unit):
    v = r_m * scale
    edges = np.histogram_bin_edges(v[used], bins="auto")
    groups = [v[used & (s.plate == k)] for k in range(len(plates))]
    ax.hist(groups, bins=edges, stacked=True, label=_hist_labels(plates), color=COLORS[:len(plates)],
            edgecolor="white", linewidth=0.5)
    ax.set_xlabel(f"model error (model − measured) [{unit}]")
    ax.set_ylabel("samples")
    integer_y(ax)
    return edges


def fig_error_hist(out, name, r_m, s, used, plates, title, caption, sigma_m=None):
    scale, unit = display_scale("m", r_m[used])
    fig, ax = new_figure(7, 4)
    ax = ax[0, 0]
    edges = _error_hist(ax, r_m, s, used, plates, scale, unit)
    if sigma_m:
        from scipy import stats
        x = np.linspace(edges[0], edges[-1], 300)
        w = edges[1] - edges[0]
        sg = sigma_m * scale
        ax.plot(x, used.sum() * w * stats.norm.pdf(x, 0.0, sg), color="black", linewidth=1.2,
                label=f"normal, σ = {sg:.3g} {unit} (the fit's)")
    ax.set_title(title)
    if len(plates) > 1 or sigma_m:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, name, title, caption)


def fig_error_per_sample(out, r0, r1, s, used, plates):
    idx = np.arange(len(r1))
    fig, axes = new_figure(9, 6, 2, 1, sharex=True)
    for ax, r, what in ((axes[0, 0], r0, "initial parameters"),
                        (axes[1, 0], r1, "calibrated parameters")):
        scale, unit = display_scale("m", r[used])
        for k, name in enumerate(plates):
            m = used & (s.plate == k)
            ax.plot(idx[m], r[m] * scale, "o", markersize=3.5, color=COLORS[k % len(COLORS)],
                    label=name)
        if (~used).any():
            # the scale is the used samples'; an outlier beyond it is drawn at the edge as
            # an arrowhead pointing the way it lies
            lim = np.max(np.abs(r[used] * scale)) * 1.3
            v = r[~used] * scale
            inside = np.abs(v) <= lim
            ax.plot(idx[~used][inside], v[inside], "x", color="black", markersize=6,
                    label="outlier (not used)")
            for sign, mk in ((1, "^"), (-1, "v")):
                off = sign * v > lim
                if off.any():
                    ax.plot(idx[~used][off], np.full(off.sum(), sign * lim * 0.96), mk,
                            color="black", markersize=6, label="outlier off scale")
            ax.set_ylim(-lim, lim)
        ax.axhline(0, color="#555", linewidth=0.8)
        ax.set_ylabel(f"model error [{unit}]")
        ax.set_title(f"With the {what}: RMS {_rms_mm(r, used) * 1e-3 * scale:.3g} {unit}")
        ax.grid(True, alpha=0.3)
    axes[1, 0].set_xlabel("sample (order in the sample files)")
    if len(plates) > 1 or (~used).any():
        seen = {}
        for ax in axes.flat:
            for h, lab in zip(*ax.get_legend_handles_labels()):
                seen.setdefault(lab, h)
        fig.legend(list(seen.values()), list(seen), loc="outside right upper", fontsize=8)
    return save(fig, out, "error_per_sample", "Model error per sample",
                "Model error (model − measured distance) of each sample with the initial and "
                "with the calibrated parameters, coloured by plate; the two panels have "
                "their own scale. A trend along the run or a plate apart from the others "
                "points at a model error, not noise.")


def fig_offsets(out, rows, initial, free):
    rows = [r for r in rows if r.name.startswith("delta")]
    names = [r.name for r in rows]
    x = np.arange(len(rows))
    val = np.array([r.value for r in rows])
    std = np.array([np.nan if r.std is None else r.std for r in rows])
    scale, unit = display_scale("rad", np.concatenate([val, std[np.isfinite(std)]]))
    fig, ax = new_figure(7, 4)
    ax = ax[0, 0]
    fitted = np.array([n in free for n in names])
    ok = fitted & np.isfinite(std)
    ax.errorbar(x[ok], val[ok] * scale, yerr=3 * std[ok] * scale, fmt="o", color=AFTER,
                capsize=5, label="calibrated ± 3 std")
    if (fitted & ~np.isfinite(std)).any():
        m = fitted & ~np.isfinite(std)
        ax.plot(x[m], val[m] * scale, "o", color=BEFORE, label="calibrated, not identifiable")
    if (~fitted).any():
        ax.plot(x[~fitted], val[~fitted] * scale, "o", mfc="white", color="#555",
                label="fixed (not fitted)")
    if initial is not None:
        ax.plot(x, initial.joint_offsets * scale, "D", color="#999", markersize=4,
                label="initial")
    ax.axhline(0, color="#555", linewidth=0.8)
    ax.set_xticks(x, [label(n) for n in names])
    ax.set_xlim(-0.5, 5.5)
    ax.set_ylabel(f"joint offset [{unit}]")
    ax.set_title("Joint offsets")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "offsets", "Joint offsets",
                "Identified joint offsets with ±3 standard deviations (the fit's own "
                "covariance); δ1 and δ6 cannot be told from a turn of the plane and a roll "
                "of the sensor and are fixed by default.")


def fig_singular_values(out, ident):
    s = np.asarray(ident.get("scaled_singular_values") or [], float)
    if s.size == 0:
        return None
    ratio = s / s[0]
    weak = {round(float(w.get("scaled_singular_ratio", -1)), 12)
            for w in ident.get("weak_directions", [])}
    is_weak = np.array([round(float(v), 12) in weak for v in ratio])
    fig, ax = new_figure(7, 4)
    ax = ax[0, 0]
    k = np.arange(1, len(s) + 1)
    ax.semilogy(k, ratio, "-", color="#999", linewidth=0.8)
    ax.semilogy(k[~is_weak], ratio[~is_weak], "o", color=AFTER, label="identifiable")
    if is_weak.any():
        ax.semilogy(k[is_weak], ratio[is_weak], "o", color=BEFORE, label="weakly identifiable")
    ax.set_xticks(k)
    log_ticks(ax, "y")
    ax.set_xlabel("singular value number")
    ax.set_ylabel("scaled singular value / largest")
    cn = ident.get("condition_number_scaled")
    ax.set_title("Singular values of the column-scaled Jacobian"
                 + (f" (condition number {cn:.3g})" if isinstance(cn, (int, float)) else ""))
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="lower left")
    return save(fig, out, "singular_values", "Singular values",
                "Singular values of the Jacobian with unit-norm columns (units do not matter), "
                "relative to the largest: a small one is a combination of parameters the data "
                "barely sees.")


def correlation(cov: dict) -> tuple[list[str], np.ndarray]:
    names = list(cov["names"])
    C = np.array([[np.nan if v is None else float(v) for v in row] for row in cov["matrix"]])
    if C.shape != (len(names), len(names)):
        raise InputError(f"result: covariance: matrix is {C.shape}, names {len(names)}")
    sd = np.sqrt(np.diag(C))
    with np.errstate(invalid="ignore", divide="ignore"):
        R = C / np.outer(sd, sd)
    return names, R


def fig_correlation(out, cov: dict):
    """The correlation matrix; each cell's number up to ``ANNOTATE_ALL_MAX`` parameters,
    the strong pairs' beyond (level 3's 60: 3,600 texts, seconds to draw, unreadable)."""
    from matplotlib.colors import TwoSlopeNorm
    names, R = correlation(cov)
    n = len(names)
    size = min(10.0, max(5.0, 0.5 * n + 2.0))
    fig, ax = new_figure(size + 1.2, size)
    ax = ax[0, 0]
    cmap = __import__("matplotlib").colormaps["RdBu_r"].with_extremes(bad="#dddddd")
    im = ax.imshow(np.ma.masked_invalid(R), cmap=cmap, norm=TwoSlopeNorm(0.0, -1.0, 1.0))
    ax.set_xticks(range(n), [label(x) for x in names])
    ax.set_yticks(range(n), [label(x) for x in names])
    every = n <= ANNOTATE_ALL_MAX
    for i in range(n):
        for j in range(n):
            v = R[i, j]
            if not every and not (i != j and np.isfinite(v) and abs(v) >= STRONG):
                continue
            text = "n/i" if not np.isfinite(v) else f"{v:.2f}".replace("-0.00", "0.00")
            ax.text(j, i, text, ha="center", va="center", fontsize=7 if n > 10 else 8,
                    color="white" if np.isfinite(v) and abs(v) > 0.6 else "black")
    fig.colorbar(im, ax=ax, shrink=0.8, label="correlation coefficient")
    ax.set_title("Correlation of the fitted parameters")
    shown = ("" if every else f" The numbers are shown where |ρ| ≥ {STRONG:g} ({n} "
             "parameters: the others' cells are too small to read); grey: not identifiable.")
    return save(fig, out, "correlation", "Correlation matrix",
                "Correlation coefficients of the free parameters from the fit's covariance; "
                "|ρ| near 1: the data moves the two together. n/i: not identifiable." + shown)


# ----- the page ----------------------------------------------------------------------------------

def build(ctx: Context) -> Page:
    """The page: the model error (the seed's graphs and the per-sample errors), the
    parameters, the identifiability."""
    from planecal.io.params import params_from_dict

    doc = ctx.doc
    where = str(ctx.source) if ctx.source else "result"
    final = params_from_dict(doc, where)
    n_planes = final.n_planes
    rows = parameter_rows(doc)
    free = list(doc.get("free") or [])
    page = Page("Calibration report", _subtitle(ctx, doc))
    notes: list[str] = []
    scene = load_scene_for(ctx, notes)
    if scene is not None and len(scene.plates) != n_planes:
        notes.append(f"scene {scene.name} has {len(scene.plates)} plate(s), the result "
                     f"{n_planes}: the scene's plate names and nominal values are not used")
    samples = _samples(ctx, notes)
    initial, initial_from = _initial(ctx, scene, n_planes, notes)
    plates = _plate_names(scene, n_planes)
    _model_error_section(page.section("Model error (seed 7.3.2)"), ctx, scene, samples,
                         plates, final, initial, initial_from, notes)
    _parameters_section(page.section("Parameters"), ctx, rows, free, initial, initial_from)
    _identifiability_section(page.section("Identifiability"), ctx)
    return page


def _subtitle(ctx: Context, doc: dict) -> str:
    return (f"{ctx.source.name if ctx.source else 'calibration result'} (level "
            f"{result_label(doc)}): "
            f"{doc.get('samples_used', '?')} samples used, model error "
            f"({MODEL_ERROR}) RMS "
            f"{_fmt(doc.get('residual_rms_initial_mm'))} mm before, "
            f"{_fmt(doc.get('residual_rms_mm'))} mm after; "
            f"{doc.get('iterations', '?')} iterations"
            + ("" if doc.get("converged", True) else " (NOT converged)") + ".")


def _identifiability(doc: dict) -> dict:
    return doc.get("identifiability") if isinstance(doc.get("identifiability"), dict) else {}


def _model_errors(doc: dict, scene, samples, final, initial, initial_from,
                  notes: list[str]):
    """The model error per sample with the calibrated and with the initial parameters
    and the samples used: (r0, r1, used), r0 or r1 None where the recomputed RMS does not
    reproduce the file's (said in ``notes``), all None without samples and scene."""
    from planecal.model.measurement import predict
    r0 = r1 = used = None
    if samples is None or scene is None:
        return r0, r1, used
    n_planes = final.n_planes
    if samples.plate.max() >= n_planes:
        notes.append(f"the samples refer to plate {samples.plate.max() + 1}, the result "
                     f"has {n_planes} plane(s): not this result's samples")
        return r0, r1, used
    used = np.ones(len(samples), bool)
    outl = [int(i) for i in doc.get("outliers", []) if 0 <= int(i) < len(samples)]
    used[outl] = False
    # the approach directions: level 3's backlash flanks (without: 0.034 mm for 0.010)
    r1 = predict(scene.robot, samples.qe, final, samples.plate,
                 samples.direction) - samples.d_mm * 1e-3
    rms1 = _rms_mm(r1, used)
    if not _matches(rms1, doc.get("residual_rms_mm")):
        notes.append(f"with these samples the calibrated model's RMS error is "
                     f"{rms1:.6g} mm, the result says {doc.get('residual_rms_mm')} mm: "
                     f"they are not the samples of this result; no model-error figures")
        r1 = None
    elif initial is not None:
        r0 = predict(scene.robot, samples.qe, initial, samples.plate,
                     samples.direction) - samples.d_mm * 1e-3
        rms0 = _rms_mm(r0, used)
        if not _matches(rms0, doc.get("residual_rms_initial_mm")):
            notes.append(f"the initial parameters taken ({initial_from}) give an RMS "
                         f"error of {rms0:.6g} mm, the result says "
                         f"{doc.get('residual_rms_initial_mm')} mm: the fit started "
                         f"elsewhere (give the result's initial file); no 'before' "
                         f"figures")
            r0 = None
    else:
        notes.append("the result does not record its initial parameters and the scene "
                     "cannot supply them: no 'before' figures")
    return r0, r1, used


def _model_error_section(sec, ctx: Context, scene, samples, plates, final, initial,
                         initial_from, notes: list[str]) -> None:
    """The seed's graphs and the per-sample errors, then every note gathered so far."""
    doc, out = ctx.doc, ctx.out_dir
    r0, r1, used = _model_errors(doc, scene, samples, final, initial, initial_from, notes)
    if samples is not None:
        sec.figure(fig_distances(out, samples, plates, scene))
    history = doc.get("history")
    if isinstance(history, list) and history:
        sec.figure(fig_convergence(out, history))
    else:
        sec.note("The convergence graph needs the fit's iteration history, which this result "
                 "file does not hold (key 'history').")
    if r0 is not None:
        sec.figure(fig_error_hist(
            out, "error_before", r0, samples, used, plates,
            "Model error with the initial parameters",
            f"Distribution of the model error with the initial parameters ({initial_from}; "
            f"seed 7.3.2, third graph); outliers left out."))
    if r1 is not None:
        sig = _identifiability(doc).get("sigma_mm")
        sec.figure(fig_error_hist(
            out, "error_after", r1, samples, used, plates,
            "Model error with the calibrated parameters",
            "Distribution of the model error with the new parameters (seed 7.3.2, fourth "
            "graph); outliers left out; the curve is the normal density with the fit's "
            "sigma.", None if sig is None else sig * 1e-3))
        if r0 is not None:
            sec.figure(fig_error_per_sample(out, r0, r1, samples, used, plates))
    for n in notes:
        sec.note(n)


def _parameters_section(sec, ctx: Context, rows, free, initial, initial_from) -> None:
    """The joint offsets' figure, the parameter table and the correlation matrix."""
    doc, out = ctx.doc, ctx.out_dir
    sec.figure(fig_offsets(out, rows, initial, free))
    x0 = {r.name: r.value for r in parameter_rows(_as_doc(initial))} \
        if initial is not None else {}
    table = []
    for r in rows:
        scale, dunit = TABLE_UNITS[r.unit]
        x_init = r.initial if r.initial is not None else x0.get(r.name)
        corr = None if x_init is None else r.value - x_init
        sd = r.std
        ratio = "–" if corr is None or sd is None or sd == 0 else f"{abs(corr) / sd:.3g}"
        table.append([r.name, f"{r.value:.7g}", r.unit, _fmt(sd, scale), _fmt(corr, scale),
                      dunit, ratio, "" if r.status == "fitted" else r.status])
    sec.table(["parameter", "value", "unit", "std", "correction", "unit (std, correction)",
               "|correction| / std", ""], table, left=1)
    sec.text("std: the fit's standard deviation (null in the file where a parameter is fixed "
             "or not identifiable); correction: calibrated − initial"
             + (f" ({initial_from})." if initial_from else " (initial values unknown)."))
    cov = doc.get("covariance")
    if isinstance(cov, dict) and cov.get("names") and cov.get("matrix") is not None:
        sec.figure(fig_correlation(out, cov))
    else:
        sec.note("No correlation matrix: this result file holds no covariance "
                 "(key 'covariance': {\"names\": [...], \"matrix\": [[...]]}).")


def _identifiability_section(sec, ctx: Context) -> None:
    """The identifiability findings, the scaled singular values and the fit's summary."""
    doc, out = ctx.doc, ctx.out_dir
    ident = _identifiability(doc)
    lines = [(f.text, f.warning) for f in findings(doc)]
    if not ident:
        sec.note("The result file holds no identifiability report.")
    warned = False
    for text, warn in lines:
        if warn:
            warned = True
            sec.finding(text)
        else:
            sec.text(text)
    if ident and not warned:
        sec.finding("No unidentifiable or weakly identifiable parameters.", ok=True)
    sec.figure(fig_singular_values(out, ident))
    summary = [["samples used", doc.get("samples_used", "–")],
               ["outliers", ", ".join(str(i) for i in doc.get("outliers", [])) or "none"],
               ["iterations", f"{doc.get('iterations', '–')}"
                + ("" if doc.get("converged", True) else " (not converged)")],
               ["residual RMS before [mm]", _fmt(doc.get("residual_rms_initial_mm"), digits=6)],
               ["residual RMS after [mm]", _fmt(doc.get("residual_rms_mm"), digits=6)],
               ["largest |residual| after [mm]", _fmt(doc.get("residual_max_mm"), digits=6)]]
    sec.table(["", ""], summary, left=1)


def _as_doc(p) -> dict:
    from planecal.io.params import params_to_dict
    return params_to_dict(p)
