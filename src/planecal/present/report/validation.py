"""Report of a validation on the twin (``validate --out``): ISO 9283 pose accuracy AP and
repeatability RP with the nominal and the calibrated model, the gauge block (seed 9.3) and
the offset error left after calibration.

Figures: the AP vectors per pose (components, nominal vs calibrated), AP and RP per pose,
the gauge-block length error per model, the joint offset error against the truth.
"""
from __future__ import annotations

import numpy as np

from planecal.present.report.figures import (AFTER, BEFORE, display_scale, label, log_ticks,
                                     new_figure, num, save)
from planecal.present.report.inputs import Context
from planecal.present.report.page import Page

MODELS = (("nominal", "nominal model", BEFORE), ("calibrated", "calibrated model", AFTER))


def fig_ap_vectors(out, iso):
    fig, axes = new_figure(11, 4.2, 1, 2)
    poses = [f"P{i + 1}" for i in range(len(iso["points_m"]))]
    x = np.arange(len(poses))
    w = 0.25
    comp_colors = ("#1b9e77", "#d95f02", "#7570b3")
    for ax, (key, what, _) in zip(axes.flat, MODELS):
        v = np.asarray(iso["models"][key]["ap_xyz_mm"], float) * 1e-3  # m
        ap = np.asarray(iso["models"][key]["ap_mm"], float) * 1e-3
        scale, unit = display_scale("m", np.concatenate([v.ravel(), ap]))
        for c in range(3):
            ax.bar(x + (c - 1) * w, v[:, c] * scale, w, color=comp_colors[c],
                   label=f"{'xyz'[c]} (base frame)")
        ax.plot(x, ap * scale, "D", color="black", markersize=5, label="|AP|")
        ax.axhline(0, color="#555", linewidth=0.8)
        ax.set_xticks(x, poses)
        ax.set_xlabel("ISO 9283 pose")
        ax.set_ylabel(f"attained − commanded position [{unit}]")
        ax.set_title(f"{what}: largest AP {ap.max() * scale:.3g} {unit}", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=4)
    fig.suptitle("Pose accuracy vectors (barycentre of the attained positions − commanded)")
    return save(fig, out, "ap_vectors", "AP vectors",
                "The ISO 9283 accuracy vector of each pose, by component in the robot base "
                "frame, with the nominal and the calibrated model (each panel its own scale); "
                "the diamond is its length AP.")


def fig_ap_rp(out, v):
    iso = v["iso"]
    n = len(iso["points_m"])
    x = np.arange(n)
    fig, ax = new_figure(8, 4.4)
    ax = ax[0, 0]
    w = 0.2
    series = [(np.asarray(iso["models"]["nominal"]["ap_mm"]), "AP nominal", BEFORE, None),
              (np.asarray(iso["models"]["calibrated"]["ap_mm"]), "AP calibrated", AFTER, None),
              (np.asarray(iso["models"]["nominal"]["rp_mm"]), "RP nominal", BEFORE, "//"),
              (np.asarray(iso["models"]["calibrated"]["rp_mm"]), "RP calibrated", AFTER, "//")]
    for k, (y, what, color, hatch) in enumerate(series):
        ax.bar(x + (k - 1.5) * w, y, w, label=what, color="white" if hatch else color,
               edgecolor=color, hatch=hatch)
    pr = v.get("predicted_from_fit")
    if isinstance(pr, dict) and pr.get("tcp_position_rms_mm") is not None:
        ax.plot(x - 0.5 * w, np.asarray(pr["tcp_position_rms_mm"]), "_", color="black",
                markersize=18, markeredgewidth=2,
                label="predicted by the fit's covariance (1σ)")
    ax.set_yscale("log")
    ax.set_xticks(x, [f"P{i + 1}" for i in range(n)])
    ax.set_xlabel("ISO 9283 pose")
    ax.set_ylabel("AP, RP [mm]")
    lo = min(float(np.min(s[0][s[0] > 0])) for s in series)
    hi = max(float(np.max(s[0])) for s in series)
    ax.set_ylim(lo / 1.5, hi * 1.5)
    log_ticks(ax, "y")
    ax.set_title(f"Pose accuracy AP and repeatability RP ({v['settings']['cycles']} cycles)",
                 fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "ap_rp", "AP and RP",
                "Pose accuracy AP and pose repeatability RP (l̄ + 3 S_l) per pose, nominal "
                "and calibrated model, on a logarithmic axis.")


def fig_gauge(out, v):
    g = v["gauge"]
    names = list(g["models"])
    nice = {"nominal": "nominal", "calibrated": "calibrated",
            "calibrated_sensor_nominal_offsets": "calibrated sensor,\nnominal offsets"}
    e = np.array([g["models"][n]["error_mm"] for n in names])
    s = np.array([g["models"][n]["error_std_mm"] for n in names])
    scale, unit = display_scale("m", np.concatenate([e, s]) * 1e-3)
    k = scale * 1e-3  # mm -> display unit
    fig, ax = new_figure(7.5, 4)
    ax = ax[0, 0]
    x = np.arange(len(names))
    colors = [BEFORE if n == "nominal" else AFTER if n == "calibrated" else "#9467bd"
              for n in names]
    ax.bar(x, e * k, 0.55, color=colors, yerr=s * k, capsize=6,
           error_kw={"label": f"± std over {g['repeats']} repeats"})
    pr = v.get("predicted_from_fit")
    if isinstance(pr, dict) and "gauge_length_std_mm" in pr and "calibrated" in names:
        i = names.index("calibrated")
        sd = pr["gauge_length_std_mm"] * k
        ax.errorbar([i + 0.36], [0.0], yerr=[sd], fmt="none", ecolor="#777", capsize=5,
                    elinewidth=2.5, label="the fit's predicted ±1σ (around 0)")
    ax.axhline(0, color="#555", linewidth=0.8)
    ax.set_xticks(x, [nice.get(n, n) for n in names])
    ax.set_ylabel(f"length error [{unit}]")
    ax.set_title(f"Gauge block {g['length_m'] * 1e3:.0f} mm: measured − true length", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "gauge", "Gauge block",
                "Length of the gauge block measured with the laser (4 points per face) minus "
                "its true length, with the nominal model, the calibrated model and the "
                "calibrated sensor pose with nominal offsets (the offsets' share).")


def fig_offset_error(out, v):
    t = np.asarray(v["truth_offsets_rad"], float)
    c = np.asarray(v["calibrated_offsets_rad"], float)
    std = (v.get("calibration") or {}).get("offsets_std_rad")
    std = None if std is None else np.array([np.nan if s is None else s for s in std], float)
    err_nom, err_cal = -t, c - t
    scale, unit = display_scale("rad", np.concatenate([err_nom, err_cal]))
    x = np.arange(6)
    fig, ax = new_figure(7.5, 4)
    ax = ax[0, 0]
    ax.bar(x - 0.18, err_nom * scale, 0.36, color=BEFORE, label="nominal (0) − truth")
    ax.bar(x + 0.18, err_cal * scale, 0.36, color=AFTER, label="calibrated − truth")
    if std is not None:
        ok = np.isfinite(std)
        ax.errorbar(x[ok] + 0.18, err_cal[ok] * scale, yerr=3 * std[ok] * scale, fmt="none",
                    ecolor="black", capsize=4, label="± 3 std (the fit's)")
    ax.axhline(0, color="#555", linewidth=0.8)
    ax.set_xticks(x, [label(f"delta{i + 1}") for i in range(6)])
    ax.set_ylabel(f"offset error [{unit}]")
    ax.set_title("Joint offset error against the twin's truth", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "offset_error", "Offset error",
                "Error of each joint offset before (the nominal model: 0) and after "
                "calibration, against the twin's hidden truth. δ1 and δ6 are not "
                "identifiable from plane distances; their error stays.")


def fig_truths(out, truths, world, level):
    seeds = [str(t["truth_seed"]) for t in truths]
    before = np.array([t["ap_before_mm"] for t in truths], float)
    after = np.array([t["ap_after_mm"] for t in truths], float)
    x = np.arange(len(truths))
    fig, ax = new_figure(7.5, 4)
    ax = ax[0, 0]
    ax.bar(x - 0.18, before, 0.36, color=BEFORE, label="AP before (nominal model)")
    ax.bar(x + 0.18, after, 0.36, color=AFTER, label="AP after (calibrated)")
    ax.axhline(float(np.median(after)), color=AFTER, linestyle="--", linewidth=1,
               label=f"median after {np.median(after):.3g} mm")
    ax.set_yscale("log")
    log_ticks(ax, "y")
    ax.set_xticks(x, seeds)
    ax.set_xlabel("truth seed (one world each)")
    ax.set_ylabel("AP, worst of P1..P5 [mm]")
    ax.set_title(f"ISO 9283 AP over {len(truths)} truths, {world} world", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "truths", "AP over truths",
                f"Pose accuracy before and after a calibration at level {level}, one world per "
                "truth seed (logarithmic axis).")


def fig_breakdown(out, bd, level):
    rows = [r for r in bd["variants"] if "failed" not in r]
    names = [r["variant"] for r in rows]
    after = np.array([r["ap_after_mm"] for r in rows], float)
    y = np.arange(len(rows))[::-1]
    fig, ax = new_figure(7.5, 0.5 * len(rows) + 1.5)
    ax = ax[0, 0]
    ax.barh(y, after, 0.6, color=AFTER)
    for yi, a in zip(y, after):
        ax.text(a, yi, f" {a:.3f}", va="center", fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(after.min() / 1.5, after.max() * 1.8)
    log_ticks(ax, "x")
    ax.set_yticks(y, names)
    ax.set_xlabel("AP after calibration [mm] (log)")
    how = "each source alone" if bd["mode"] == "alone" else "each source switched off"
    ax.set_title(f"What each error source leaves (truth {bd['truth_seed']}, {how})",
                 fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    return save(fig, out, "breakdown", "Error sources",
                f"AP after a calibration at level {level} in the truth's world with the error "
                "sources of the profile switched on one at a time (or off in turn); 'none' "
                "is the cell alone.")


def build(ctx: Context) -> Page:
    v = ctx.doc
    out = ctx.out_dir
    iso, g = v["iso"], v["gauge"]
    truths = v.get("truths") or []
    world = v.get("errors", "ideal")
    over = ""
    if len(truths) > 1:
        over = (f"{world} world, {len(truths)} truths: AP after median "
                f"{v['ap_after_median_mm']:.4g} mm, worst {v['ap_after_worst_mm']:.4g} mm. "
                f"The details below are the median truth's (seed {v.get('detail_truth_seed')}): ")
    elif "errors" in v:
        over = f"{world} world: "
    page = Page("Validation on the twin",
                f"Scene {v.get('scene', '?')}, {over}AP {v['ap_before_mm']:.4g} mm before, "
                f"{v['ap_after_mm']:.4g} mm after calibration (×{v['ap_ratio']:.1f} smaller); "
                f"RP {v['rp_mm']:.4g} mm; gauge block error {v['gauge_error_before_mm']:+.4g} "
                f"mm before, {v['gauge_error_after_mm']:+.4g} mm after.")
    if len(truths) > 1:
        sec = page.section("Over the truths")
        sec.figure(fig_truths(out, truths, world, _level(v)))
        sec.table(["truth", "AP before [mm]", "AP after [mm]", "AP after, cell frame [mm]",
                   "RP after [mm]", "gauge after [mm]", "max model error [mm]"],
                  [[str(t["truth_seed"]), num(t["ap_before_mm"]), num(t["ap_after_mm"]),
                    num(t.get("ap_after_cell_mm")), num(t.get("rp_after_mm")),
                    num(t.get("gauge_error_after_mm")), num(t.get("max_model_error_mm"))]
                   for t in truths], left=1)
    bd = v.get("breakdown")
    if bd and bd.get("variants"):
        sec = page.section("What each error source leaves")
        sec.figure(fig_breakdown(out, bd, _level(v)))
        cr = bd.get("cannot_remove") or []
        if cr:
            sec.table(["source", "what", "AP after with it [mm]", "its share [mm]"],
                      [[c["source"], c["what"], num(c["ap_after_variant_mm"]),
                        num(c["ap_after_share_mm"])] for c in cr], left=2)
            sec.text(f"A calibration at level {_level(v)} cannot remove these: none is in the fit's "
                     "model; the offsets absorb only the part that looks like a joint zero "
                     "in the calibrated region. See docs/ERRORS.md.")
    sec = page.section("ISO 9283 pose accuracy and repeatability")
    sec.text(f"Cube edge {iso['edge_m'] * 1e3:.0f} mm centred at "
             f"{', '.join(f'{c:.3f}' for c in iso['center_m'])} m (base frame), "
             f"{v['settings']['cycles']} cycles; TCP "
             f"{', '.join(f'{c * 1e3:g}' for c in v['settings']['tcp_m'])} mm in the flange frame.")
    sec.figure(fig_ap_vectors(out, iso))
    sec.figure(fig_ap_rp(out, v))
    rows = []
    nb, ca = iso["models"]["nominal"], iso["models"]["calibrated"]
    for i, p in enumerate(iso["points_m"]):
        rows.append([f"P{i + 1}", " ".join(f"{c:.3f}" for c in p), num(nb["ap_mm"][i]),
                     num(ca["ap_mm"][i]), num(nb["rp_mm"][i]), num(ca["rp_mm"][i])])
    sec.table(["pose", "position [m]", "AP nominal [mm]", "AP calibrated [mm]",
               "RP nominal [mm]", "RP calibrated [mm]"], rows, left=2)
    sec = page.section("Gauge block")
    sec.figure(fig_gauge(out, v))
    sec.table(["model", "length error [mm]", "std [mm]", "max |error| [mm]"],
              [[n, f"{m['error_mm']:+.4f}", f"{m['error_std_mm']:.4f}",
                f"{m['max_abs_error_mm']:.4f}"] for n, m in g["models"].items()], left=1)
    sec.text(f"Largest angle of incidence on a face: {g['max_incidence_deg']:.0f} deg.")
    sec = page.section("Offsets")
    if "truth_offsets_rad" in v and "calibrated_offsets_rad" in v:
        sec.figure(fig_offset_error(out, v))
    r = v.get("residual_offset_error") or {}
    if r:
        sec.text(f"δ1 (a turn of the plates about the base axis) leaves up to "
                 f"{r.get('delta1_share_mm', float('nan')):.3f} mm at the ISO poses; δ6 (a roll "
                 f"of the sensor) {r.get('delta6_share_mm', float('nan')):.3f} mm at the TCP.")
    cal = v.get("calibration") or {}
    if cal:
        sec.text(f"Calibration on the twin: {cal.get('samples', '?')} samples, fit RMS "
                 f"{cal.get('fit_rms_mm', float('nan')) * 1e3:.3g} µm.")
    return page


def _level(doc: dict) -> str:
    """The calibration's level as the validation result records it."""
    return (doc.get("level") or "offsets") + (" + compliance" if doc.get("compliance") else "")
