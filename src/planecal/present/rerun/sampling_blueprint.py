"""The blueprint of a sampling run's recording and of its live view (one layout for both:
``present.rerun.sampling`` writes the recording, ``present.rerun.live`` serves it)."""
from __future__ import annotations

from planecal.present.rerun.common import eye_controls, hidden, whole_axis, whole_range


def sampling_blueprint(scene=None, kind: str = "rehearsal"):
    """The blueprint of a sampling run (``kind`` "rehearsal" on the twin or "real"): the 3D
    view framing the first plate and the tool (rejections in /rejected start hidden)
    over an overview of the whole run (laser readings and each sample's model error,
    whole tick range); the run's info panel (legend) over tabs of the detail series and
    the event log."""
    import rerun.blueprint as rrb

    title = "rehearsal on the twin" if kind == "rehearsal" else "real run"
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(name=f"cell: {title}", origin="/",
                                  eye_controls=eye_controls(scene),
                                  contents=["/cell/**", "/robot/**", "/laser/**",
                                            "/samples/**", "/rejected/**"],
                                  overrides=hidden("/rejected")),
                rrb.TimeSeriesView(name="whole run: laser [mm] and sample model error [mm]",
                                   origin="/series",
                                   contents=["/series/laser_mm", "/series/model_error_mm"],
                                   time_ranges=whole_range("tick"), axis_x=whole_axis(),
                                   plot_legend=rrb.PlotLegend(rrb.Corner2D.LeftTop)),
                row_shares=[3, 1]),
            rrb.Vertical(
                rrb.TextDocumentView(name="run info and legend", origin="/run/info"),
                rrb.Tabs(
                    rrb.TimeSeriesView(name="joint angles [deg]", origin="/series/joint_deg",
                                       time_ranges=whole_range("tick")),
                    rrb.TimeSeriesView(name="step counts per tick", origin="/series/steps",
                                       time_ranges=whole_range("tick")),
                    rrb.TimeSeriesView(name="laser [mm]", origin="/series/laser_mm",
                                       time_ranges=whole_range("tick")),
                    rrb.TimeSeriesView(name="model error per sample [mm]",
                                       origin="/series/model_error_mm",
                                       time_ranges=whole_range("tick")),
                    rrb.TextLogView(name="events", origin="/events"),
                    active_tab=0),
                row_shares=[1, 1]),
            column_shares=[3, 2]),
        # "following": a finished recording opens at its end (every sample on the plate)
        rrb.TimePanel(timeline="tick", play_state="following"),
        collapse_panels=False)
