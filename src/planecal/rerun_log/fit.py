"""The optimizer's recording (seed 7.3.2's graphs): convergence per iteration, model error
histograms before and after, the distance distribution, the parameter table with
standard deviations and the identifiability warnings; plus the cell on the identified
planes and the sample hit points coloured by their final model error."""
from __future__ import annotations

from dataclasses import asdict

import numpy as np

from planecal.cell import sensor_in_base
from planecal.encoder import counts_to_joints
from planecal.rerun_log.common import (_rr, close_recording, diverging_colors, eye_controls,
                                       log_cell, open_recording, recording_path)

HIST_BINS = 20  # equal-width bins from the smallest to the largest value (numpy.histogram)
HIST_ENTITIES = {"error_before": "/fit/hist/error_before", "error_after": "/fit/hist/error_after",
                 "distance": "/fit/hist/distance"}
SAMPLE_RADIUS_M = 0.003


def histogram(values_mm: np.ndarray, bins: int = HIST_BINS):
    """(counts, edges) exactly as ``numpy.histogram(values_mm, bins)``: ``bins`` equal
    bins from min to max, the last one closed."""
    v = np.asarray(values_mm, float)
    v = v[np.isfinite(v)]
    return np.histogram(v, bins=bins)


def fit_blueprint(scene=None):
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="samples (final model error)", origin="/",
                                  eye_controls=eye_controls(scene, "plate"),
                                  contents=["/cell/**", "/samples/**"]),
                rrb.TimeSeriesView(name="model error per iteration [mm]", origin="/fit",
                                   contents=["/fit/rms_mm", "/fit/max_mm"]),
            ),
            rrb.Vertical(
                rrb.BarChartView(name="distance distribution [mm]", origin="/fit/hist/distance"),
                rrb.BarChartView(name="model error before [mm]", origin="/fit/hist/error_before"),
                rrb.BarChartView(name="model error after [mm]", origin="/fit/hist/error_after"),
            ),
            rrb.Vertical(
                rrb.TextDocumentView(name="parameters", origin="/fit/parameters"),
                rrb.TextDocumentView(name="identifiability", origin="/fit/identifiability"),
            ),
            column_shares=[3, 2, 2]),
        rrb.TimePanel(timeline="iteration"),
        collapse_panels=False)


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.7g}"


def parameter_markdown(res) -> str:
    """The parameter table: initial value, identified value, std, correction, unit."""
    ident = res.identifiability
    layout = res.layout
    x0, x = res.initial.to_vector(layout), res.params.to_vector(layout)
    sd = res.std
    lines = ["# Identified parameters", "",
             "| parameter | initial | identified | std | correction | unit |",
             "|---|---:|---:|---:|---:|---|"]
    for i, (name, unit) in enumerate(zip(layout.names, layout.units)):
        if not res.free[i]:
            std = "fixed"
        elif name in ident.not_identifiable:
            std = "NOT IDENT."
        else:
            std = f"{sd[i]:.3e}"
        lines.append(f"| {name} | {_fmt(x0[i])} | {_fmt(x[i])} | {std} | "
                     f"{x[i] - x0[i]:.4e} | {unit} |")
    used = res.used
    lines += ["",
              f"* samples used: {int(used.sum())} of {len(used)}; outliers: "
              + (", ".join(str(i) for i in res.outliers) if res.outliers else "none"),
              f"* model error RMS: before {res.rms_mm(True):.4f} mm, after {res.rms_mm():.4f} mm; "
              f"max |error| after {np.max(np.abs(res.residuals_m[used])) * 1e3:.4f} mm",
              f"* iterations: {res.iterations}" + ("" if res.converged else " (not converged)")]
    return "\n".join(lines) + "\n"


def identifiability_markdown(res) -> str:
    ident = res.identifiability
    lines = ["# Identifiability", ""]
    obs = asdict(ident.observability)
    lines.append(f"* sigma {ident.sigma_mm:.4g} mm, scaled condition number "
                 f"{ident.condition_number_scaled:.4g}, "
                 + ", ".join(f"{k} {v:.3g}" for k, v in obs.items()))
    if ident.weighted:
        lines.append(f"* weighted by the repeatability noise model, variance factor "
                     f"{ident.variance_factor:.3g}")
    warnings = []
    for d in ident.unidentifiable_directions:
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in d.items())
        warnings.append(f"**not identifiable**: {', '.join(d)} move together without "
                        f"changing any distance (direction {mix})")
    for w in ident.weak_directions:
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in w.direction.items())
        warnings.append(f"**weakly identifiable** (scaled singular value ratio "
                        f"{w.scaled_singular_ratio:.2e}): {mix}")
    for pr in ident.correlated_pairs:
        warnings.append(f"**strongly correlated**: {pr.a} ~ {pr.b} (rho {pr.rho:+.4f})")
    warnings += [f"note: {n}" for n in res.notes]
    lines += [""] + ([f"* WARNING {w}" for w in warnings] if warnings else ["No warnings."])
    return "\n".join(lines) + "\n"


def log_fit(rec, res, samples, scene) -> None:
    """Log a ``fit.Result`` and its data set (``Samples``: qe, d_mm, plate) to ``rec``."""
    rr = _rr()
    robot = scene.robot
    # convergence (timeline "iteration"): RMS and max |model error| of the samples used
    it = np.array([h.iteration for h in res.history], np.int64)
    idx = [rr.TimeColumn("iteration", sequence=it)]
    for path, vals in (("/fit/rms_mm", [h.rms_m for h in res.history]),
                       ("/fit/max_mm", [h.max_m for h in res.history])):
        rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(
            scalars=np.array(vals, float) * 1e3))
    rec.send_columns("/fit/samples_used", indexes=idx, columns=rr.Scalars.columns(
        scalars=np.array([h.samples for h in res.history], float)))
    # histograms (static): all samples, outliers included
    data = {"error_before": np.asarray(res.initial_residuals_m) * 1e3,
            "error_after": np.asarray(res.residuals_m) * 1e3,
            "distance": np.asarray(samples.d_mm, float)}
    colors = {"error_before": (200, 80, 60), "error_after": (60, 140, 200),
              "distance": (120, 120, 120)}
    for key, path in HIST_ENTITIES.items():
        counts, edges = histogram(data[key])
        rec.log(path, rr.BarChart(counts.astype(np.int64), abscissa=0.5 * (edges[:-1] + edges[1:]),
                                  widths=np.diff(edges).astype(np.float32), color=colors[key]),
                rr.AnyValues(bin_edges_mm=edges), static=True)
    rec.log("/fit/parameters", rr.TextDocument(parameter_markdown(res), media_type="text/markdown"),
            static=True)
    rec.log("/fit/identifiability", rr.TextDocument(identifiability_markdown(res),
                                                    media_type="text/markdown"), static=True)
    # the cell on the identified planes, hit points with the identified parameters
    planes = res.params.planes if res.params.n_planes == len(scene.plates) else None
    log_cell(rec, scene, planes)
    qe = np.asarray(samples.qe)
    o_b, z_b = sensor_in_base(robot, counts_to_joints(robot, qe), res.params)
    p = o_b + (np.asarray(samples.d_mm, float) * 1e-3)[:, None] * z_b
    e_after = data["error_after"]
    rec.log("/samples/points",
            rr.Points3D(p, colors=diverging_colors(e_after), radii=SAMPLE_RADIUS_M),
            rr.AnyValues(error_mm=e_after, error_before_mm=data["error_before"],
                         used=np.asarray(res.used, bool), plate=np.asarray(samples.plate)),
            static=True)


def log_fit_to_file(arg, res, samples, scene):
    """Write the fit's recording; ``arg`` as for ``recording_path`` (command "calibrate").
    Returns the path written."""
    path = recording_path(arg, "calibrate", scene.name)
    rec = open_recording(path, fit_blueprint(scene), name=f"calibrate {scene.name}")
    try:
        log_fit(rec, res, samples, scene)
    finally:
        close_recording(rec)
    return path
