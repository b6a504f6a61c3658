"""A replay's terminal report (``studies.replay``)."""
from __future__ import annotations

from planecal.present.tables import table


def format_replay(res: dict) -> str:

    def f(x, nd=4):
        return "-" if x is None else f"{x:.{nd}f}"
    rows = [[r["index"], f(r["measured_mm"]), f(r["twin_mm"]), f(r["analytic_mm"]),
             f(r["twin_minus_measured_mm"]), f(r["edge_margin_mm"], 1), r["hit"]]
            for r in res["rows"]]
    s = res["summary"]
    out = [table(["#", "measured_mm", "twin_mm", "analytic_mm", "twin-meas_mm", "edge_mm",
                  "ray hit"], rows, "rrrrrrl"), ""]
    if s["plate_hits"]:
        out.append(f"{s['plate_hits']} of {s['samples']} rays hit their plate: twin - measured "
                   f"mean {s['mean_diff_mm']:+.4f} mm, std {f(s['std_diff_mm'])} mm, max |diff| "
                   f"{s['max_abs_diff_mm']:.4f} mm, rms {s['rms_diff_mm']:.4f} mm; twin vs "
                   f"analytic model max |diff| {s['max_abs_twin_minus_analytic_mm']:.2e} mm; hit points "
                   f"at least {s['min_edge_margin_mm']:.1f} mm inside the plate's edges")
    if s["misses"]:
        out.append(f"WARNING {s['misses']} ray(s) miss their plate in the twin (see 'ray hit'): "
                   f"the scene's plate is too small or placed elsewhere for these poses")
    return "\n".join(out)
