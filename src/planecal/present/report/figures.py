"""What every report figure shares: a matplotlib ``Figure`` drawn without pyplot (no
global state, no GUI backend), saved as a PNG into the report directory, the display
unit an axis uses, and the parameter names of a result file.

Display units: values are SI inside (m, rad, 1/m); an axis shows them scaled to a prefix
that gives tick labels of one to three digits (``display_scale``), and says the unit in
its label.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

DPI = 100
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
          "#7f7f7f", "#bcbd22", "#17becf")
BEFORE, AFTER = "#d62728", "#1f77b4"  # nominal / initial model, calibrated model

# SI unit -> [(scale, label)], largest first; the first whose scaled range reaches 1 wins
_PREFIXES = {
    "rad": [(1.0, "rad"), (1e3, "mrad"), (1e6, "µrad"), (1e9, "nrad")],
    "m": [(1.0, "m"), (1e3, "mm"), (1e6, "µm"), (1e9, "nm")],
    "1/m": [(1.0, "1/m"), (1e3, "10⁻³/m"), (1e6, "10⁻⁶/m")],
}

# fixed display units for spreads in tables (one unit per column, not per row)
TABLE_UNITS = {"rad": (1e6, "µrad"), "m": (1e6, "µm"), "1/m": (1e3, "10⁻³/m"),
               "rad/(N m)": (1e9, "µrad/kNm")}


@dataclass(frozen=True)
class Plot:
    """A figure written to the report directory."""
    file: str  # file name in the report directory
    title: str
    caption: str


def display_scale(unit: str, values) -> tuple[float, str]:
    """(scale, label) for showing SI ``values`` in ``unit``: the largest prefix at which
    the largest finite |value| is at least 1 (so ticks read 1..999, not 0.000012)."""
    prefixes = _PREFIXES.get(unit)
    if prefixes is None:
        return 1.0, unit
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v) & (v > 0)]
    if v.size == 0:
        return prefixes[0]
    top = float(v.max())
    for scale, label in prefixes:
        if top * scale >= 1.0:
            return scale, label
    return prefixes[-1]


def new_figure(width_in: float, height_in: float, rows: int = 1, cols: int = 1, **kw):
    """A Figure with constrained layout (titles and labels are never cut) and its axes."""
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, **kw)
    return fig, axes


def save(fig, out_dir: Path, name: str, title: str, caption: str) -> Plot:
    from planecal.base.progress import report
    path = Path(out_dir) / f"{name}.png"
    report(what=f"drawing {path.name}")
    fig.savefig(path, dpi=DPI, metadata={"Software": "planecal"})  # outputs.PNG_MARK
    return Plot(path.name, title, caption)


def num(v, digits: int = 4) -> str:
    """A number for a table: ``digits`` significant digits, positional notation from 1e-3
    to 1e6 (18470, not 1.847e+04), "–" for a missing or non-finite value."""
    import math
    if v is None or not np.isfinite(v):
        return "–"
    x = float(f"{v:.{digits}g}")
    if x == 0:
        return "0"
    e = math.floor(math.log10(abs(x)))
    if -3 <= e < 6:
        return f"{x:.{max(digits - 1 - e, 0)}f}"
    return f"{x:.{digits - 1}e}"


def integer_y(ax) -> None:
    """Counts on the y axis: integer ticks only (no "2.5 samples")."""
    from matplotlib.ticker import MaxNLocator
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def headroom(ax, factor: float = 1.35) -> None:
    """Room above the data for a legend inside the axes (it must not hide data)."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, lo + (hi - lo) * factor)


def log_ticks(ax, which: str = "y") -> None:
    """Readable value ticks on a log axis: 1-2-5 per decade over up to two decades, 1-3
    over four, decades beyond; plain numbers (0.05, 20), no minor labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullLocator
    axis = ax.yaxis if which == "y" else ax.xaxis
    lo, hi = ax.get_ylim() if which == "y" else ax.get_xlim()
    decades = np.log10(hi / lo) if lo > 0 and hi > lo else 10.0
    subs = (1.0, 2.0, 5.0) if decades <= 2.5 else (1.0, 3.0) if decades <= 4.5 else (1.0,)
    axis.set_major_locator(LogLocator(base=10.0, subs=subs))
    axis.set_minor_locator(NullLocator())
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))


def grid_shape(n: int, max_cols: int = 3) -> tuple[int, int]:
    """(rows, cols) for n panels: as few rows as max_cols allows, filled evenly (4 -> 2 x 2,
    not 3 + 1)."""
    rows = -(-n // max_cols)
    return rows, -(-n // rows)


def hide_unused(axes, n: int) -> None:
    for ax in axes.flat[n:]:
        ax.set_visible(False)


# ----- parameters of a result file -----------------------------------------------------------

def parameter_unit(name: str) -> str:
    """SI unit of a calibration parameter, from its name in result files
    (``planecal.model.layout.quantity_of``)."""
    from planecal.model.layout import quantity_of
    return quantity_of(name)["unit"]


def parameter_group(name: str) -> str:
    """The figure group a parameter goes to: joint offsets, sensor pose, its plane, joint
    geometry, base frame or compliance."""
    import re
    if name.startswith("delta"):
        return "joint offsets"
    if name.startswith("o_") or name.startswith("phi"):
        return "sensor pose"
    if name.startswith("base_"):
        return "base frame"
    if re.fullmatch(r"n\d+_[xyz]", name):
        return f"plane {name[1:].split('_')[0]}"
    if re.fullmatch(r"c\d+", name):
        return "compliance"
    return "joint geometry"


def groups(names) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for n in names:
        out.setdefault(parameter_group(n), []).append(n)
    return out


def label(name: str) -> str:
    """A parameter name as a reader writes it: delta2 -> δ2, phi_y -> φy, n1_x -> ñ1x."""
    if name.startswith("delta"):
        return "δ" + name[5:]
    if name.startswith("phi_"):
        return "φ" + name[4:]
    if name.startswith("o_"):
        return "o" + name[2:]
    if name.startswith("n") and "_" in name:
        k, c = name[1:].split("_", 1)
        return f"ñ{k}{c}"
    return name
