"""The plate-layouts study's terminal report (``studies.layouts``)."""
from __future__ import annotations

from planecal.present.tables import table


def format_layouts(res: dict, display) -> str:
    """A table per subset: parameter, predicted std (display units); then what is
    excluded and why. ``display(name) -> (scale, unit)``."""
    out = [f"plate layouts of {res['scene']}: {res['samples']} collision-free random poses "
           f"per layout (seed {res['seed']}), std predicted at the twin's noise "
           f"(repeatability {res['noise']['joint_sigma_rad'] * 1e6:.1f} urad per joint, "
           f"laser {res['noise']['laser_sample_sigma_m'] * 1e9:.0f} nm per sample)"]
    names = []
    for r in res["layouts"]:
        for n in r["free"]:
            if n not in names:
                names.append(n)
    head = ["parameter"] + ["+".join(r["plates"]) for r in res["layouts"]]
    rows = []
    for n in names:
        row = [n]
        for r in res["layouts"]:
            if n in r["std"]:
                sc, unit = display(n)
                row.append(f"{r['std'][n] * sc:.3g} {unit}")
            elif any(e["parameter"] == n for e in r["excluded"]):
                row.append("excluded")
            else:
                row.append("-")
        rows.append(row)
    out.append(table(head, rows))
    for r in res["layouts"]:
        if r["excluded"]:
            out.append(f"{'+'.join(r['plates'])}: rank {r['rank']} of {len(r['free'])}; "
                       + "; ".join(_why(e) for e in r["excluded"]))
    return "\n".join(out)


def _why(e: dict) -> str:
    if e["reason"] != "combination":
        return {"no_effect": f"{e['parameter']}: no effect on any distance",
                "scale": f"{e['parameter']}: the arm's scale, kept (--free-scale frees it)"}[
            e["reason"]]
    mix = " ".join(f"{v:+.3g}*{k}" for k, v in list(e["combination"].items())[:4])
    more = " ..." if len(e["combination"]) > 4 else ""
    return f"{e['parameter']}: a combination of others ({mix}{more})"
