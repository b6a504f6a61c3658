"""The plate-layouts study's terminal report (``studies.layouts``)."""
from __future__ import annotations

import textwrap

from planecal.present.tables import table


def format_layouts(res: dict, display, width: int = 100) -> str:
    """A table per subset: parameter, predicted std (display units); then what is
    excluded and why. ``display(name) -> (scale, unit)``. No line longer than ``width``
    (a terminal's, or 100): the layouts' columns go into as many tables as they need,
    each repeating the parameter and its unit."""
    out = [textwrap.fill(
        f"plate layouts of {res['scene']}: {res['samples']} collision-free random poses "
        f"per layout (seed {res['seed']}), std predicted at the twin's noise "
        f"(repeatability {res['noise']['joint_sigma_rad'] * 1e6:.1f} urad per joint, "
        f"laser {res['noise']['laser_sample_sigma_m'] * 1e9:.0f} nm per sample)", width)]
    names = []
    for r in res["layouts"]:
        for n in r["free"]:
            if n not in names:
                names.append(n)
    cols = []  # per layout: its heading and one cell per parameter
    for r in res["layouts"]:
        cells = []
        for n in names:
            if n in r["std"]:
                cells.append(f"{r['std'][n] * display(n)[0]:.3g}")
            elif any(e["parameter"] == n for e in r["excluded"]):
                cells.append("excluded")
            else:
                cells.append("-")
        cols.append(("+".join(r["plates"]), cells))
    units = [display(n)[1] for n in names]
    lead = max(map(len, ["parameter", *names])) + 2 + max(map(len, ["unit", *units]))

    def span(block):
        return lead + sum(2 + max(len(h), *map(len, c)) for h, c in block)

    block: list = []
    for col in cols + [None]:
        if block and (col is None or span(block + [col]) > width):
            rows = [[n, u] + [c[i] for _, c in block]
                    for i, (n, u) in enumerate(zip(names, units))]
            out += ([""] if len(out) > 1 else []) + [
                table(["parameter", "unit"] + [h for h, _ in block], rows,
                      "ll" + "r" * len(block))]
            block = []
        if col is not None:
            block.append(col)
    for r in res["layouts"]:
        if r["excluded"]:
            out.append(textwrap.fill(f"{'+'.join(r['plates'])}: rank {r['rank']} of "
                                     f"{len(r['free'])}; "
                                     + "; ".join(_why(e) for e in r["excluded"]), width,
                                     subsequent_indent="    "))
    return "\n".join(out)


def _why(e: dict) -> str:
    if e["reason"] != "combination":
        return {"no_effect": f"{e['parameter']}: no effect on any distance",
                "scale": f"{e['parameter']}: the arm's scale, kept (--free-scale frees it)"}[
            e["reason"]]
    mix = " ".join(f"{v:+.3g}*{k}" for k, v in list(e["combination"].items())[:4])
    more = " ..." if len(e["combination"]) > 4 else ""
    return f"{e['parameter']}: a combination of others ({mix}{more})"
