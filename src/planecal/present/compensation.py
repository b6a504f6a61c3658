"""The JSON record of a compensation (``planecal compensate --out X.json``,
``planecal-compensated/1``, docs/COMPENSATE.md)."""
from __future__ import annotations

import numpy as np

from planecal.estimation.compensate import (COMPENSATED_FORMAT, CalibratedModel, Compensation,
                                            Region)
from planecal.io.targets import angles_of


def compensated_document(comp: Compensation, model: CalibratedModel, region: Region,
                         inputs: dict, frame: str = "robot") -> dict:
    """The JSON output (``planecal-compensated/1``, docs/COMPENSATE.md)."""
    rows = []
    for i, name in enumerate(comp.names):
        rows.append({
            "name": name,
            "counts": comp.counts_corrected[i].tolist(),
            "nominal_counts": comp.counts_nominal[i].tolist(),
            "correction_counts": comp.correction_counts[i].tolist(),
            "joints_deg": np.degrees(comp.q_corrected[i]).tolist(),
            "nominal_joints_deg": np.degrees(comp.q_nominal[i]).tolist(),
            "position_mm": (comp.pose[i, :3, 3] * 1e3).tolist(),
            "rotation_deg": angles_of(comp.pose[i]).tolist(),
            "iterations": int(comp.iterations[i]),
            "converged": bool(comp.converged[i]),
            "residual_mm": float(comp.residual_m[i] * 1e3),
            "rounded_residual_mm": float(comp.rounded_residual_m[i] * 1e3),
            "outside_deg": np.degrees(comp.outside_rad[i]).tolist(),
            "outside_mm": float(comp.outside_m[i] * 1e3),
        })
    return {"format": COMPENSATED_FORMAT, "level": model.level, "frame": frame,
            "robot_frame": model.robot_frame().tolist(), "inputs": inputs,
            "region": region.to_dict(), "summary": comp.summary(), "targets": rows}


def compensation_text(s: dict, model: CalibratedModel, region: Region,
                      source) -> tuple[str, str | None]:
    """The terminal report of a compensation (its ``summary()`` ``s``) and, where targets
    lie outside the calibrated region, what says so in one line (else None)."""
    what = None
    if s["outside"]:
        far = []
        if s["max_outside_mm_target"] is not None:
            far.append(f"{s['max_outside_mm_target']} {s['max_outside_mm']:.0f} mm beyond the "
                       "samples' flange positions")
        if s["max_outside_target"] is not None:
            far.append(f"{s['max_outside_target']} {s['max_outside_deg']:.2f} deg beyond J"
                       f"{s['max_outside_joint']}'s sampled range")
        what = (f"{s['outside']} of {s['targets']} targets lie outside the calibrated region "
                f"of {region.samples} samples (the furthest: {'; '.join(far)})")
    lines = [f"compensated {s['targets']} targets with the {model.level} model of {source}",
             f"calibrated region: the flange positions and joint ranges of {region.samples} "
             f"samples, grown by {region.margin_m * 1e3:.0f} mm and "
             f"{np.degrees(region.margin_rad):.0f} deg ({region.source})",
             "max |correction| per joint: counts " + " ".join(f"{v:d}" for v in
                                                               s["max_correction_counts"])
             + "; mrad " + " ".join(f"{v:.3f}" for v in s["max_correction_mrad"]),
             f"solve: converged in <= {s['max_iterations']} iterations, residual <= "
             f"{s['max_residual_mm'] * 1e3:.2g} um, {s['max_residual_mrad'] * 1e3:.2g} urad; "
             f"at whole counts <= {s['max_rounded_residual_mm'] * 1e3:.1f} um, "
             f"{s['max_rounded_residual_mrad'] * 1e3:.1f} urad"]
    if what:
        lines.append(f"WARNING {what} (--allow-outside): the calibration is not known there")
    return "\n".join(lines), what
