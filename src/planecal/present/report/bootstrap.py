"""Report of a bootstrap study (``bootstrap --out``, seed 9.3's subset resampling).

Figure per parameter group: the spread of each parameter over the random subsets against
the subset size on log-log axes (observed, corrected to independent sets, and the mean std
the fits report), with an N^-1/2 line at the level that fits the corrected spread best;
a table per size; the overlap warnings.
"""
from __future__ import annotations

import numpy as np
from matplotlib.ticker import NullLocator

from planecal.present.report.figures import (AFTER, BEFORE, TABLE_UNITS, display_scale, grid_shape,
                                     groups, hide_unused, label, log_ticks, new_figure, num,
                                     parameter_unit, save)
from planecal.present.report.inputs import Context
from planecal.present.report.page import Page


def _series(res, name, key):
    out = []
    for e in res["sizes"]:
        v = e["params"].get(name, {}).get(key)
        out.append(np.nan if v is None else float(v))
    return np.array(out)


def slope(N, y) -> float | None:
    ok = np.isfinite(y) & (y > 0)
    if ok.sum() < 2:
        return None
    return float(np.polyfit(np.log(N[ok]), np.log(y[ok]), 1)[0])


def fig_spread(out, res, group, names):
    N = np.array([e["size"] for e in res["sizes"]], float)
    rows, cols = grid_shape(len(names))
    fig, axes = new_figure(3.9 * cols + 0.4, 3.2 * rows + 0.7, rows, cols)
    for ax, n in zip(axes.flat, names):
        obs, ind, rep = (_series(res, n, k) for k in ("std", "std_independent", "reported_std"))
        allv = np.concatenate([obs, ind, rep])
        top = np.nanmax(np.abs(allv)) if np.isfinite(allv).any() else 0.0
        # a spread at rounding level is no spread: it has no place on a log axis
        flat = [int(s) for s, v in zip(N, obs) if np.isfinite(v) and v <= 1e-9 * top]
        obs = np.where(obs > 1e-9 * top, obs, np.nan)
        ind = np.where(ind > 1e-9 * top, ind, np.nan)
        if not (np.isfinite(obs).any() or np.isfinite(rep).any()):
            ax.text(0.5, 0.5, f"{label(n)}: no spread (every subset gave the same value)",
                    ha="center", va="center", transform=ax.transAxes, fontsize=9, wrap=True)
            ax.set_axis_off()
            continue
        allv = np.concatenate([obs, ind, rep])
        scale, unit = display_scale(parameter_unit(n), allv[np.isfinite(allv)])
        ok = np.isfinite(ind) & (ind > 0)
        ax.loglog(N, obs * scale, "o", mfc="white", color=AFTER, label="observed spread")
        ax.loglog(N[ok], ind[ok] * scale, "o-", color=AFTER,
                  label="spread of independent sets (corrected)")
        if np.isfinite(rep).any():
            ax.loglog(N, rep * scale, "s--", color=BEFORE, mfc="white", label="std the fits report")
        title = label(n)
        if ok.sum() >= 1:
            level = np.exp(np.mean(np.log(ind[ok]) + 0.5 * np.log(N[ok])))
            ax.loglog(N, level * scale / np.sqrt(N), ":", color="#555",
                      label=r"$\propto N^{-1/2}$ (level fitted)")
            b = slope(N, ind)
            if b is not None:
                title += f": slope {b:+.2f}"
        if flat:
            title += f" (no spread at {', '.join(map(str, flat))})"
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("subset size [samples]")
        ax.set_ylabel(f"std of {label(n)} [{unit}]")
        v = allv[np.isfinite(allv) & (allv > 0)] * scale
        if v.size:
            ax.set_ylim(v.min() / 1.3, v.max() * 1.3)
        log_ticks(ax, "y")
        ax.set_xticks(N, [f"{int(x)}" for x in N])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.grid(True, which="both", alpha=0.3)
    hide_unused(axes, len(names))
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    fig.suptitle(f"Spread against subset size: {group} "
                 f"({res['repeats']} subsets per size from a pool of {res['pool']})")
    return save(fig, out, f"spread_{group.replace(' ', '_')}", f"Spread: {group}",
                "Standard deviation of the identified values over the random subsets of each "
                "size, on log-log axes. Subsets drawn from one pool overlap, so the observed "
                "spread shrinks to 0 as the size approaches the pool; the corrected spread "
                "(÷ sqrt((n − s)/(n − 1))) is what independent sets would show and should "
                "follow the N^-1/2 line and the std the fits report.")


def build(ctx: Context) -> Page:
    res = ctx.doc
    out = ctx.out_dir
    page = Page("Bootstrap study",
                f"Pool of {res['pool']} samples; {res['repeats']} random subsets of each size "
                f"({', '.join(str(e['size']) for e in res['sizes'])}), seed {res.get('seed', '?')}.")
    sec = page.section("Spread against subset size")
    names = [n for n in res["free"] if any(n in e["params"] for e in res["sizes"])]
    if not names:
        sec.note("No size has two or more successful fits: no spread to show.")
    for group, ns in groups(names).items():
        sec.figure(fig_spread(out, res, group, ns))
    for e in res["sizes"]:
        if e.get("warning"):
            sec.finding(e["warning"])
        if e.get("failed") or e.get("not_converged"):
            sec.finding(f"subset size {e['size']}: {e.get('failed', 0)} fits failed, "
                        f"{e.get('not_converged', 0)} did not converge")
    sec = page.section("Per size")
    for e in res["sizes"]:
        ov = e["overlap"]
        sec.text(f"Subset size {e['size']}: {e['fits']} fits; each subset is {ov['share']:.0%} of "
                 f"the pool, two share {ov['expected_common_samples']:.1f} samples on average.")
        rows = []
        for n, v in e["params"].items():
            k, unit = TABLE_UNITS[parameter_unit(n)]
            rep = v.get("reported_std")
            ratio = (v["std_independent"] / rep) if rep else float("nan")
            rows.append([n, f"{v['mean']:.7g}", unit, num(v["std"] * k),
                         num(v["std_independent"] * k), num((v["min"] - v["mean"]) * k),
                         num((v["max"] - v["mean"]) * k), num(None if rep is None else rep * k),
                         num(ratio, 3)])
        if rows:
            sec.table(["parameter", "mean (SI)", "unit", "std", "std independent",
                       "min − mean", "max − mean", "fit's std", "independent / fit"], rows,
                      left=1)
    pf = res.get("pool_fit")
    if isinstance(pf, dict) and pf.get("x") is not None:
        sec.text("The whole pool's fit is in the result file (pool_fit).")
    return page
