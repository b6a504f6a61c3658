"""Recordings of the studies (``--rrd`` on montecarlo, bootstrap, validate), each with a
blueprint of its own: a 3D view of the cell with the samples the study is about (the
robot and its beam at one of them), the study's info panel with the colour legend, and
every chart laid out (a grid), bar charts on value axes (bin centres and widths).

Terminal tables and JSON carry every number; the recordings are for looking. Entity
paths: docs/RERUN.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planecal.present.rerun.common import (_rr, close_recording, diverging_colors, error_legend,
                                       eye_controls, log_info, log_pose_set, open_recording,
                                       pose_eye, recording_path, sequential_colors)

Z_BINS = np.linspace(-4, 4, 17)  # normalised errors: 16 bins of 0.5 sigma
OBSERVED_RGBA = (90, 150, 220, 255)
EXPECTED_RGBA = (240, 200, 60, 255)


@dataclass
class PoseSet:
    """Samples to show in a study's 3D view: encoder counts (N,6), distances [m], plate
    indices, the parameters that place the cell and the robot, a colour per sample and
    the markdown legend of those colours."""
    qe: np.ndarray
    d_m: np.ndarray
    plate: np.ndarray
    params: object  # CellParams
    colors: np.ndarray
    legend: str
    shown: int = 0


def order_pose_set(qe, d_m, plate, params, what: str) -> PoseSet:
    """A pose set coloured by acquisition order (``what`` names the samples)."""
    n = len(d_m)
    return PoseSet(np.asarray(qe), np.asarray(d_m, float), np.asarray(plate, int), params,
                   sequential_colors(np.arange(n), 0, max(n - 1, 1)),
                   f"**sample colour** = order of acquisition of {what}: first dark blue, "
                   f"then purple, orange, last yellow")


def _space_view(rrb, scene, eye, name, extra=()):
    return rrb.Spatial3DView(name=name, origin="/", eye_controls=eye or eye_controls(scene),
                             contents=["/cell/**", "/robot/**", "/laser/**", "/samples/**",
                                       *extra])


def _histogram(rec, path, values, edges, color):
    rr = _rr()
    v = np.asarray(values, float)
    h, _ = np.histogram(v[np.isfinite(v)], edges)
    rec.log(path, rr.BarChart(h.astype(float), abscissa=0.5 * (edges[1:] + edges[:-1]),
                              widths=np.diff(edges).astype(np.float32), color=color),
            static=True)


def _expected(rec, path, counts, edges):
    """Expected counts per bin, drawn as narrower bars inside the observed ones."""
    rr = _rr()
    rec.log(path, rr.BarChart(np.asarray(counts, float),
                              abscissa=0.5 * (edges[1:] + edges[:-1]),
                              widths=(0.4 * np.diff(edges)).astype(np.float32),
                              color=EXPECTED_RGBA), static=True)


def _pose_part(rec, scene, poses: PoseSet | None):
    if poses is None or scene is None or not len(poses.d_m):
        return None
    return log_pose_set(rec, scene, poses.params, poses.qe, poses.d_m, poses.plate,
                        poses.colors, shown=poses.shown)


# ----- Monte Carlo -------------------------------------------------------------------------

def montecarlo_blueprint(names, scene=None, eye=None, chi2=False, slope_names=()):
    import rerun.blueprint as rrb

    no_legend = rrb.PlotLegend(visible=False)  # the tab's title says which bars are which
    charts = [rrb.BarChartView(name=f"{n}: (fit - truth) / CRB std (grid: 1 per std)",
                               origin=f"/normalized_error/{n}",
                               plot_legend=no_legend)
              for n in names]
    tabs = [rrb.Grid(*charts, grid_columns=2, name="normalised errors (blue) vs N(0,1) (yellow)")]
    if chi2:
        tabs.append(rrb.BarChartView(name="chi-square of the offsets (blue) vs chi2(k) (yellow)",
                                     origin="/chi2", plot_legend=no_legend))
    if slope_names:
        tabs.append(rrb.Grid(*[rrb.TimeSeriesView(name=f"{n}: log10 spread vs samples",
                                                  origin=f"/log10_spread/{n}")
                               for n in slope_names], name="spread vs samples (log10)"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(_space_view(rrb, scene, eye, "Monte Carlo: cell and run 0's samples"),
                         rrb.TextDocumentView(name="Monte Carlo info and legend",
                                              origin="/info"),
                         row_shares=[3, 2]),
            rrb.Tabs(*tabs, active_tab=0),
            column_shares=[1, 2]),
        rrb.TimePanel(timeline="samples", state="collapsed") if slope_names else
        rrb.TimePanel(state="collapsed"),
        collapse_panels=False)


def log_montecarlo(path_arg, res: dict, scene=None, poses: PoseSet | None = None):
    """The Monte Carlo recording: per free parameter the histogram of the run errors over
    that run's Cramer-Rao std with the standard normal's expected counts; the offsets'
    chi-square values against chi2(k); with a slope study log10 of the empirical and CR
    spread on a ``samples`` timeline; the cell with ``poses`` (e.g. run 0's samples)."""
    import rerun as rr
    from scipy import stats

    scene_name = res["settings"]["scene"]
    path = recording_path(path_arg, "montecarlo", scene_name)
    names = list(res["free"])
    c = res.get("chi2_offsets_reported")
    has_chi2 = bool(c and c.get("values"))
    sl = res.get("slope")
    slope_names = list(sl["slopes"]) if sl else []
    eye = None if poses is None or scene is None or not len(poses.d_m) else \
        pose_eye(scene, poses.params, poses.qe[poses.shown])
    rec = open_recording(path, montecarlo_blueprint(names, scene, eye, has_chi2, slope_names),
                         name=f"montecarlo {scene_name}")
    try:
        E = np.asarray(res.get("run_errors", []))
        C = np.asarray(res.get("run_crb_std", []))
        runs = len(E)
        expect = runs * np.diff(stats.norm.cdf(Z_BINS))
        for i, n in enumerate(names):
            if E.size:
                _histogram(rec, f"/normalized_error/{n}/observed", E[:, i] / C[:, i], Z_BINS,
                           OBSERVED_RGBA)
                _expected(rec, f"/normalized_error/{n}/expected_normal", expect, Z_BINS)
        if has_chi2:
            edges = np.linspace(0, max(20.0, max(c["values"])), 41)
            _histogram(rec, "/chi2/observed", c["values"], edges, OBSERVED_RGBA)
            _expected(rec, "/chi2/expected", len(c["values"]) * np.diff(
                stats.chi2.cdf(edges, c["dof"])), edges)
        if sl:
            for row in sl["rows"]:
                rec.set_time("samples", sequence=int(row["samples"]))
                for n in sl["slopes"]:
                    rec.log(f"/log10_spread/{n}/empirical",
                            rr.Scalars(np.log10(row[n]["empirical_std"])))
                    rec.log(f"/log10_spread/{n}/crb", rr.Scalars(np.log10(row[n]["crb_std"])))
        _pose_part(rec, scene, poses)
        st = res["settings"]
        log_info(rec, "/info", "\n".join([
            f"# Monte Carlo, scene `{scene_name}`", "",
            f"* {runs} runs of {st.get('samples', '?')} samples, mode {st.get('mode', '?')}, "
            f"errors {st.get('errors', '?')}",
            "* charts: per free parameter the histogram of (fit - truth) / Cramer-Rao std "
            "over the runs, 16 bins of 0.5 from -4 to 4 (blue), and the counts a standard "
            "normal gives (narrow yellow bars); x = normalised error, y = runs",
            *(["* chi-square tab: the offsets' chi-square values (blue) vs chi2(k) "
               f"(k = {c['dof']}, yellow)"] if has_chi2 else []),
            *(["* slope tab: log10 of the empirical (`empirical`) and Cramer-Rao (`crb`) "
               "spread against the sample count (timeline `samples`)"] if sl else []),
            *([f"* 3D: {poses.legend}; robot and green beam at sample {poses.shown}"]
              if poses is not None else []),
        ]) + "\n")
    finally:
        close_recording(rec)
    return path


# ----- bootstrap ---------------------------------------------------------------------------

def bootstrap_blueprint(names, scene=None, eye=None):
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(_space_view(rrb, scene, eye, "bootstrap: the pool of samples"),
                         rrb.TextDocumentView(name="bootstrap info and legend", origin="/info"),
                         row_shares=[3, 2]),
            rrb.Grid(*[rrb.TimeSeriesView(name=f"{n}: spread vs subset size",
                                          origin=f"/spread/{n}") for n in names],
                     name="spread per parameter"),
            column_shares=[2, 3]),
        rrb.TimePanel(timeline="subset_size", state="collapsed"),
        collapse_panels=False)


def log_bootstrap(path_arg, res: dict, scene=None, pool=None):
    """The bootstrap recording: per free parameter the subset spread (corrected to
    independent sets) and the fits' reported std on a ``subset_size`` timeline, one chart
    each; the pool (``studies.bootstrap.Pool``) in 3D, coloured by the model error with the
    parameters of the whole pool's fit (``res["pool_fit"]``)."""
    import rerun as rr

    from planecal.model.cell_params import CellParams
    from planecal.model.measurement import predict

    path = recording_path(path_arg, "bootstrap", "pool" if scene is None else scene.name)
    names = list(res["free"])
    poses = None
    fit = res.get("pool_fit")
    if pool is not None and scene is not None and fit and fit.get("x") is not None:
        params = CellParams.from_vector(np.asarray(fit["x"], float), pool.layout)
        e = (predict(pool.robot, pool.qe, params, pool.plate) - pool.d_m) * 1e3
        scale = max(float(np.max(np.abs(e))), 1e-3)
        poses = PoseSet(pool.qe, pool.d_m, pool.plate, params,
                        diverging_colors(e, scale),
                        error_legend(scale, "model error with the parameters of a fit of "
                                            "the whole pool"))
    eye = None if poses is None else pose_eye(scene, poses.params, poses.qe[poses.shown])
    rec = open_recording(path, bootstrap_blueprint(names, scene, eye),
                         name="bootstrap" if scene is None else f"bootstrap {scene.name}")
    try:
        for n in names:  # the same colours in every chart
            rec.log(f"/spread/{n}/subsets_independent",
                    rr.SeriesLines(colors=OBSERVED_RGBA, widths=2), static=True)
            rec.log(f"/spread/{n}/fit_reported", rr.SeriesLines(colors=EXPECTED_RGBA, widths=2),
                    static=True)
        for e in res["sizes"]:
            rec.set_time("subset_size", sequence=int(e["size"]))
            for n, v in e["params"].items():
                if np.isfinite(v["std_independent"]):
                    rec.log(f"/spread/{n}/subsets_independent", rr.Scalars(v["std_independent"]))
                if v["reported_std"] is not None:
                    rec.log(f"/spread/{n}/fit_reported", rr.Scalars(v["reported_std"]))
        _pose_part(rec, scene, poses)
        log_info(rec, "/info", "\n".join([
            "# Bootstrap", "",
            f"* pool of {res['pool']} samples; {res['repeats']} random subsets per size "
            f"({', '.join(str(e['size']) for e in res['sizes'])})",
            "* charts: per free parameter, against the subset size (x), the std of the "
            "identified value over the subsets corrected to independent sets "
            "(`subsets_independent`, blue) and the std the fits report (`fit_reported`, "
            "yellow), in SI "
            "units (m, rad, 1/m)",
            *([f"* 3D: {poses.legend}; robot and green beam at sample {poses.shown}"]
              if poses is not None else []),
        ]) + "\n")
    finally:
        close_recording(rec)
    return path


# ----- validate ----------------------------------------------------------------------------

AP_SCALE = 100.0  # AP vectors drawn 100x longer


def validate_blueprint(scene=None, eye=None):
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(_space_view(rrb, scene, eye,
                                     "validate: ISO poses, AP vectors x100, calibration samples",
                                     extra=["/iso/**"]),
                         rrb.TextDocumentView(name="validation info and legend", origin="/info"),
                         row_shares=[3, 2]),
            rrb.Vertical(
                rrb.BarChartView(name="AP at the tool point per ISO pose P1..P5 [mm]: nominal "
                                      "(red), calibrated (blue), true model (green)",
                                 origin="/ap"),
                rrb.BarChartView(name="RP at the tool point per ISO pose P1..P5 [mm]",
                                 origin="/rp"),
                rrb.BarChartView(name="gauge block length error [mm]: nominal, calibrated, "
                                      "calibrated sensor + nominal offsets", origin="/gauge",
                                 plot_legend=rrb.PlotLegend(visible=False))),
            column_shares=[3, 2]),
        rrb.TimePanel(state="collapsed"),
        collapse_panels=False)


MODEL_RGBA = {"nominal": (220, 70, 60, 255), "oracle": (60, 170, 70, 255)}
CALIBRATED_RGBA = (70, 140, 230, 255)  # every calibrated level


def log_validate(path_arg, v: dict, scene, calibrated, qe=None, d_m=None, plate=None):
    """The validation recording: the ISO 9283 poses P1..P5 (tool points) and their AP
    vectors at the tool point (from the pose to the barycentre of the attained tool
    points, 100x) for every model (nominal, each calibrated level, the twin's own true
    model); AP and RP at the tool point and the gauge-block errors as bar charts; the
    calibration's samples (``qe``, ``d_m``, ``plate``) on the plate with the calibrated
    parameters."""
    import rerun as rr

    path = recording_path(path_arg, "validate", scene.name)
    poses = None
    if qe is not None and d_m is not None and len(d_m):
        poses = order_pose_set(qe, d_m, plate, calibrated, "the calibration samples")
    eye = None if poses is None else pose_eye(scene, calibrated, poses.qe[0])
    rec = open_recording(path, validate_blueprint(scene, eye), name=f"validate {scene.name}")
    try:
        iso = v["iso"]
        P = np.asarray(iso["points_m"], float)
        rec.log("/iso/poses", rr.Points3D(P, radii=0.006, colors=(255, 255, 255),
                                          labels=[f"P{i + 1}" for i in range(len(P))],
                                          show_labels=True), static=True)
        x = np.arange(1, len(P) + 1, dtype=float)
        w = 0.8 / len(iso["models"])
        for k, (model, m) in enumerate(iso["models"].items()):
            col = MODEL_RGBA.get(model, CALIBRATED_RGBA)
            name = rr.escape_entity_path_part(model)  # "full + compliance", "floor: offsets"
            tool = m["tool"]
            ap = np.asarray(tool["ap_xyz_mm"], float) * 1e-3
            rec.log(f"/iso/ap_x100/{name}", rr.Arrows3D(origins=P, vectors=AP_SCALE * ap,
                                                        colors=col, radii=0.002), static=True)
            at = x + (k - (len(iso["models"]) - 1) / 2) * w
            rec.log(f"/ap/{name}", rr.BarChart(np.asarray(tool["ap_mm"], float), abscissa=at,
                                               widths=np.full(len(x), w, np.float32),
                                               color=col), static=True)
            rec.log(f"/rp/{name}", rr.BarChart(np.asarray(tool["rp_mm"], float), abscissa=at,
                                               widths=np.full(len(x), w, np.float32),
                                               color=col), static=True)
        g = [v.get("gauge_error_before_mm"), v.get("gauge_error_after_mm"),
             v.get("gauge_error_offsets_only_mm")]
        g = np.array([np.nan if a is None else float(a) for a in g])
        rec.log("/gauge", rr.BarChart(g, abscissa=np.arange(1.0, 4.0),
                                      widths=np.full(3, 0.6, np.float32),
                                      color=(160, 160, 160, 255)), static=True)
        _pose_part(rec, scene, poses)
        log_info(rec, "/info", "\n".join([
            f"# Validation (ISO 9283, gauge block), scene `{scene.name}`", "",
            f"* AP at the tool point (max over P1..P5, robot frame): nominal "
            f"**{v['ap_before_tool_mm']:.4f} mm**, calibrated ({v['model_after']}) "
            f"**{v['ap_after_tool_mm']:.4f} mm**, the twin's own true model "
            f"{v['ap_oracle_tool_mm']:.4f} mm; at the flange {v['ap_before_flange_mm']:.4f}, "
            f"{v['ap_after_flange_mm']:.4f}, {v['ap_oracle_flange_mm']:.4f} mm; RP "
            f"{v['rp_after_tool_mm']:.4f} mm",
            f"* gauge block error: nominal {g[0]:+.4f} mm, calibrated {g[1]:+.4f} mm, "
            f"calibrated sensor with nominal offsets {g[2]:+.4f} mm",
            "* 3D: white spheres P1..P5 = the ISO poses (tool points); arrows = AP vectors "
            f"(pose -> barycentre of the attained tool points) drawn {AP_SCALE:g}x: red "
            "nominal model, blue calibrated (each level, and each level's floor), green the "
            "twin's whole true model",
            *([f"* {poses.legend}; robot and green beam at the first sample (calibrated "
               f"parameters)"] if poses is not None else []),
            "* bar charts: x = pose number 1..5 (AP, RP) or 1 nominal, 2 calibrated, "
            "3 calibrated sensor + nominal offsets (gauge); y = mm",
        ]) + "\n")
    finally:
        close_recording(rec)
    return path
