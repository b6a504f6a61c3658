"""Every text rendering of a validation (``planecal validate``, the demo): one truth, the
truths' table, the breakdown by error source."""
from __future__ import annotations

import numpy as np

from planecal.present.tables import table
from planecal.studies.validation.truths import cannot_remove


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


def _models(v: dict) -> list[tuple[str, str]]:
    """(label, key in iso.models) of every model commanding, in order."""
    return ([("nominal", "nominal")] + [(r["level"], r["level"]) for r in v["levels"]]
            + [("oracle", "oracle")])


def format_validation(v: dict) -> str:
    """One validation: per ISO pose the tool point's AP of every model, then the worst
    pose's at the tool point, the flange and the named TCPs, robot and cell frame, and the
    gauge block."""
    iso, cube = v["iso"], v["cube"]
    models = _models(v)
    after = v["model_after"]
    rows = []
    for i in range(5):
        p = iso["points_m"][i]
        rows.append([f"P{i + 1}", f"{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}",
                     f"{cube['nearest_sample_mm'][i]:.0f}"]
                    + [f"{iso['models'][k]['tool']['ap_mm'][i]:.4f}" for _, k in models]
                    + [f"{iso['models'][after]['tool']['rp_mm'][i]:.4f}"])
    how = "(given), centred" if cube["rule"].startswith("given") else "centred on the " \
        "samples' medoid tool point"
    out = [f"ISO 9283 on the twin at {where_text(v)}, in the robot's frame: cube edge "
           f"{cube['edge_m'] * 1e3:.0f} mm {how} at "
           f"{np.round(np.asarray(cube['center_m']), 3).tolist()} m, "
           f"{v['settings']['cycles']} cycles; 'nearest': the ISO point's distance to the "
           "nearest sample's tool point",
           table(["pose", "position [m]", "nearest mm"] + [f"AP {m} mm" for m, _ in models]
                 + [f"RP {after} mm"], rows), ""]
    if not cube["inside_region"]:
        out.append(f"the given cube reaches {max(cube['outside_region_mm']):.0f} mm / "
                   f"{max(cube['outside_region_deg']):.1f} deg outside the calibrated region")
    out += [f"AP at the tool point (worst pose): before {v['ap_before_tool_mm']:.4f} mm, after "
            f"({after}) {v['ap_after_tool_mm']:.4f} mm "
            f"({change(v['ap_before_tool_mm'], v['ap_after_tool_mm'])}); the twin's own "
            f"true model {v['ap_oracle_tool_mm']:.4f} mm (the floor: backlash, repeatability, "
            f"whole counts); RP after {v['rp_after_tool_mm']:.4f} mm",
            f"AP at the flange (beside it; a plane calibration puts the flange frame's error "
            f"into the sensor pose): before {v['ap_before_flange_mm']:.4f} mm, after "
            f"{v['ap_after_flange_mm']:.4f} mm, true model {v['ap_oracle_flange_mm']:.4f} mm",
            f"in the cell frame (with the robot's placement and delta1, which no plane "
            f"calibration sees), tool point: AP before {v['ap_before_tool_cell_mm']:.4f} mm, "
            f"after {v['ap_after_tool_cell_mm']:.4f} mm"]
    for t in v["tcps"]:
        out.append(f"TCP {t['name']} ({', '.join(f'{c * 1e3:g}' for c in t['tcp_m'])} mm in "
                   f"the flange frame; the calibration has no better estimate of it than "
                   f"the nominal one): AP before {t['ap_before_tcp_mm']:.4f} mm, after "
                   f"{t['ap_after_tcp_mm']:.4f} mm, true model {t['ap_oracle_tcp_mm']:.4f} mm")
    out.append("")
    out += _gauge_lines(v)
    return "\n".join(out)


def _gauge_lines(v: dict) -> list[str]:
    out = []
    g = v["gauge"]
    if g is not None:
        rows = [[name, f"{m['error_mm']:+.4f}", f"{m['error_std_mm']:.4f}",
                 f"{m['max_abs_error_mm']:.4f}"] for name, m in g["models"].items()]
        out.append(f"gauge block {g['length_m'] * 1e3:.0f} mm, 4 points per face, "
                   f"{g['repeats']} repeats (largest incidence {g['max_incidence_deg']:.0f} deg)")
        out.append(table(["model", "length error mm", "std mm", "max |error| mm"], rows))
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


def _ap_level(r: dict) -> str:
    """A level's AP, marked ``!`` where its verdict refuses it (estimation.verdict)."""
    return _mm(r["ap_after_tool_mm"]) + ("!" if r.get("verdict") == "worse" else "")


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


def _mm(x, fmt=".3f"):
    return "-" if x is None else format(x, fmt)


def format_truths(summary: dict, world: str, level: str = "offsets") -> str:
    """The per-truth table (AP at the tool point of every model side by side, the flange's
    and the cell frame's after, RP, gauge, the fit's largest residual, the ISO points'
    largest distance to a sample), the median and the worst truth; ``level``: the
    validated calibration's label (``CalibrationSettings.label``)."""
    truths = summary["truths"]
    labels = [r["level"] for r in truths[0]["levels"]] if truths else [level]
    rows = []
    for t in truths:
        near = t.get("nearest_sample_mm")
        rows.append([str(t["truth_seed"]), _mm(t["ap_before_tool_mm"], ".2f")]
                    + [_ap_level(r) for r in t["levels"]]
                    + [_mm(t["ap_oracle_tool_mm"]), _mm(t["ap_after_flange_mm"]),
                       _mm(t["ap_oracle_flange_mm"]), _mm(t["ap_after_tool_cell_mm"]),
                       _mm(t["rp_after_tool_mm"]), _mm(t["gauge_error_before_mm"], "+.3f"),
                       _mm(t["gauge_error_after_mm"], "+.3f"), _mm(t["max_model_error_mm"]),
                       "-" if near is None else f"{max(near):.0f}",
                       _predicted(t)])
    out = [f"ISO 9283 and gauge block on the twin, {world} world, {len(rows)} truth(s); "
           f"calibration at level {level} from the nominal values (and below it, on the "
           "same poses); AP at the tool point (the laser's beam point at its measuring "
           "centre) in the robot's frame, worst of P1..P5, unless the column says flange "
           "or cell; oracle: the twin's own true model (the floor)",
           table(["truth", "AP nominal"] + [f"AP {lb}" for lb in labels]
                 + ["AP oracle", f"flange {level}", "flange oracle", f"cell {level}",
                    "RP", "gauge before", "gauge after", "max model err", "nearest",
                    "predicted"], rows),
           "(mm; max model err: the validated fit's largest |residual|, seed Table 9's "
           "figure; nearest: the ISO points' largest distance to a sample's tool point; "
           f"predicted: what the {level} calibration says of itself before any validation "
           "(estimation.verdict): its expected tool-point error, rms over its samples' "
           "poses, the 10-90 % band of AP near the samples and its grade; ! after an AP: "
           "that level's verdict refuses it, no better than a simpler level)", ""]
    cover = band_coverage(truths)
    if cover:
        out.insert(-1, cover)
    by_seed = {t["truth_seed"]: t for t in truths}
    for what, key in (("median", "median_truth_seed"), ("worst", "worst_truth_seed")):
        t = by_seed[summary[key]]
        out.append(f"{what} truth (seed {t['truth_seed']}): AP at the tool point "
                   f"{t['ap_before_tool_mm']:.2f} -> {t['ap_after_tool_mm']:.3f} mm "
                   f"({change(t['ap_before_tool_mm'], t['ap_after_tool_mm'])}; true model "
                   f"{t['ap_oracle_tool_mm']:.3f}), at the flange {t['ap_before_flange_mm']:.2f}"
                   f" -> {t['ap_after_flange_mm']:.3f} mm, cell frame "
                   f"{t['ap_before_tool_cell_mm']:.2f} -> {t['ap_after_tool_cell_mm']:.3f}; RP "
                   f"{t['rp_after_tool_mm']:.3f} mm; gauge block "
                   f"{_mm(t['gauge_error_before_mm'], '+.3f')} -> "
                   f"{_mm(t['gauge_error_after_mm'], '+.3f')} mm")
    out.append("over the truths, AP at the tool point: " + "; ".join(
        f"{r['level']} median {r['ap_after_tool_median_mm']:.3f}, worst "
        f"{r['ap_after_tool_worst_mm']:.3f} mm" for r in summary["levels_summary"])
        + f"; the twin's own true model median {summary['ap_oracle_tool_median_mm']:.3f}, "
          f"worst {summary['ap_oracle_tool_worst_mm']:.3f} mm")
    for k, tcp in enumerate(truths[0]["tcps"] if truths else []):
        out.append(f"at the named TCP {tcp['name']} (the calibration has no better estimate "
                   "of it than the nominal one), AP before -> after (true model) per truth: "
                   + "; ".join(f"{t['truth_seed']}: {t['tcps'][k]['ap_before_tcp_mm']:.2f} -> "
                               f"{t['tcps'][k]['ap_after_tcp_mm']:.3f} "
                               f"({t['tcps'][k]['ap_oracle_tcp_mm']:.3f})" for t in truths)
                   + " mm")
    for f in summary["failed_truths"]:
        out.append(f"truth {f['truth_seed']} left out: {f['reason']}")
    return "\n".join(out)


def format_breakdown(bd: dict, level: str = "offsets") -> str:
    """What each error source leaves after calibration (``breakdown``), and the sources
    the calibration (at ``level``) cannot remove."""
    rows = []
    for r in bd["variants"]:
        if "failed" in r:
            rows.append([r["variant"], "failed", "", "", "", "", ""])
            continue
        rows.append([r["variant"], f"{r['ap_before_tool_mm']:.2f}",
                     f"{r['ap_after_tool_mm']:.3f}", f"{r['ap_after_flange_mm']:.3f}",
                     f"{r['ap_after_tool_cell_mm']:.3f}", f"{r['ap_oracle_tool_mm']:.3f}",
                     f"{r['max_model_error_mm']:.3f}"])
    how = "switched off in turn" if bd["mode"] == "off" else "each alone"
    out = [f"what each error source leaves (truth {bd['truth_seed']}, the same poses; sources "
           f"{how}; no gauge block)",
           table(["world", "AP before", "AP after", "flange after", "cell after", "AP oracle",
                  "max model err"], rows),
           "(mm; AP at the tool point, robot frame, unless the column says flange or cell; "
           "oracle: the twin's own true model in that world)"]
    cr = cannot_remove(bd)
    noise = [c for c in cr if c["source"] == "noise"]
    cr = [c for c in cr if c["source"] != "noise"]
    big = [c for c in cr if c["ap_after_tool_share_mm"] >= 0.005]
    if big:
        what = ("AP after calibration drops by" if bd["mode"] == "off"
                else "alone it adds")
        out.append(f"a calibration at level {level} cannot remove: " + "; ".join(
            f"{c['what']} ({what} {c['ap_after_tool_share_mm']:.3f} mm)" for c in big)
            + ". The fit's model at this level lacks them; its parameters absorb only the "
              "part that looks like one of theirs in the calibrated region.")
    small = [c for c in cr if c["ap_after_tool_share_mm"] < 0.005]
    if small:
        out.append("less than 5 um of AP here (a negative share: without it AP is larger, "
                   "the sources partly cancel in the fit): " + ", ".join(
                       f"{c['source']} {c['ap_after_tool_share_mm'] * 1e3:+.0f} um" for c in small))
    for c in noise:
        out.append(f"the noise ({c['what']}) is the floor no calibration removes: alone it "
                   f"adds {c['ap_after_tool_share_mm'] * 1e3:.0f} um of AP (and sets RP)")
    return "\n".join(out)
