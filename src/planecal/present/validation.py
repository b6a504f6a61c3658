"""Every text rendering of a validation (``planecal validate``, the demo): one truth, the
truths' table, the breakdown by error source."""
from __future__ import annotations

import numpy as np

from planecal.present.tables import table
from planecal.studies.validation.truths import cannot_remove


def format_validation(v: dict) -> str:
    iso = v["iso"]
    rows = []
    for i in range(5):
        nb, ca = iso["models"]["nominal"], iso["models"]["calibrated"]
        p = iso["points_m"][i]
        rows.append([f"P{i + 1}", f"{p[0]:.3f} {p[1]:.3f} {p[2]:.3f}", f"{nb['ap_mm'][i]:.4f}",
                     f"{ca['ap_mm'][i]:.4f}", f"{nb['rp_mm'][i]:.4f}", f"{ca['rp_mm'][i]:.4f}"])
    out = [f"ISO 9283 pose accuracy on the twin: cube edge {iso['edge_m'] * 1e3:.0f} mm centred "
           f"at {np.round(np.asarray(iso['center_m']), 3).tolist()} m, "
           f"{v['settings']['cycles']} cycles, TCP {list(v['settings']['tcp_m'])} m in the flange frame",
           table(["pose", "position [m]", "AP nominal mm", "AP calibrated mm", "RP nominal mm",
                  "RP calibrated mm"], rows), "",
           f"AP before {v['ap_before_mm']:.4f} mm, after {v['ap_after_mm']:.4f} mm "
           f"(x{v['ap_ratio']:.1f} smaller); RP {v['rp_mm']:.4f} mm (the robot's frame)",
           f"in the cell frame (with the robot's placement and delta1, which no plane "
           f"calibration sees): AP before {v['ap_before_cell_mm']:.4f} mm, after "
           f"{v['ap_after_cell_mm']:.4f} mm", ""]
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
                   f"{pr['gauge_length_std_mm']:.4f} mm (sensor pose and offsets); TCP position "
                   f"error from the offsets at P1..P5 "
                   + " ".join(f"{x:.4f}" for x in pr["tcp_position_rms_mm"]) + " mm (rms)")
    out.append("")
    out.append("offset error left after calibration [urad]: "
               + " ".join(f"{e * 1e6:+.1f}" for e in r["offset_error_rad"]))
    if abs(r["delta1_error_rad"]) > 1e-9 or abs(r["delta6_error_rad"]) > 1e-9:
        out.append(f"delta1 (not identifiable: a turn of the plates about the base axis) leaves up "
                   f"to {r['delta1_share_mm']:.3f} mm at these poses in the cell frame (none in "
                   f"the robot's frame, which J1's zero defines); delta6 (a roll of the sensor) "
                   f"leaves {r['delta6_share_mm']:.3f} mm at the TCP. Neither changes a distance "
                   f"the laser measures, so the gauge length does not see them.")
    return "\n".join(out)


def _mm(x, fmt=".3f"):
    return "-" if x is None else format(x, fmt)


def format_truths(summary: dict, world: str, level: str = "offsets") -> str:
    """The per-truth table, the median and the worst truth; ``level``: the calibration's
    label (``CalibrationSettings.label``)."""
    rows = [[str(t["truth_seed"]), _mm(t["ap_before_mm"], ".2f"), _mm(t["ap_after_mm"]),
             _mm(t["ap_after_cell_mm"]), _mm(t["rp_mm"]), _mm(t["gauge_error_before_mm"], "+.3f"),
             _mm(t["gauge_error_after_mm"], "+.3f"), _mm(t["max_model_error_mm"])]
            for t in summary["truths"]]
    out = [f"ISO 9283 and gauge block on the twin, {world} world, {len(rows)} truth(s); "
           f"calibration at level {level} from the nominal values; AP in the robot's "
           "frame (cell: in the cell frame)",
           table(["truth", "AP before", "AP after", "AP after cell", "RP", "gauge before",
                  "gauge after", "max model err"], rows),
           "(mm; AP, RP: worst of P1..P5; max model err: the fit's largest |residual|, seed "
           "Table 9's figure)", ""]
    by_seed = {t["truth_seed"]: t for t in summary["truths"]}
    for what, key in (("median", "median_truth_seed"), ("worst", "worst_truth_seed")):
        t = by_seed[summary[key]]
        out.append(f"{what} truth (seed {t['truth_seed']}): AP {t['ap_before_mm']:.2f} -> "
                   f"{t['ap_after_mm']:.3f} mm (cell frame {t['ap_before_cell_mm']:.2f} -> "
                   f"{t['ap_after_cell_mm']:.3f}), RP {t['rp_before_mm']:.3f} -> "
                   f"{t['rp_after_mm']:.3f} mm, gauge block "
                   f"{_mm(t['gauge_error_before_mm'], '+.3f')} -> "
                   f"{_mm(t['gauge_error_after_mm'], '+.3f')} mm")
    out.append(f"over the truths: AP after median {summary['ap_after_median_mm']:.3f} mm, "
               f"worst {summary['ap_after_worst_mm']:.3f} mm; in the cell frame median "
               f"{summary['ap_after_cell_median_mm']:.3f}, worst "
               f"{summary['ap_after_cell_worst_mm']:.3f} mm")
    for f in summary["failed_truths"]:
        out.append(f"truth {f['truth_seed']} left out: {f['reason']}")
    return "\n".join(out)


def format_breakdown(bd: dict, level: str = "offsets") -> str:
    """What each error source leaves after calibration (``breakdown``), and the sources
    the calibration (at ``level``) cannot remove."""
    rows = []
    for r in bd["variants"]:
        if "failed" in r:
            rows.append([r["variant"], "failed", "", "", ""])
            continue
        rows.append([r["variant"], f"{r['ap_before_mm']:.2f}", f"{r['ap_after_mm']:.3f}",
                     f"{r['ap_after_cell_mm']:.3f}", f"{r['max_model_error_mm']:.3f}"])
    how = "switched off in turn" if bd["mode"] == "off" else "each alone"
    out = [f"what each error source leaves (truth {bd['truth_seed']}, the same poses; sources "
           f"{how}; no gauge block)",
           table(["world", "AP before", "AP after", "AP after cell", "max model err"], rows),
           "(mm)"]
    cr = cannot_remove(bd)
    noise = [c for c in cr if c["source"] == "noise"]
    cr = [c for c in cr if c["source"] != "noise"]
    big = [c for c in cr if c["ap_after_share_mm"] >= 0.005]
    if big:
        what = ("AP after calibration drops by" if bd["mode"] == "off"
                else "alone it adds")
        out.append(f"a calibration at level {level} cannot remove: " + "; ".join(
            f"{c['what']} ({what} {c['ap_after_share_mm']:.3f} mm)" for c in big)
            + ". The fit's model at this level lacks them; its parameters absorb only the "
              "part that looks like one of theirs in the calibrated region.")
    small = [c for c in cr if c["ap_after_share_mm"] < 0.005]
    if small:
        out.append("less than 5 um of AP here (a negative share: without it AP is larger, "
                   "the sources partly cancel in the fit): " + ", ".join(
                       f"{c['source']} {c['ap_after_share_mm'] * 1e3:+.0f} um" for c in small))
    for c in noise:
        out.append(f"the noise ({c['what']}) is the floor no calibration removes: alone it "
                   f"adds {c['ap_after_share_mm'] * 1e3:.0f} um of AP (and sets RP)")
    return "\n".join(out)
