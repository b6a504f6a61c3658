"""The optimizer's recording (seed 7.3.2's graphs): convergence per iteration, model error
histograms before and after, the distance distribution, the parameter table with
standard deviations and the identifiability warnings; plus the cell on the identified
planes and the sample hit points coloured by their final model error."""
from __future__ import annotations

import numpy as np

from planecal.present.rerun.common import (_rr, close_recording, diverging_colors, error_legend,
                                       eye_controls, log_info, log_pose_set, open_recording,
                                       pose_eye, recording_path)

LOG_FLOOR_MM = 1e-15  # log10 plot: an exact 0 is drawn at -15 (1e-18 m, far below rounding)
HIST_BINS = 20  # equal-width bins from the smallest to the largest value (numpy.histogram)
HIST_ENTITIES = {"error_before": "/fit/hist/error_before", "error_after": "/fit/hist/error_after",
                 "distance": "/fit/hist/distance"}


def histogram(values_mm: np.ndarray, bins: int = HIST_BINS):
    """(counts, edges) exactly as ``numpy.histogram(values_mm, bins)``: ``bins`` equal
    bins from min to max, the last one closed."""
    v = np.asarray(values_mm, float)
    v = v[np.isfinite(v)]
    return np.histogram(v, bins=bins)


def hist_ranges(res, samples) -> dict:
    """The value range of each histogram, for the view titles: {key: (lo, hi)} in mm."""
    data = {"error_before": np.asarray(res.initial_residuals_m) * 1e3,
            "error_after": np.asarray(res.residuals_m) * 1e3,
            "distance": np.asarray(samples.d_mm, float)}
    out = {}
    for k, v in data.items():
        v = v[np.isfinite(v)]
        if v.size:
            out[k] = (float(v.min()), float(v.max()))
    return out


def fit_blueprint(scene=None, eye=None, ranges: dict | None = None):
    """The calibration's blueprint: the 3D view framing the first plate and the tool
    (``eye``: ``common.pose_eye`` of the pose shown; default ``eye_controls(scene)``) over the convergence plot (log10 of
    the model error per iteration); the info panel (legend) over tabs with the parameter
    table and the identifiability report; the three histograms on value axes."""
    import rerun.blueprint as rrb

    no_legend = rrb.PlotLegend(visible=False)  # one series per chart, named in its title

    def title(text, key):
        r = (ranges or {}).get(key)
        return text if r is None else f"{text}: {r[0]:.4g} to {r[1]:.4g}"

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name="calibration: samples by final model error",
                                  origin="/", eye_controls=eye or eye_controls(scene),
                                  contents=["/cell/**", "/robot/**", "/laser/**",
                                            "/samples/**"]),
                rrb.TimeSeriesView(name="convergence: log10(model error / 1 mm) per iteration",
                                   origin="/fit/log10",
                                   plot_legend=rrb.PlotLegend(rrb.Corner2D.RightTop)),
                row_shares=[3, 2]),
            rrb.Vertical(
                rrb.TextDocumentView(name="calibration info and legend", origin="/fit/info"),
                rrb.Tabs(
                    rrb.TextDocumentView(name="parameters", origin="/fit/parameters"),
                    rrb.TextDocumentView(name="identifiability", origin="/fit/identifiability"),
                    active_tab=0),
                row_shares=[1, 3]),
            rrb.Vertical(
                rrb.BarChartView(name=title("model error before [mm]", "error_before"),
                                 origin="/fit/hist/error_before", plot_legend=no_legend),
                rrb.BarChartView(name=title("model error after [mm]", "error_after"),
                                 origin="/fit/hist/error_after", plot_legend=no_legend),
                rrb.BarChartView(name=title("measured distance [mm]", "distance"),
                                 origin="/fit/hist/distance", plot_legend=no_legend),
            ),
            column_shares=[5, 4, 3]),
        rrb.TimePanel(timeline="iteration", state="collapsed"),
        collapse_panels=False)


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.7g}"


def parameter_markdown(doc: dict) -> str:
    """The parameter table of a result document (``present.calibration.parameter_rows``):
    initial value, identified value, std or status, correction, unit."""
    from planecal.present.calibration import parameter_rows
    lines = ["# Identified parameters", "",
             "| parameter | initial | identified | std | correction | unit |",
             "|---|---:|---:|---:|---:|---|"]
    for r in parameter_rows(doc):
        std = (f"{r.std:.3e}" if r.std is not None else "n/a") if r.status == "fitted" \
            else r.status
        x0 = "" if r.initial is None else _fmt(r.initial)
        corr = "" if r.initial is None else f"{r.value - r.initial:.4e}"
        lines.append(f"| {r.name} | {x0} | {_fmt(r.value)} | {std} | {corr} | {r.unit} |")
    used, outl = doc.get("samples_used", 0), doc.get("outliers") or []
    lines += ["",
              f"* samples used: {used} of {used + len(outl)}; outliers: "
              + (", ".join(str(i) for i in outl) if outl else "none"),
              f"* model error RMS: before {doc['residual_rms_initial_mm']:.4f} mm, after "
              f"{doc['residual_rms_mm']:.4f} mm; max |error| after "
              f"{doc['residual_max_mm']:.4f} mm",
              f"* iterations: {doc['iterations']}"
              + ("" if doc.get("converged") else " (not converged)")]
    return "\n".join(lines) + "\n"


def identifiability_markdown(doc: dict) -> str:
    """The findings of a result document (``present.calibration.findings``)."""
    from planecal.present.calibration import findings
    lines = ["# Identifiability", ""]
    fs = findings(doc)
    lines += [("* WARNING " if f.warning else "* ") + f.text for f in fs]
    if not any(f.warning for f in fs):
        lines.append("No warnings.")
    return "\n".join(lines) + "\n"


def log_fit(rec, cal, samples, scene) -> None:
    """Log a calibration (``estimation.calibrate.Calibration``) and its data set
    (``Samples``: qe, d_mm, plate) to ``rec``."""
    from planecal.present.calibration import document
    rr = _rr()
    res = cal.result
    doc = document(cal)
    # convergence (timeline "iteration"): RMS and max |model error| of the samples used
    it = np.array([h.iteration for h in res.history], np.int64)
    idx = [rr.TimeColumn("iteration", sequence=it)]
    for path, vals in (("/fit/rms_mm", [h.rms_m for h in res.history]),
                       ("/fit/max_mm", [h.max_m for h in res.history])):
        rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(
            scalars=np.array(vals, float) * 1e3))
    for path, vals in (("/fit/log10/rms", [h.rms_m for h in res.history]),
                       ("/fit/log10/max", [h.max_m for h in res.history])):
        rec.send_columns(path, indexes=idx, columns=rr.Scalars.columns(
            scalars=np.log10(np.maximum(np.array(vals, float) * 1e3, LOG_FLOOR_MM))))
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
    rec.log("/fit/parameters", rr.TextDocument(parameter_markdown(doc), media_type="text/markdown"),
            static=True)
    rec.log("/fit/identifiability", rr.TextDocument(identifiability_markdown(doc),
                                                    media_type="text/markdown"), static=True)
    # the cell on the identified planes, hit points with the identified parameters, the
    # robot at the first sample used, its beam to the hit
    shown = pose_shown(res)
    e_after = data["error_after"]
    scale = error_scale(e_after[np.asarray(res.used, bool)])
    log_pose_set(rec, scene, res.params, samples.qe, np.asarray(samples.d_mm, float) * 1e-3,
                 samples.plate, diverging_colors(e_after, scale), shown=shown,
                 extra={"error_mm": e_after, "error_before_mm": data["error_before"],
                        "used": np.asarray(res.used, bool)})
    log_info(rec, "/fit/info", fit_info_markdown(res, scale, shown))


def pose_shown(res) -> int:
    """The sample whose pose the 3D view shows: the first one used."""
    used = np.flatnonzero(np.asarray(res.used, bool))
    return int(used[0]) if used.size else 0


def error_scale(e_mm: np.ndarray) -> float:
    """The colour scale of model errors: the largest |error| of the samples used
    (outliers saturate), at least 1 um."""
    e = np.abs(np.asarray(e_mm, float))
    e = e[np.isfinite(e)]
    return max(float(e.max()) if e.size else 0.0, 1e-3)


def fit_info_markdown(res, scale_mm: float, shown: int) -> str:
    return (f"# Calibration\n\n"
            f"* {error_legend(scale_mm, 'model error after calibration (predicted - measured distance, identified parameters)')}; "
            "outliers saturate\n"
            "* spheres sit on the plate face (exact hit points: `hit_x_m`, `hit_y_m`, "
            "`hit_z_m`); plates on the identified planes\n"
            f"* robot and green beam: the pose of sample {shown} (identified parameters)\n"
            f"* model error RMS: before **{res.rms_mm(True):.4f} mm**, after "
            f"**{res.rms_mm():.4f} mm** in {res.iterations} iterations"
            + ("" if res.converged else " (NOT converged)") + "\n"
            "* convergence plot: log10 of the RMS and max |model error| in mm "
            "(-2 = 0.01 mm); histograms: 20 equal bins, x = value [mm], y = samples\n")


def log_fit_to_file(arg, cal, samples, scene):
    """Write a calibration's recording; ``arg`` as for ``recording_path`` (command
    "calibrate"). Returns the path written."""
    res = cal.result
    path = recording_path(arg, "calibrate", scene.name)
    rec = open_recording(path, fit_blueprint(
        scene, pose_eye(scene, res.params, np.asarray(samples.qe)[pose_shown(res)]),
        hist_ranges(res, samples)),
                         name=f"calibrate {scene.name}")
    try:
        log_fit(rec, cal, samples, scene)
    finally:
        close_recording(rec)
    return path
