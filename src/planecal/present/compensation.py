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
