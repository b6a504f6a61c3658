"""The Rerun view of a twin-against-real comparison (``planecal compare --rrd``), from its
verdict document: the cell with both runs' hit points (the rehearsal's small and blue,
the run's coloured by its difference, blue-grey-red), the robot at the first pose, and on
a ``sample`` timeline the two runs' distances overlaid, their difference with the noise
band and what the named parameters explain; the verdict in the info panel. Entity paths:
docs/RERUN.md."""
from __future__ import annotations

import numpy as np

from planecal.present.rerun.common import (_rr, close_recording, diverging_colors,
                                           error_legend, hit_columns, lifted, log_info,
                                           log_pose_set, open_recording, recording_path,
                                           sample_points)

RUN_RGBA = (215, 50, 40, 255)
REHEARSAL_RGBA = (40, 110, 220, 255)
BAND_RGBA = (150, 150, 150, 255)
FIT_RGBA = (40, 170, 60, 255)
REHEARSAL_RADIUS_M = 0.0022


def compare_blueprint(scene, eye):
    import rerun.blueprint as rrb

    from planecal.present.rerun.common import eye_controls, whole_range
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(name="cell: run (coloured by difference) and rehearsal (blue)",
                              origin="/", eye_controls=eye or eye_controls(scene),
                              contents=["/cell/**", "/robot/**", "/laser/**", "/samples/**",
                                        "/rehearsal/**"]),
            rrb.Vertical(
                rrb.TimeSeriesView(name="distance per sample [mm]: run and rehearsal",
                                   origin="/series/distance_mm",
                                   time_ranges=whole_range("sample")),
                rrb.TimeSeriesView(name="difference run - rehearsal [mm], noise band, explained",
                                   origin="/series/difference_mm",
                                   time_ranges=whole_range("sample")),
                rrb.TextDocumentView(name="verdict and legend", origin="/compare/info"),
                row_shares=[2, 2, 2]),
            column_shares=[3, 2]),
        rrb.TimePanel(timeline="sample", play_state="following"),
        collapse_panels=False)


def _info(doc: dict, scale_mm: float) -> str:
    t = doc["test"]
    expl = doc.get("explanation")
    lines = [f"# {doc['verdict'].upper()}: run `{doc['run']}` against rehearsal "
             f"`{doc['rehearsal']}`",
             f"* chi-square test: sum z^2 = {t['chi2']:.1f} on {t['dof']} samples, "
             f"p = {t['p_value']:.3g} (alpha {t['alpha']:g}); exit {doc['exit_code']}",
             f"* mean difference {doc['mean_difference_mm']:+.4f} mm, RMS "
             f"{doc['rms_difference_mm']:.4f} mm; paired t p = {doc['paired_t_test_p']:.3g}",
             f"* samples beyond the band: "
             f"{', '.join(map(str, doc['flagged_samples'])) or 'none'}"]
    if expl:
        from planecal.present.drift import in_display
        parts = []
        for q in expl["parameters"]:
            v, unit = in_display(q["name"], q["amount"])
            parts.append(f"{q['label']} {v} {unit}")
        lines.append("* explained by: " + "; ".join(parts))
    lines += ["", error_legend(scale_mm, "the run's difference from the rehearsal"),
              "* small blue spheres: the rehearsal's hit points at the same poses",
              "* series: red the run, blue the rehearsal; grey the noise band "
              f"(±{doc['z_limit']:.2f} σ), green what the named parameters explain"]
    return "\n".join(lines)


def log_compare(path, doc: dict, scene, params) -> str:
    """Write the recording (module docstring) of a compare verdict ``doc``; the path."""
    rr = _rr()
    p = recording_path(path, "compare", scene.name)
    s = doc["samples"]
    qe = _counts(doc, scene)
    run = np.array([x["run_mm"] for x in s]) * 1e-3
    reh = np.array([x["rehearsal_mm"] for x in s]) * 1e-3
    plate = np.array([x["plate"] - 1 for x in s], int)
    diff = np.array([x["difference_mm"] for x in s])
    scale = max(float(np.max(np.abs(diff))), 1e-6)
    rec = open_recording(p, compare_blueprint(scene, None), name=f"compare {scene.name}")
    try:
        log_pose_set(rec, scene, params, qe, run, plate, diverging_colors(diff, scale),
                     extra={"difference_mm": diff})
        hp, hn = sample_points(scene, params, qe, reh, plate)
        rec.log("/rehearsal/points", rr.Points3D(lifted(hp, hn, REHEARSAL_RADIUS_M),
                                                 colors=REHEARSAL_RGBA,
                                                 radii=REHEARSAL_RADIUS_M),
                rr.AnyValues(**hit_columns(hp)), static=True)
        log_info(rec, "/compare/info", _info(doc, scale))
        _series(rec, doc)
    finally:
        close_recording(rec)
    return str(p)


def _counts(doc: dict, scene) -> np.ndarray:
    """The poses' counts: read back from the rehearsal's sample file the document names."""
    from planecal.io.samples import read_samples
    return read_samples(doc["rehearsal"], scene).qe


def _series(rec, doc: dict) -> None:
    rr = _rr()
    s = doc["samples"]
    k = np.array([x["sample"] for x in s], np.int64)
    idx = [rr.TimeColumn("sample", sequence=k)]

    def series(path, values, color, name, points=True):
        style = (rr.SeriesPoints(colors=[color], names=[name], marker_sizes=[3.0]) if points
                 else rr.SeriesLines(colors=[color], names=[name]))
        rec.log(path, style, static=True)
        rec.send_columns(path, indexes=idx,
                         columns=rr.Scalars.columns(scalars=np.asarray(values, float)))

    series("/series/distance_mm/run", [x["run_mm"] for x in s], RUN_RGBA, "run")
    series("/series/distance_mm/rehearsal", [x["rehearsal_mm"] for x in s], REHEARSAL_RGBA,
           "rehearsal")
    lim = doc["z_limit"]
    band = np.array([x["sigma_mm"] for x in s]) * lim
    series("/series/difference_mm/difference", [x["difference_mm"] for x in s], RUN_RGBA,
           "run - rehearsal")
    series("/series/difference_mm/band_high", band, BAND_RGBA, f"+{lim:.2f} sigma", False)
    series("/series/difference_mm/band_low", -band, BAND_RGBA, f"-{lim:.2f} sigma", False)
    if doc.get("explanation"):
        series("/series/difference_mm/explained", [x["explained_mm"] for x in s], FIT_RGBA,
               "explained", False)
