"""Report of a validation on the twin (``validate --out``): ISO 9283 pose accuracy AP and
repeatability RP at the tool point of the nominal model, each calibrated level, each
level's floor and the twin's own true model (the oracle), in the near-sample cube and the
standard's, with the flange's beside, the gauge block (seed 9.3) and the offset error left
after calibration.

Figures: AP over the truths, the AP vectors per pose (components), AP and RP per pose,
the gauge-block length error per model, the joint offset error against the truth, and
what each error source leaves.
"""
from __future__ import annotations

import numpy as np

from planecal.present.report.figures import (AFTER, BEFORE, display_scale, label, log_ticks,
                                     new_figure, num, save)
from planecal.present.report.inputs import Context
from planecal.present.report.page import Page
from planecal.present.validation import CELL, FLOOR, ORACLE, ROBOT_FRAME, change
from planecal.studies.validation.truths import noise_share

GREEN = "#2ca02c"  # the twin's own true model
LEVEL_COLORS = ("#9ecae1", "#6baed6", AFTER)  # lower levels lighter, the validated one AFTER


def models_of(v: dict) -> list[tuple[str, str, str]]:
    """(key in iso.models, label, colour) of every model that commanded, in order: the
    nominal model, each level (the validated one last), the oracle."""
    levels = [r["level"] for r in v["levels"]]
    colors = LEVEL_COLORS[-len(levels):] if len(levels) <= 3 else \
        [LEVEL_COLORS[0]] * (len(levels) - 1) + [AFTER]
    return ([("nominal", "nominal model", BEFORE)]
            + [(lv, f"calibrated ({lv})", c) for lv, c in zip(levels, colors)]
            + [("oracle", "the twin's whole true model (oracle)", GREEN)])


def fig_ap_vectors(out, v):
    iso = v["iso"]
    shown = [m for m in models_of(v) if m[0] in ("nominal", v["model_after"], "oracle")]
    fig, axes = new_figure(15, 4.2, 1, len(shown))
    poses = [f"P{i + 1}" for i in range(len(iso["points_m"]))]
    x = np.arange(len(poses))
    w = 0.25
    comp_colors = ("#1b9e77", "#d95f02", "#7570b3")
    for ax, (key, what, _) in zip(axes.flat, shown):
        v_ = np.asarray(iso["models"][key]["tool"]["ap_xyz_mm"], float) * 1e-3  # m
        ap = np.asarray(iso["models"][key]["tool"]["ap_mm"], float) * 1e-3
        scale, unit = display_scale("m", np.concatenate([v_.ravel(), ap]))
        for c in range(3):
            ax.bar(x + (c - 1) * w, v_[:, c] * scale, w, color=comp_colors[c],
                   label=f"{'xyz'[c]} (robot frame)")
        ax.plot(x, ap * scale, "D", color="black", markersize=5, label="|AP|")
        ax.axhline(0, color="#555", linewidth=0.8)
        ax.set_xticks(x, poses)
        ax.set_xlabel("ISO 9283 pose")
        ax.set_ylabel(f"attained − commanded tool point [{unit}]")
        ax.set_title(f"{what}: largest AP {ap.max() * scale:.3g} {unit}", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=4)
    fig.suptitle("Pose accuracy vectors at the tool point (barycentre of the attained "
                 "positions − commanded)")
    return save(fig, out, "ap_vectors", "AP vectors",
                "The ISO 9283 accuracy vector of each pose at the tool point (the laser's beam "
                "point at its measuring centre), by component in the robot's frame, with the "
                "nominal model, the validated calibration and the twin's own true model (each "
                "panel its own scale); the diamond is its length AP.")


def fig_ap_rp(out, v):
    iso = v["iso"]
    n = len(iso["points_m"])
    x = np.arange(n)
    fig, ax = new_figure(9, 4.6)
    ax = ax[0, 0]
    models = models_of(v)
    w = 0.8 / (len(models) + 1)
    series = [np.asarray(iso["models"][k]["tool"]["ap_mm"], float) for k, _, _ in models]
    for k, ((_, what, color), y) in enumerate(zip(models, series)):
        ax.bar(x + (k - len(models) / 2) * w, y, w, label=f"AP, {what}", color=color)
    after = v["model_after"]
    rp = np.asarray(iso["models"][after]["tool"]["rp_mm"], float)
    ax.bar(x + (len(models) - len(models) / 2) * w, rp, w, color="white", edgecolor=AFTER,
           hatch="//", label=f"RP, calibrated ({after})")
    flange = np.asarray(iso["models"][after]["flange"]["ap_mm"], float)
    ax.plot(x, flange, "v", color="black", markersize=7,
            label=f"AP at the flange, calibrated ({after})")
    pr = v.get("predicted_from_fit")
    if isinstance(pr, dict) and pr.get("tcp_position_rms_mm") is not None:
        ax.plot(x, np.asarray(pr["tcp_position_rms_mm"]), "_", color="#555",
                markersize=18, markeredgewidth=2,
                label="predicted by the fit's covariance (1σ)")
    ax.set_yscale("log")
    ax.set_xticks(x, [f"P{i + 1}" for i in range(n)])
    ax.set_xlabel("ISO 9283 pose")
    ax.set_ylabel("AP, RP [mm]")
    vals = np.concatenate(series + [rp, flange])
    ax.set_ylim(float(np.min(vals[vals > 0])) / 1.5, float(np.max(vals)) * 1.5)
    log_ticks(ax, "y")
    ax.set_title(f"AP and RP at the tool point, robot frame ({v['settings']['cycles']} "
                 "cycles)", fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "ap_rp", "AP and RP",
                "Pose accuracy AP at the tool point per pose for every model on the same poses "
                "(the oracle is the twin's whole true model, backlash by the approach "
                "direction: what repeatability and whole counts leave), the validated "
                "calibration's RP (l̄ + 3 S_l) and its AP "
                "at the flange (triangles), on a logarithmic axis.")


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


def fig_truths(out, v, world, level):
    truths = v["truths"]
    seeds = [str(t["truth_seed"]) for t in truths]
    models = models_of(v)
    series = [[t["ap_before_tool_mm"] for t in truths]]
    series += [[t["levels"][k]["ap_after_tool_mm"] for t in truths]
               for k in range(len(models) - 2)]
    series += [[t["ap_oracle_tool_mm"] for t in truths]]
    x = np.arange(len(truths))
    fig, ax = new_figure(9, 4.4)
    ax = ax[0, 0]
    w = 0.8 / len(models)
    for k, ((_, what, color), y) in enumerate(zip(models, series)):
        ax.bar(x + (k - (len(models) - 1) / 2) * w, np.asarray(y, float), w, color=color,
               label=what)
    flange = np.array([t["ap_after_flange_mm"] for t in truths], float)
    ax.plot(x, flange, "v", color="black", markersize=7,
            label=f"calibrated ({level}) at the flange")
    for key, mark, what in (("ap_floor_tool_mm", "_", f"its level's floor ({level})"),
                            ("ap_after_tool_standard_mm", "s",
                             f"calibrated ({level}) in the standard's cube")):
        y = np.array([np.nan if t.get(key) is None else t[key] for t in truths], float)
        if np.isfinite(y).any():
            ax.plot(x + (len(models) - 3) / 2 * w, y, mark, color=AFTER, markersize=12
                    if mark == "_" else 5, markeredgewidth=2, fillstyle="none", label=what)
    pred = [(k, t["predicted_tool_mm"], t.get("predicted_band_mm")) for k, t in
            enumerate(truths) if t.get("predicted_tool_mm") is not None]
    if pred:  # what the calibration said of itself before the validation
        xk = x[[k for k, _, _ in pred]] + (len(models) - 3) / 2 * w
        y = np.array([p for _, p, _ in pred], float)
        band = [b for _, _, b in pred]
        err = (np.array([[p - b[0], b[1] - p] for (_, p, _), b in zip(pred, band)]).T
               if all(band) else None)
        ax.errorbar(xk, y, yerr=err, fmt="o", color="dimgray", markersize=5, capsize=3,
                    label=f"calibrated ({level}): its own estimate"
                    + (", 10-90 % of one calibration" if err is not None else ""))
    med = float(np.median(series[-2]))
    ax.axhline(med, color=AFTER, linestyle="--", linewidth=1,
               label=f"median, calibrated ({level}): {med:.3g} mm")
    ax.set_yscale("log")
    log_ticks(ax, "y")
    ax.set_xticks(x, seeds)
    ax.set_xlabel("truth seed (one world each)")
    ax.set_ylabel("AP at the tool point, worst of P1..P5 [mm]")
    ax.set_title(f"ISO 9283 AP over {len(truths)} truths, {world} world, robot frame",
                 fontsize=10)
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=8)
    return save(fig, out, "truths", "AP over truths",
                f"Pose accuracy at the tool point of the nominal model, the calibration at "
                f"level {level} and each level below it, and the twin's own whole true model, "
                "on the same poses of the near-sample cube, one world per truth seed; "
                f"dashes: the validated level's floor ({FLOOR}); squares: the validated "
                "calibration in the standard's cube; triangles: the "
                "validated calibration's AP at the flange; grey points: what that "
                "calibration predicted of its own tool-point error before the validation "
                "(rms over its samples' poses), with the band one calibration's error falls "
                "in 10-90 % of the time (logarithmic axis).")


def fig_breakdown(out, bd, level):
    rows = [r for r in bd["variants"] if "failed" not in r]
    names = [r["variant"] for r in rows]
    after = np.array([r["ap_after_tool_mm"] for r in rows], float)
    oracle = np.array([r["ap_oracle_tool_mm"] for r in rows], float)
    y = np.arange(len(rows))[::-1]
    fig, ax = new_figure(7.5, 0.5 * len(rows) + 1.5)
    ax = ax[0, 0]
    ax.barh(y, after, 0.6, color=AFTER, label=f"calibrated ({level})")
    ax.plot(oracle, y, "|", color=GREEN, markersize=14, markeredgewidth=3,
            label="the twin's whole true model (oracle)")
    floor = np.array([np.nan if r.get("ap_floor_tool_mm") is None else r["ap_floor_tool_mm"]
                      for r in rows], float)
    if np.isfinite(floor).any():
        ax.plot(floor, y, "|", color="black", markersize=14, markeredgewidth=2,
                label=f"the level's floor ({level})")
    for yi, a in zip(y, after):
        ax.text(a, yi, f" {a:.3f}", va="center", fontsize=8)
    ax.set_xscale("log")
    ax.set_xlim(min(after.min(), oracle.min()) / 1.5, after.max() * 1.8)
    ax.legend(loc="lower right", fontsize=8)
    log_ticks(ax, "x")
    ax.set_yticks(y, names)
    ax.set_xlabel("AP at the tool point, robot frame [mm] (log)")
    how = "each source alone" if bd["mode"] == "alone" else "each source switched off"
    ax.set_title(f"What each error source leaves (truth {bd['truth_seed']}, {how})",
                 fontsize=10)
    ax.grid(True, axis="x", alpha=0.3)
    return save(fig, out, "breakdown", "Error sources",
                f"AP at the tool point after a calibration at level {level} in the truth's "
                "world without the noise (the same poses rehearsed noise-free) and with the "
                "error sources of the profile switched on one at a time (or off in turn), "
                "the level's floor and what the twin's whole true model leaves there; "
                "'none' is the cell alone.")


def build(ctx: Context) -> Page:
    v = ctx.doc
    out = ctx.out_dir
    iso, g = v["iso"], v["gauge"]
    truths = v.get("truths") or []
    world = v.get("errors", "ideal")
    after = v["model_after"]
    over = ""
    if len(truths) > 1:
        over = (f"{world} world, {len(truths)} truths: AP at the tool point after calibration "
                f"median {v['ap_after_tool_median_mm']:.4g} mm, worst "
                f"{v['ap_after_tool_worst_mm']:.4g} mm; the twin's own true model median "
                f"{v['ap_oracle_tool_median_mm']:.4g} mm. The details below are the median "
                f"truth's (seed {v.get('detail_truth_seed')}): ")
    elif "errors" in v:
        over = f"{world} world: "
    gauge = ("" if g is None else f"; gauge block error {v['gauge_error_before_mm']:+.4g} mm "
             f"before, {v['gauge_error_after_mm']:+.4g} mm after")
    page = Page("Validation on the twin",
                f"Scene {v.get('scene', '?')}, {over}AP at the tool point (the laser's beam "
                f"point at its {v['standoff_mm']:.0f} mm measuring centre, robot frame) "
                f"{v['ap_before_tool_mm']:.4g} mm before, {v['ap_after_tool_mm']:.4g} mm "
                f"after calibration ({after}; {change(v['ap_before_tool_mm'], v['ap_after_tool_mm'])}), "
                f"{v['ap_oracle_tool_mm']:.4g} mm with the twin's own true model; at the "
                f"flange {v['ap_before_flange_mm']:.4g} -> {v['ap_after_flange_mm']:.4g} mm "
                f"(oracle {v['ap_oracle_flange_mm']:.4g}); RP {v['rp_after_tool_mm']:.4g} mm"
                f"{gauge}.")
    if len(truths) > 1:
        _truths_section(page, out, v, world)
    bd = v.get("breakdown")
    if bd and bd.get("variants"):
        _breakdown_section(page, out, bd, _level(v))
    _iso_section(page, out, v)
    if g is None and v.get("gauge_failed"):
        page.section("Gauge block").text(f"Not measured: {v['gauge_failed']}. The ISO "
                                         "figures above stand without it.")
    if g is not None:
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
                 f"{r.get('delta1_share_mm', float('nan')):.3f} mm at the ISO poses in the "
                 f"cell frame; δ6 (a roll of the sensor, absorbed by its pose at the tool "
                 f"point) {r.get('delta6_share_mm', float('nan')):.3f} mm at the named TCPs.")
    cal = v.get("calibration") or {}
    if cal:
        sec.text(f"Calibration on the twin: {cal.get('samples', '?')} samples, fit RMS "
                 f"{cal.get('fit_rms_mm', float('nan')) * 1e3:.3g} µm.")
    return page


def _breakdown_section(page, out, bd, level) -> None:
    sec = page.section("What each error source leaves")
    sec.figure(fig_breakdown(out, bd, level))
    ns = noise_share(bd)
    if ns is not None:
        sec.text(f"The noise ({ns['what']}): with every source AP after is "
                 f"{ns['with_mm']:.4g} mm, on the same poses rehearsed without it "
                 f"{ns['without_mm']:.4g} mm" + (": it is what limits this calibration; a "
                                                  "richer model does not remove it, more "
                                                  "samples do." if ns["dominates"] else "."))
    cr = bd.get("cannot_remove") or []
    if cr:
        sec.table(["source", "what", "AP at the tool point with it [mm]", "its share [mm]",
                   f"in level {level}'s model"],
                  [[c["source"], c["what"], num(c["ap_after_tool_variant_mm"]),
                    num(c["ap_after_tool_share_mm"]), "yes" if c.get("modelled") else "no"]
                   for c in cr], left=2)
        sec.text("Each source's share without the noise: alone, its world less the cell "
                 "alone; switched off, all but the noise less all but the noise and it. A "
                 "source outside the level's model is absorbed only where it looks like one "
                 "of its parameters in the calibrated region. See docs/ERRORS.md.")


def _truths_section(page, out, v, world) -> None:
    truths = v["truths"]
    sec = page.section("Over the truths")
    sec.figure(fig_truths(out, v, world, _level(v)))
    labels = [r["level"] for r in truths[0]["levels"]]
    sec.table(["truth", "AP nominal [mm]"] + [f"AP {lb} [mm]" for lb in labels]
              + ["floor [mm]", "AP oracle [mm]", "standard cube [mm]",
                 "standard cube floor [mm]", "flange, calibrated [mm]",
                 "cell frame, calibrated [mm]", "RP after [mm]", "gauge after [mm]",
                 "max model error [mm]", "farthest ISO point from a sample, near / standard "
                 "[mm]"],
              [[str(t["truth_seed"]), num(t["ap_before_tool_mm"])]
               + [num(r["ap_after_tool_mm"]) for r in t["levels"]]
               + [num(t.get("ap_floor_tool_mm")), num(t["ap_oracle_tool_mm"]),
                  num(t.get("ap_after_tool_standard_mm")),
                  num(t.get("ap_floor_tool_standard_mm")), num(t["ap_after_flange_mm"]),
                  num(t.get("ap_after_tool_cell_mm")),
                  num(t.get("rp_after_tool_mm")), num(t.get("gauge_error_after_mm")),
                  num(t.get("max_model_error_mm")),
                  " / ".join("-" if t.get(k) is None else f"{max(t[k]):.0f}" for k in
                             ("nearest_sample_mm", "standard_nearest_sample_mm"))]
               for t in truths], left=1)
    sec.text(f"AP at the tool point in the {ROBOT_FRAME}, worst of P1..P5, in the "
             "near-sample cube unless the column says standard cube, flange or cell frame; "
             f"every model on the same poses of each truth. {FLOOR}; {ORACLE}; {CELL}.")


def _iso_section(page, out, v) -> None:
    iso, cube = v["iso"], v["cube"]
    sec = page.section("ISO 9283 pose accuracy and repeatability")
    sec.text(f"The near-sample cube: edge {cube['edge_m'] * 1e3:.0f} mm centred at "
             f"{', '.join(f'{c:.3f}' for c in cube['center_m'])} m (robot frame): "
             f"{cube['rule']}. {v['settings']['cycles']} cycles. Each model commands its own "
             "estimate of the tool point onto the ISO point; the twin's true tool point is "
             "what it attains.")
    sec.figure(fig_ap_vectors(out, v))
    sec.figure(fig_ap_rp(out, v))
    models = models_of(v)
    rows = []
    for i, p in enumerate(iso["points_m"]):
        rows.append([f"P{i + 1}", " ".join(f"{c:.3f}" for c in p),
                     num(cube["nearest_sample_mm"][i], 3)]
                    + [num(iso["models"][k]["tool"]["ap_mm"][i]) for k, _, _ in models]
                    + [num(iso["models"][v["model_after"]]["flange"]["ap_mm"][i]),
                       num(iso["models"][v["model_after"]]["tool"]["rp_mm"][i])])
    sec.table(["pose", "position [m]", "nearest sample [mm]"]
              + [f"AP {k} [mm]" for k, _, _ in models]
              + ["AP flange, calibrated [mm]", "RP calibrated [mm]"], rows, left=2)
    std = v.get("standard_cube")
    if std and std.get("failed"):
        sec.text(f"The standard's cube: not measured: {std['failed']}")
    elif std:
        sec.text(f"The standard's cube: edge {std['edge_m'] * 1e3:.0f} mm centred at "
                 f"{', '.join(f'{c:.3f}' for c in std['center_m'])} m: {std['rule']}; its "
                 f"points {min(std['nearest_sample_mm']):.0f}-"
                 f"{max(std['nearest_sample_mm']):.0f} mm from the nearest sample's tool "
                 "point.")
        siso = v["iso_standard"]
        sec.table(["pose", "position [m]", "nearest sample [mm]"]
                  + [f"AP {k} [mm]" for k, _, _ in models],
                  [[f"P{i + 1}", " ".join(f"{c:.3f}" for c in p),
                    num(std["nearest_sample_mm"][i], 3)]
                   + [num(siso["models"][k]["tool"]["ap_mm"][i]) for k, _, _ in models]
                   for i, p in enumerate(siso["points_m"])], left=2)
    if v.get("tcps"):
        sec.table(["TCP", "in the flange frame [mm]", "AP nominal [mm]", "AP calibrated [mm]",
                   "AP oracle [mm]", "RP calibrated [mm]"],
                  [[t["name"], " ".join(f"{c * 1e3:g}" for c in t["tcp_m"]),
                    num(t["ap_before_tcp_mm"]), num(t["ap_after_tcp_mm"]),
                    num(t["ap_oracle_tcp_mm"]), num(t["rp_after_tcp_mm"])]
                   for t in v["tcps"]], left=2)
        sec.text("A named TCP: the calibration has no better estimate of it than the nominal "
                 "one, so the flange frame's error stays in its AP.")


def _level(doc: dict) -> str:
    """The calibration's level as the validation result records it."""
    return (doc.get("level") or "offsets") + (" + compliance" if doc.get("compliance") else "")
