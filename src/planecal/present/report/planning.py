"""Report of a pose plan (``plan --out POSES.json``): the D-optimal design against the
design the sampling run itself would visit with the same seed ("run design").

Figures: the predicted std per parameter for both designs (and the measured spread with
``--measure``); the joint angles of both designs; where the beam meets each plate (in the
plate's own frame, with the scene's nominal parameters).
"""
from __future__ import annotations

import numpy as np

from planecal.present.report.figures import (AFTER, BEFORE, TABLE_UNITS, grid_shape, hide_unused,
                                     integer_y, label, log_ticks, new_figure, num,
                                     parameter_unit, save)
from planecal.present.report.inputs import Context, load_scene_for
from planecal.present.report.page import Page

PLANNED, RUN = AFTER, BEFORE
_UNIT_PANELS = (("rad", "angles: joint offsets and beam angles"), ("m", "sensor origin"),
                ("1/m", "planes"))


def fig_predicted(out, res):
    free = list(res["free"])
    meas = res.get("measured") if isinstance(res.get("measured"), dict) else None
    panels = [(u, what, [n for n in free if parameter_unit(n) == u]) for u, what in _UNIT_PANELS]
    panels = [p for p in panels if p[2]]
    widths = [max(len(p[2]), 2) for p in panels]
    fig, axes = new_figure(max(8.0, 0.6 * sum(widths) + 2.0), 4.4, 1, len(panels),
                           gridspec_kw={"width_ratios": widths})
    for ax, (unit, what, names) in zip(axes.flat, panels):
        k, dunit = TABLE_UNITS[unit]
        x = np.arange(len(names))
        pl = np.array([res["predicted_std_planned"][n] for n in names]) * k
        rd = np.array([res["predicted_std_random"][n] for n in names]) * k
        ax.bar(x - 0.2, rd, 0.4, color=RUN, label="run design, predicted")
        ax.bar(x + 0.2, pl, 0.4, color=PLANNED, label="planned, predicted")
        vals = [pl, rd]
        if meas:
            for key, dx, color, what_m in (("random", -0.2, "#5a0d0e", "run design, measured"),
                                           ("planned", 0.2, "#0b2e4f", "planned, measured")):
                m = np.array([meas.get(key, {}).get(n, np.nan) for n in names], float) * k
                ax.plot(x + dx, m, "D", color=color, markersize=5, label=what_m)
                vals.append(m[np.isfinite(m)])
        ax.set_yscale("log")
        v = np.concatenate(vals)
        v = v[np.isfinite(v) & (v > 0)]
        ax.set_ylim(v.min() / 1.6, v.max() * 1.6)
        log_ticks(ax, "y")
        ax.set_xticks(x, [label(n) for n in names])
        ax.set_ylabel(f"std [{dunit}]")
        ax.set_title(what, fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center",
               ncols=4 if meas else 2)
    fig.suptitle(f"Standard deviation of each parameter: {res['samples']} planned poses vs "
                 f"the run's own design (D-efficiency ×{res['d_efficiency_gain']:.2f})")
    return save(fig, out, "predicted_std", "Predicted spread",
                "Standard deviation predicted for each parameter (the unweighted fit's sandwich "
                "covariance with the twin's noise model) for the planned poses and for the "
                "poses the sampling run would visit with the same seed"
                + ("; diamonds: measured over twin runs." if meas else "."))


def fig_joints(out, robot, qe_p, qe_r):
    from planecal.model.encoder import counts_to_joints
    qp = np.degrees(counts_to_joints(robot, np.asarray(qe_p, float)))
    qr = np.degrees(counts_to_joints(robot, np.asarray(qe_r, float)))
    lim = np.degrees(robot.limits)
    fig, axes = new_figure(11, 5.6, 2, 3)
    for j, ax in enumerate(axes.flat):
        lo = min(qp[:, j].min(), qr[:, j].min())
        hi = max(qp[:, j].max(), qr[:, j].max())
        pad = max(1.0, 0.05 * (hi - lo))
        edges = np.linspace(lo - pad, hi + pad, 16)
        ax.hist(qr[:, j], bins=edges, color=RUN, alpha=0.55, label="run design")
        ax.hist(qp[:, j], bins=edges, histtype="step", color=PLANNED, linewidth=2,
                label="planned")
        ax.set_xlabel(f"q{j + 1} [deg]  (limits {lim[j, 0]:g} to {lim[j, 1]:g})")
        ax.set_ylabel("poses")
        integer_y(ax)
    hide_unused(axes, 6)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    fig.suptitle("Joint angles of the two designs")
    return save(fig, out, "design_joints", "Joint angles",
                "Distribution of each joint angle over the planned poses and over the run's "
                "own design. A design that keeps a joint in a narrow range (e.g. the wrist q5 "
                "on one side) leaves the offsets it couples to poorly determined.")


def fig_spots(out, scene, qe_p, pl_p, qe_r, pl_r):
    from planecal.model.measurement import plane_distance, sensor_in_base
    from planecal.model.encoder import counts_to_joints
    from planecal.model.scene import nominal_params
    params = nominal_params(scene)
    robot = scene.robot
    k = len(scene.plates)
    rows, cols = grid_shape(k)
    fig, axes = new_figure(max(6.0, 4.3 * cols + 0.5), 3.4 * rows + 1.0, rows, cols)
    for i, (ax, plate) in enumerate(zip(axes.flat, scene.plates)):
        F = plate.frame()
        for qe, pl, color, marker, what in ((qe_r, pl_r, RUN, "x", "run design"),
                                            (qe_p, pl_p, PLANNED, "o", "planned")):
            m = np.asarray(pl) == i
            if not m.any():
                ax.plot([], [], marker, color=color, label=what)
                continue
            q = counts_to_joints(robot, np.asarray(qe, float)[m])
            o, z = sensor_in_base(robot, q, params)
            d = plane_distance(params.planes[i], o, z)
            hit = o + d[:, None] * z
            local = (hit - F[:3, 3]) @ F[:3, :3]
            ax.plot(local[:, 0] * 1e3, local[:, 1] * 1e3, marker, color=color, markersize=5,
                    mfc="none" if marker == "o" else color, label=what)
        w, h = plate.size * 1e3
        ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], color="#555", linewidth=1)
        ax.set_aspect("equal")
        ax.set_xlim(-0.08 * w, 1.08 * w)
        ax.set_ylim(-0.08 * h, 1.08 * h)
        ax.set_xlabel("along the plate's x edge [mm]")
        ax.set_ylabel("along its y edge [mm]")
        ax.set_title(plate.name, fontsize=10)
    hide_unused(axes, k)
    fig.legend(*axes.flat[0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
    fig.suptitle("Where the beam meets the plate (nominal parameters)")
    return save(fig, out, "design_spots", "Beam spots",
                "The laser spot of each pose on its plate, in the plate's frame (corner at "
                "0, 0), computed with the scene's nominal parameters.")


def build(ctx: Context) -> Page:
    res = ctx.doc
    out = ctx.out_dir
    page = Page("Pose plan",
                f"Scene {res.get('scene', '?')}: {res['samples']} of {res['candidates']} "
                f"collision-free candidates (seed {res.get('seed', '?')}); log det "
                f"{res['logdet_planned']:.2f} planned vs {res['logdet_random']:.2f} for the "
                f"run's own design: D-efficiency ×{res['d_efficiency_gain']:.2f}.")
    sec = page.section("Predicted spread")
    sec.figure(fig_predicted(out, res))
    meas = res.get("measured") if isinstance(res.get("measured"), dict) else {}
    rows = []
    for n in res["free"]:
        k, unit = TABLE_UNITS[parameter_unit(n)]
        r, p = res["predicted_std_random"][n], res["predicted_std_planned"][n]
        row = [n, unit, num(r * k), num(p * k), f"{r / p:.2f}"]
        if meas:
            mr, mp = meas.get("random", {}).get(n), meas.get("planned", {}).get(n)
            row += [num(None if mr is None else mr * k), num(None if mp is None else mp * k)]
        rows.append(row)
    heads = ["parameter", "unit", "run design", "planned", "ratio"]
    if meas:
        heads += ["measured, run design", "measured, planned"]
    sec.table(heads, rows, left=2)
    if meas:
        sec.text(f"Measured: std of the estimates over {meas.get('runs', '?')} twin runs per design.")
    sec = page.section("The designs")
    notes: list[str] = []
    scene = load_scene_for(ctx, notes)
    if scene is not None and "random_counts" in res:
        sec.figure(fig_joints(out, scene.robot, res["counts"], res["random_counts"]))
        if max(res["plates"] + res.get("random_plates", [0])) < len(scene.plates):
            sec.figure(fig_spots(out, scene, res["counts"], res["plates"],
                                 res["random_counts"], res["random_plates"]))
        else:
            notes.append(f"the plan refers to more plates than scene {scene.name} has: no "
                         f"beam-spot figure")
    for n in notes:
        sec.note(n)
    text = (f"{res.get('exchange_swaps', '?')} exchanges in "
            f"{res.get('exchange_passes', '?')} passes.")
    rt = res.get("robot_time_s")
    if rt:
        text += (f" Robot time: random run {rt['random'] / 60:.1f} min, planned in the "
                 f"design's order {rt['planned_unordered'] / 60:.1f} min, ordered "
                 f"{rt['planned'] / 60:.1f} min.")
    tr = res.get("tour")
    if tr:
        text += (f" The tour took {tr['detours']} detours and has {tr['excluded']} blocked moves"
                 f" without one.")
    sec.text(text)
    return page
