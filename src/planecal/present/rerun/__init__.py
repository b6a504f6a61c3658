"""Rerun recordings of planecal: sampling runs (twin rehearsal or real cell, one logger)
and the optimizer. The entity tree and timelines are documented in docs/RERUN.md.

    obs = sampling_observer("recordings/", scene, twin=twin)   # an Observer; obs.path
    ... run the sampling loop with it ...; obs.close()
    path = log_fit_to_file("recordings/", fit_result, samples, scene)
    log_montecarlo / log_bootstrap / log_validate (planecal.present.rerun.studies)

Each recording kind has a blueprint of its own (docs/RERUN.md, docs/img/rerun-*.png);
``blueprint_views(path)`` reads one back.

Everything is written headless to an .rrd file (``rec.save``) with a default blueprint;
no viewer is ever spawned here (``planecal view FILE`` opens one).
"""
from planecal.present.rerun.common import (KINDS, blueprint_views, close_recording,
                                       diverging_colors, is_recording, log_cell,
                                       log_robot_meshes, open_recording, recording_path,
                                       sequential_colors, summarize)
from planecal.present.rerun.fit import (HIST_BINS, HIST_ENTITIES, fit_blueprint, histogram,
                                    identifiability_markdown, log_fit, log_fit_to_file,
                                    parameter_markdown)
from planecal.present.rerun.sampling import (DEFAULT_EVERY, SamplingObserver, reject_kind,
                                         sampling_blueprint, sampling_observer)
from planecal.present.rerun.studies import (PoseSet, log_bootstrap, log_montecarlo, log_validate,
                                        order_pose_set)

__all__ = ["recording_path", "open_recording", "close_recording", "is_recording", "summarize",
           "log_cell", "log_robot_meshes", "diverging_colors", "sampling_observer",
           "SamplingObserver", "sampling_blueprint", "reject_kind", "DEFAULT_EVERY",
           "log_fit", "log_fit_to_file", "fit_blueprint", "histogram", "HIST_BINS",
           "HIST_ENTITIES", "parameter_markdown", "identifiability_markdown", "KINDS",
           "blueprint_views", "sequential_colors", "log_montecarlo", "log_bootstrap",
           "log_validate", "PoseSet", "order_pose_set"]
