"""The bootstrap study's terminal report (``studies.bootstrap``)."""
from __future__ import annotations

import numpy as np

from planecal.model.layout import ParamLayout
from planecal.present.tables import table


def format_bootstrap(res: dict, layout: ParamLayout) -> str:
    """Terminal report: per size a table of the free parameters' spread (display units of
    the study's parameter ``layout``)."""
    lines = [f"pool: {res['pool']} samples; {res['repeats']} random subsets per size "
             f"(seed {res['seed']})"]
    for e in res["sizes"]:
        ov = e["overlap"]
        lines.append("")
        lines.append(f"subset size {e['size']}: {e['fits']} fits"
                     + (f", {e['failed']} failed" if e['failed'] else "")
                     + (f", {e['not_converged']} not converged" if e['not_converged'] else "")
                     + f"; share of pool {ov['share']:.0%}, two subsets share "
                     f"{ov['expected_common_samples']:.1f} samples on average")
        rows = []
        for nm, v in e["params"].items():
            k, unit = layout.display(nm)

            def f(x):
                return "-" if x is None or not np.isfinite(x) else f"{x * k:.4g}"
            ratio = (v["std_independent"] / v["reported_std"]
                     if v["reported_std"] else float("nan"))
            rows.append([nm, unit, f"{v['mean']:.7g}", f(v["std"]), f(v["std_independent"]),
                         f(v["min"] - v["mean"]), f(v["max"] - v["mean"]), f(v["reported_std"]),
                         "-" if not np.isfinite(ratio) else f"{ratio:.2f}"])
        if rows:
            lines.append(table(["param", "spread in", "mean (SI)", "std", "std_indep", "min-mean", "max-mean",
                                "fit_std", "indep/fit"], rows))
        if e["warning"]:
            lines.append(f"WARNING {e['warning']}")
    return "\n".join(lines)
