"""The sweep's figure: accuracy against robot minutes, one curve per pose design (the
points of a curve are its sample counts), one panel per scene x error profile x level."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from planecal.present.report.figures import (COLORS, Plot, grid_shape, hide_unused, log_ticks,
                                     new_figure, save)
from planecal.present.report.page import Page

MARKERS = {"random": "o", "planned": "s", "planned+ordered": "^"}


def _panel_key(c: dict) -> tuple:
    return (c["scene"], c["errors"], c["level"])


def fig_accuracy_vs_time(out: Path, res: dict, name: str = "accuracy_vs_robot_time") -> Plot:
    """Offset std (RMS over the free offsets of their std over the runs) against the mean
    robot minutes of a run, one curve per design, log-log."""
    cells = [c for c in res["cells"] if c.get("runs", 0) > 1]
    panels: dict = {}
    for c in cells:
        panels.setdefault(_panel_key(c), []).append(c)
    rows, cols = grid_shape(max(1, len(panels)), 2)
    fig, axes = new_figure(6.0 * cols, 4.4 * rows, rows, cols)
    flat = axes.ravel()
    designs = list(dict.fromkeys(c["design"] for c in res["cells"]))
    for ax, (key, cs) in zip(flat, panels.items()):
        for i, d in enumerate(designs):
            pts = sorted((c["robot_time_min"], c["offset_std_rad"] * 1e6, c["samples"])
                         for c in cs if c["design"] == d)
            if not pts:
                continue
            x, y, n = (np.array(v) for v in zip(*pts))
            ax.plot(x, y, marker=MARKERS.get(d, "o"), color=COLORS[i % len(COLORS)], label=d)
            for xi, yi, ni in zip(x, y, n):
                ax.annotate(f"N={int(ni)}", (xi, yi), textcoords="offset points",
                            xytext=(4, 4), fontsize=8)
        scene, errors, level = key
        err = Path(errors).stem if "/" in errors else errors
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("robot time of a run [min]")
        ax.set_ylabel("offset error std, RMS over free offsets [µrad]")
        ax.set_title(f"{scene}, {err} world, level {level}", fontsize=10)
        ax.margins(0.12)
        log_ticks(ax, "x")
        log_ticks(ax, "y")
        ax.grid(True, which="major", alpha=0.3)
        ax.legend(fontsize=9)
    hide_unused(flat, len(panels))
    runs = max((c["runs"] for c in cells), default=0)
    return save(fig, out, name, "Accuracy against robot time",
                f"Std over the runs (up to {runs} per point) of the joint offsets' error "
                "against the truth, RMS over the free offsets, against the mean robot time "
                "of a run; one curve per pose design, its points the sample counts.")


def build(ctx) -> Page:
    """The report page of a sweep (``planecal sweep``'s sweep.json): the figure and the
    table of every cell."""
    from planecal.present.report.page import Page
    res = ctx.doc
    spec = res.get("spec", {})
    page = Page("Sweep: accuracy against robot time",
                f"{len(res['cells'])} cells, {spec.get('runs', '?')} runs each, seed "
                f"{spec.get('seed', '?')}; offsets' errors against the truth of each run.")
    sec = page.section("Accuracy against robot time")
    sec.figure(fig_accuracy_vs_time(ctx.out_dir, res))
    names = next((c["names"] for c in res["cells"] if c.get("names")), [])
    rows = []
    for c in res["cells"]:
        err = Path(c["errors"]).stem if "/" in c["errors"] else c["errors"]
        row = [c["scene"], err, c["design"], c["level"], str(c["samples"]), str(c["runs"])]
        if c.get("runs"):
            row += [f"{c['samples_taken']:.1f}", f"{c['robot_time_min']:.2f}",
                    f"{c['travel_per_sample_s']:.2f}"]
            from planecal.present.sweep import urad_text  # null (one run: no std): "-"
            row += [urad_text(c["std_rad"].get(n)) for n in names]
            row += [urad_text(c["offset_std_rad"])]
        else:
            row += ["-"] * (4 + len(names))
        rows.append(row)
        if c.get("failed"):
            sec.finding(f"{c['cell']}: {c['failed']} runs failed")
    sec = page.section("Per cell")
    sec.table(["scene", "errors", "design", "level", "N", "runs", "taken", "robot min",
               "travel s/sample"] + [f"std {n} [µrad]" for n in names] + ["offset std [µrad]"],
              rows, left=4)
    return page
