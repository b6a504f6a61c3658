"""Every text rendering of a validation (``planecal validate``, the demo): one truth, the
truths' table, the breakdown by error source. Every AP says where (the tool point, the
flange, a named TCP), in which cube (the near-sample cube or the standard's) and in which
frame (the robot's, registered on J1's axis and zero, or the cell's)."""
from __future__ import annotations

import numpy as np

from planecal.present.tables import table
from planecal.studies.validation.truths import cannot_remove, noise_share

ROBOT_FRAME = ("robot frame (registered on J1's true axis and zero, as a laser tracker "
               "measuring the robot for ISO 9283 finds it)")
FLOOR = ("floor: the level's own model with the parameters that put the twin's true tool "
         "point best over the samples' poses (noise-free; the best any calibration of that "
         "level can do there)")
ORACLE = ("oracle: the twin's whole true model, backlash by each pose's approach direction "
          "(what repeatability and whole counts leave)")
CELL = ("cell frame: where a program written in the drawing's coordinates lands; it adds "
        "the robot's placement and J1's zero offset delta1, which no plane calibration "
        "sees (the plates move with the robot); work located by the calibrated plates gets "
        "the robot frame's figure")


def change(before: float, after: float) -> str:
    """'x3.2 smaller' or 'x1.4 larger': how AP changed (never 'x0.7 smaller')."""
    if after <= 0 or before <= 0:
        return "unchanged" if after == before else ""
    r = before / after
    return f"x{r:.1f} smaller" if r >= 1 else f"x{1 / r:.1f} larger"


def where_text(v: dict) -> str:
    """Where the tool point is, in words."""
    return (f"the tool point (the laser's beam point at its {v['standoff_mm']:.0f} mm "
            "measuring centre)")


def _mm(x, fmt=".3f"):
    return "-" if x is None else format(x, fmt)


def _span(x) -> str:
    """'23-97' (or '3.3-3.7' below 10) of an array of mm."""
    x = np.asarray(x, float)
    f = ".0f" if x.max() >= 10 else ".1f"
    return f"{x.min():{f}}-{x.max():{f}}"


def _models(v: dict, iso: dict) -> list[tuple[str, str]]:
    """(label, key in iso.models) of every model that commanded, in order."""
    floors = [(f"floor {k}", f["level"]) for k, f in (v.get("floors") or {}).items()]
    return ([("nominal", "nominal")] + [(r["level"], r["level"]) for r in v["levels"]]
            + floors + [("oracle", "oracle")])


def _cube_table(v: dict, iso: dict, cube: dict, what: str) -> list[str]:
    models = _models(v, iso)
    after = v["model_after"]
    rows = []
    for i in range(5):
        p = iso["points_m"][i]
        rows.append([f"P{i + 1}", f"{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}",
                     f"{cube['nearest_sample_mm'][i]:.0f}"]
                    + [f"{iso['models'][k]['tool']['ap_mm'][i]:.4f}" for _, k in models]
                    + [f"{iso['models'][after]['tool']['rp_mm'][i]:.4f}"])
    return [f"{what}: edge {cube['edge_m'] * 1e3:.0f} mm at "
            f"{np.round(np.asarray(cube['center_m']), 3).tolist()} m, its points "
            f"{_span(cube['nearest_sample_mm'])} mm from the nearest sample's tool point",
            table(["pose", "position [m]", "nearest mm"] + [f"AP {m} mm" for m, _ in models]
                  + [f"RP {after} mm"], rows)]


def _ap_line(v: dict, cube: str, what: str) -> str:
    after = v["model_after"]
    b, a = v[f"ap_before_tool{cube}_mm"], v[f"ap_after_tool{cube}_mm"]
    floor = v.get(f"ap_floor_tool{cube}_mm")
    return (f"{what}: before {b:.4f} mm, after ({after}) {a:.4f} mm ({change(b, a)}); "
            + ("" if floor is None else f"its level's floor {floor:.4f} mm; ")
            + f"the twin's whole true model {v[f'ap_oracle_tool{cube}_mm']:.4f} mm; RP after "
              f"{v[f'rp_after_tool{cube}_mm']:.4f} mm")


def format_validation(v: dict) -> str:
    """One validation: per ISO pose the tool point's AP of every model in each cube, then
    the worst pose's at the tool point, the flange and the named TCPs, robot and cell
    frame, and the gauge block."""
    cube = v["cube"]
    how = ("near-sample cube (given edge)" if cube["rule"].startswith("given") else
           "near-sample cube (centred on a calibration sample's tool point)")
    out = [f"ISO 9283 on the twin at {where_text(v)}, AP in the {ROBOT_FRAME}, "
           f"{v['settings']['cycles']} cycles; 'nearest': the ISO point's distance to the "
           "nearest sample's tool point", ""]
    out += _cube_table(v, v["iso"], cube, how)
    if not cube["inside_region"]:
        out.append(f"the given cube reaches {max(cube['outside_region_mm']):.0f} mm / "
                   f"{max(cube['outside_region_deg']):.1f} deg outside the calibrated region")
    std = v.get("standard_cube")
    if std and not std.get("failed"):
        out += [""] + _cube_table(v, v["iso_standard"], std, "the standard's cube (ISO 9283: "
                                  "the largest cube inside the region the work uses, here "
                                  "the samples' flange hull)")
    out += ["", "AP at the tool point (worst pose), robot frame:",
            "  " + _ap_line(v, "", "near-sample cube")]
    if std and std.get("failed"):
        out.append(f"  the standard's cube: not measured: {std['failed']}")
    elif std:
        out.append("  " + _ap_line(v, "_standard", "the standard's cube"))
    out += [f"  ({FLOOR}; {ORACLE})",
            f"AP at the flange, near-sample cube (a plane calibration puts the flange "
            f"frame's error into the sensor pose): before {v['ap_before_flange_mm']:.4f} "
            f"mm, after {v['ap_after_flange_mm']:.4f} mm, true model "
            f"{v['ap_oracle_flange_mm']:.4f} mm", _cell_line(v)]
    for t in v["tcps"]:
        out.append(f"TCP {t['name']} ({', '.join(f'{c * 1e3:g}' for c in t['tcp_m'])} mm in "
                   f"the flange frame; the calibration has no better estimate of it than "
                   f"the nominal one): AP before {t['ap_before_tcp_mm']:.4f} mm, after "
                   f"{t['ap_after_tcp_mm']:.4f} mm, true model {t['ap_oracle_tcp_mm']:.4f} mm")
    out.append("")
    out += _gauge_lines(v)
    return "\n".join(out)


def _cell_line(v: dict) -> str:
    cf = v.get("cell_frame") or {}
    shift = cf.get("shift_mm")
    moved = "" if shift is None else (
        f"; the robot frame itself lies {_span(shift)} mm from the drawing's at these points"
        + ("" if cf.get("delta1_rad") is None else
           f" (delta1 {cf['delta1_rad'] * 1e3:+.2f} mrad and the robot's placement)"))
    return (f"in the cell frame, tool point, near-sample cube: AP before "
            f"{v['ap_before_tool_cell_mm']:.4f} mm, after {v['ap_after_tool_cell_mm']:.4f} mm"
            f"{moved}. The {CELL}.")


def _gauge_lines(v: dict) -> list[str]:
    out = []
    g = v["gauge"]
    if g is not None:
        rows = [[name, f"{m['error_mm']:+.4f}", f"{m['error_std_mm']:.4f}",
                 f"{m['max_abs_error_mm']:.4f}"] for name, m in g["models"].items()]
        out.append(f"gauge block {g['length_m'] * 1e3:.0f} mm, 4 points per face, aimed with "
                   f"the validated model, {g['repeats']} repeats (largest incidence "
                   f"{g['max_incidence_deg']:.0f} deg)")
        out.append(table(["model", "length error mm", "std mm", "max |error| mm"], rows))
    elif v.get("gauge_failed"):
        out.append(f"gauge block: not measured: {v['gauge_failed']} (the ISO figures above "
                   "stand without it)")
    r = v["residual_offset_error"]
    pr = v.get("predicted_from_fit")
    if pr:
        out.append("")
        out.append(f"the fit's covariance predicts (1 sigma): gauge length "
                   f"{pr['gauge_length_std_mm']:.4f} mm (sensor pose and offsets); tool "
                   f"point position error from the offsets at P1..P5 "
                   + " ".join(f"{x:.4f}" for x in pr["tcp_position_rms_mm"]) + " mm (rms)")
    out.append("")
    out.append("offset error left after calibration [urad]: "
               + " ".join(f"{e * 1e6:+.1f}" for e in r["offset_error_rad"]))
    if abs(r["delta1_error_rad"]) > 1e-9 or abs(r["delta6_error_rad"]) > 1e-9:
        out.append(f"delta1 (not identifiable: a turn of the plates about the base axis) leaves up "
                   f"to {r['delta1_share_mm']:.3f} mm at these poses in the cell frame (none in "
                   f"the robot's frame, which J1's zero defines); delta6 (a roll of the sensor, "
                   f"absorbed by its pose at the tool point) leaves "
                   + (f"{r['delta6_share_mm']:.3f} mm at the named TCPs" if v["tcps"]
                      else "nothing there (no other TCP is named)")
                   + ". Neither changes a distance the laser measures, so the gauge length "
                     "does not see them.")
    return out


def _predicted(t: dict) -> str:
    """The calibration's own estimate, its band of AP near the samples and its verdict."""
    p, band = t.get("predicted_tool_mm"), t.get("predicted_band_mm")
    if p is None:
        return "-"
    return (f"{p:.3f}" + (f" [{band[0]:.3f}-{band[1]:.3f}]" if band else "")
            + (f" {t['verdict']}" if t.get("verdict") else ""))


def band_coverage(truths: list[dict]) -> str | None:
    """How often the validated AP fell inside the calibration's stated 10-90 % band, and
    how many calibrations graded good measured above 1.5x the band's top."""
    rows = [t for t in truths if t.get("predicted_band_mm")]
    if not rows:
        return None
    inside = sum(b[0] <= t["ap_after_tool_mm"] <= b[1]
                 for t in rows for b in [t["predicted_band_mm"]])
    good = [t for t in rows if t.get("verdict") == "good"]
    over = sum(t["ap_after_tool_mm"] > 1.5 * t["predicted_band_mm"][1] for t in good)
    return (f"the band held on {inside} of {len(rows)} truths (10-90 %: 80 % expected); "
            f"{len(good)} graded good, {over} of them above 1.5x the band's top")


def _with_floor(ap, floor) -> str:
    return _mm(ap) + ("" if floor is None else f" ({floor:.3f})")


def _truth_row(t: dict, level: str) -> list[str]:
    near, snear = t.get("nearest_sample_mm"), t.get("standard_nearest_sample_mm")
    edges = f"{_mm(t.get('cube_edge_mm'), '.0f')}/{_mm(t.get('standard_cube_edge_mm'), '.0f')}"
    far = (f"{'-' if near is None else f'{max(near):.0f}'}/"
           f"{'-' if snear is None else f'{max(snear):.0f}'}")
    return ([str(t["truth_seed"]), _mm(t["ap_before_tool_mm"], ".2f")]
            + [_with_floor(r["ap_after_tool_mm"], r.get("ap_floor_tool_mm"))
               + ("!" if r.get("verdict") == "worse" else "") for r in t["levels"]]
            + [_mm(t["ap_oracle_tool_mm"]),
               _with_floor(t.get("ap_after_tool_standard_mm"),
                           t.get("ap_floor_tool_standard_mm")),
               edges, far, _mm(t["ap_after_flange_mm"]), _mm(t["ap_after_tool_cell_mm"]),
               _mm(t["rp_after_tool_mm"]), _mm(t["gauge_error_before_mm"], "+.3f"),
               _mm(t["gauge_error_after_mm"], "+.3f"), _mm(t["max_model_error_mm"]),
               _predicted(t)])


def format_truths(summary: dict, world: str, level: str = "offsets") -> str:
    """The per-truth table (AP at the tool point of every level with its floor, the twin's
    whole true model, the standard cube's AP, the flange's and the cell frame's after, RP,
    gauge, the fit's largest residual, the cubes' edges and farthest points), the median
    and the worst truth; ``level``: the validated calibration's label
    (``CalibrationSettings.label``)."""
    truths = summary["truths"]
    labels = [r["level"] for r in truths[0]["levels"]] if truths else [level]
    rows = [_truth_row(t, level) for t in truths]
    out = [f"ISO 9283 and gauge block on the twin, {world} world, {len(rows)} truth(s); "
           f"calibration at level {level} from the nominal values (and below it, on the "
           f"same poses); AP at the tool point (the laser's beam point at its measuring "
           f"centre), worst of P1..P5, in the {ROBOT_FRAME}, in the near-sample cube unless "
           "the column says standard, flange or cell",
           table(["truth", "AP nominal"] + [f"AP {lb} (floor)" for lb in labels]
                 + ["AP oracle", f"standard {level} (floor)", "edge near/std",
                    "farthest near/std", f"flange {level}", f"cell {level}", "RP",
                    "gauge before", "gauge after", "max model err", "predicted"], rows),
           f"(mm; in brackets each level's {FLOOR}; {ORACLE}; standard: ISO 9283's cube, the "
           "largest inside the region the work uses (the samples' flange hull); near: a "
           "cube centred on a calibration sample's tool point; edge and farthest: each "
           "cube's edge and its points' largest distance to a sample's tool point; "
           f"{CELL}; max model err: the validated fit's largest |residual|, seed Table 9's "
           f"figure; predicted: what the {level} calibration says of itself before any "
           "validation (estimation.verdict): its expected tool-point error, rms over its "
           "samples' poses, the 10-90 % band of AP near the samples and its grade; ! after "
           "an AP: that level's verdict refuses it, no better than a simpler level)", ""]
    cover = band_coverage(truths)
    if cover:
        out.insert(-1, cover)
    by_seed = {t["truth_seed"]: t for t in truths}
    for what, key in (("median", "median_truth_seed"), ("worst", "worst_truth_seed")):
        t = by_seed[summary[key]]
        out.append(f"{what} truth (seed {t['truth_seed']}): AP at the tool point "
                   f"{t['ap_before_tool_mm']:.2f} -> {t['ap_after_tool_mm']:.3f} mm "
                   f"({change(t['ap_before_tool_mm'], t['ap_after_tool_mm'])}; its level's "
                   f"floor {_mm(t.get('ap_floor_tool_mm'))}, true model "
                   f"{t['ap_oracle_tool_mm']:.3f}), in the standard's cube "
                   f"{_mm(t.get('ap_after_tool_standard_mm'))}, at the flange "
                   f"{t['ap_before_flange_mm']:.2f} -> {t['ap_after_flange_mm']:.3f} mm, cell "
                   f"frame {t['ap_before_tool_cell_mm']:.2f} -> "
                   f"{t['ap_after_tool_cell_mm']:.3f}; RP {t['rp_after_tool_mm']:.3f} mm; "
                   f"gauge block {_mm(t['gauge_error_before_mm'], '+.3f')} -> "
                   f"{_mm(t['gauge_error_after_mm'], '+.3f')} mm")
    out += _over_truths(summary)
    out += _robot_time(truths)
    for k, tcp in enumerate(truths[0]["tcps"] if truths else []):
        out.append(f"at the named TCP {tcp['name']} (the calibration has no better estimate "
                   "of it than the nominal one), AP before -> after (true model) per truth: "
                   + "; ".join(f"{t['truth_seed']}: {t['tcps'][k]['ap_before_tcp_mm']:.2f} -> "
                               f"{t['tcps'][k]['ap_after_tcp_mm']:.3f} "
                               f"({t['tcps'][k]['ap_oracle_tcp_mm']:.3f})" for t in truths)
                   + " mm")
    for t in truths:
        for what, key in (("the standard's cube", "standard_cube_failed"),
                          ("gauge block", "gauge_failed")):
            if t.get(key):
                out.append(f"truth {t['truth_seed']}: {what} not measured: {t[key]} (its "
                           "other figures stand)")
    for f in summary["failed_truths"]:
        out.append(f"truth {f['truth_seed']} left out: {f['reason']}")
    return "\n".join(out)


def _robot_time(truths: list[dict]) -> list[str]:
    """The calibration runs' robot time and samples over the truths (one line)."""
    t = [r["robot_time_s"] / 60 for r in truths if r.get("robot_time_s") is not None]
    n = [r["samples"] for r in truths if r.get("samples") is not None]
    if not t:
        return []
    return [f"the calibration runs: {min(n)}-{max(n)} samples in {min(t):.1f}-{max(t):.1f} "
            f"robot minutes (median {float(np.median(t)):.1f}: travel, settling and the "
            "laser's reads at the robot's step and tick)"]


def _over_truths(summary: dict) -> list[str]:
    """Median and worst over the truths, per level, in each cube, with the floors."""
    def pair(r, key):
        med, worst = r.get(f"{key}_median_mm"), r.get(f"{key}_worst_mm")
        return "-" if med is None else f"median {med:.3f}, worst {worst:.3f}"
    out = []
    for cube, what in (("", "near-sample cube"), ("_standard", "the standard's cube")):
        if summary.get(f"ap_after_tool{cube}_median_mm") is None:
            continue
        out.append(f"over the truths, AP at the tool point, {what}: " + "; ".join(
            f"{r['level']} {pair(r, f'ap_after_tool{cube}')} (floor "
            f"{pair(r, f'ap_floor_tool{cube}')})" for r in summary["levels_summary"])
            + f"; the twin's whole true model {pair(summary, f'ap_oracle_tool{cube}')} mm")
    return out


def format_breakdown(bd: dict, level: str = "offsets") -> str:
    """What each error source leaves after calibration (``breakdown``), the noise's share
    apart, and what limits the calibration (at ``level``)."""
    rows = []
    for r in bd["variants"]:
        if "failed" in r:
            rows.append([r["variant"], "failed"] + [""] * 6)
            continue
        rows.append([r["variant"], f"{r['ap_before_tool_mm']:.2f}",
                     f"{r['ap_after_tool_mm']:.3f}", _mm(r.get("ap_floor_tool_mm")),
                     f"{r['ap_after_flange_mm']:.3f}", f"{r['ap_after_tool_cell_mm']:.3f}",
                     f"{r['ap_oracle_tool_mm']:.3f}", f"{r['max_model_error_mm']:.3f}"])
    how = ("each mismatch source switched off in turn, without the noise" if bd["mode"] == "off"
           else "each alone")
    out = [f"what each error source leaves (truth {bd['truth_seed']}, the same poses; sources "
           f"{how}; near-sample cube, no gauge block)",
           table(["world", "AP before", "AP after", "floor", "flange after", "cell after",
                  "AP oracle", "max model err"], rows),
           f"(mm; AP at the tool point, robot frame, unless the column says flange or cell; "
           f"floor: the level's, in that world; oracle: the twin's whole true model there)"]
    out += _limits(bd, level)
    return "\n".join(out)


def _limits(bd: dict, level: str) -> list[str]:
    """The breakdown's verdict: the noise's share, then each mismatch source's (noise-free),
    said as what the level models or lacks."""
    out = []
    ns = noise_share(bd)
    if ns is not None:
        alone = "" if ns["alone_mm"] is None else (
            f"; the noise alone on the cell leaves {ns['alone_mm']:.3f} mm")
        if ns["dominates"]:
            out.append(f"what limits this calibration is the noise of its samples "
                       f"({ns['what']}): with every source AP after is {ns['with_mm']:.3f} "
                       f"mm, on the same poses rehearsed without the noise "
                       f"{ns['without_mm']:.3f} mm{alone}. A richer model does not remove "
                       "it; more samples, or poses that average it down, do.")
        else:
            adds = (f"adds {ns['share_mm']:.3f} mm" if ns["share_mm"] >= 0.005 else
                    "adds nothing measurable here (its draw through the fit may even offset "
                    "some of the mismatch)")
            out.append(f"the noise ({ns['what']}) {adds}: with every source AP after is "
                       f"{ns['with_mm']:.3f} mm, on the same poses rehearsed without the "
                       f"noise {ns['without_mm']:.3f} mm{alone}.")
    cr = cannot_remove(bd)
    big = [c for c in cr if c["ap_after_tool_share_mm"] >= 0.005]
    if big:
        how = ("switched off, all but the noise drops by" if bd["mode"] == "off"
               else "alone, without the noise, it adds")
        out.append(f"what a calibration at level {level} leaves of each source, the noise "
                   "kept out: " + "; ".join(
                       f"{c['what']}: {c['ap_after_tool_share_mm']:.3f} mm ({how} that; "
                       + ("in the level's model: the fit does not take all of it"
                          if c["modelled"] else "not in the level's model") + ")"
                       for c in big)
                   + ". A source outside the model is absorbed only where it looks like one "
                     "of the model's parameters in the calibrated region.")
    small = [c for c in cr if c["ap_after_tool_share_mm"] < 0.005]
    if small:
        out.append("less than 5 um of AP here (a negative share: the sources partly cancel "
                   "in the fit): " + ", ".join(
                       f"{c['source']} {c['ap_after_tool_share_mm'] * 1e3:+.0f} um"
                       for c in small))
    return out
