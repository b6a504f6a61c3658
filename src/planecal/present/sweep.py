"""The sweep's terminal table (``studies.sweep``)."""
from __future__ import annotations

from pathlib import Path

from planecal.present.tables import table


def urad_text(v) -> str:
    """A value in rad as urad for the table; "-" where it is not defined (one run: no std)."""
    import math
    return f"{v * 1e6:.3g}" if v is not None and math.isfinite(v) else "-"


def format_sweep(res: dict) -> str:
    """The sweep's table: one row per cell."""
    cells = res["cells"]
    names = next((c["names"] for c in cells if c.get("names")), [])
    heads = ["scene", "errors", "design", "N", "taken", "level", "runs", "robot min", "s/sample",
             "travel s/sample"] + [f"std {n}" for n in names] + ["offset std", "offset rms"]
    rows = []
    for c in cells:
        err = Path(c["errors"]).stem if "/" in c["errors"] else c["errors"]
        row = [c["scene"], err, c["design"], str(c["samples"]),
               f"{c['samples_taken']:.1f}" if c["runs"] else "-", c["level"],
               str(c["runs"]) + (f" ({c['failed']} failed)" if c["failed"] else "")]
        if c["runs"]:
            row += [f"{c['robot_time_min']:.2f}", f"{c['robot_time_per_sample_s']:.2f}",
                    f"{c['travel_per_sample_s']:.2f}"]
            row += [urad_text(c["std_rad"].get(n)) for n in names]
            row += [urad_text(c["offset_std_rad"]), urad_text(c["offset_rms_rad"])]
        else:
            row += ["-"] * (3 + len(names) + 2)
        rows.append(row)
    return ("sweep: accuracy against robot time; offset errors vs the truth over the runs "
            "[urad] (std: ddof 1; offset std/rms: RMS over the free offsets)\n"
            + table(heads, rows))
