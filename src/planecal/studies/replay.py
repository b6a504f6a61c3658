"""Replay recorded samples in the twin (twin vs real regression).

The twin is built with its truth = the given parameters and every error source off
(``TwinOptions.exact()``); for each sample the robot is put at the recorded encoder counts
(``Twin.set_counts``) and the MuJoCo ray cast of the laser site gives the twin's distance.
Reported per sample: the measured distance, the twin's ray cast, the analytic model
(``cell.predict`` with the same parameters) and what the ray hit (a plate, a stand, the
floor, nothing). The twin places each plate by the scene's corner and size on the given
plane: where the beam misses the plate (plate too small or placed elsewhere) the ray hits
something else or nothing and that sample is listed as such, not compared.
Summary: mean, std and max |twin - measured| over plate hits (the twin predicts, the
laser measured: predicted - measured, planecal's one sign), and max |twin - analytic| (the
ray cast against a box geom agrees with the analytic plane to ~1e-12 m).

In a world (``replay_world``: a ``twin.world.WorldRef``: an error profile and a truth seed,
or a truth file), the twin's robot is that world's -- its true geometry and gear phases,
the cell (offsets, sensor pose, planes) still the given parameters -- and at each sample's
counts its joints carry the profile's errors at rest (gravity compliance, gear error;
backlash keeps its direction, the noise is off: the replay is deterministic).
``twin - analytic`` is then what the world's errors the model lacks do to each distance,
and ``twin - measured`` compares the real robot with a robot of that class rather than
with the ideal one.
"""
from __future__ import annotations

import numpy as np

from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict
from planecal.base.errors import InputError


def replay_world(scene, params: CellParams, ref):
    """(world, options) of a replay in the world ``ref`` names (``twin.world.WorldRef``;
    module docstring) with the cell of ``params``, the profile's options with the noise off
    (repeatability, quantisation, laser noise)."""
    from dataclasses import replace

    world, opts = ref.build(scene)
    return (replace(world, params=params),
            replace(opts, repeatability_mm=0.0, quantization=False, laser_noise_mm=0.0))


def replay(scene, params: CellParams, qe: np.ndarray, d_mm: np.ndarray,
           plate: np.ndarray | None = None, world=None, options=None) -> dict:
    """The replay (module docstring); ``world``, ``options``: a world of an error profile
    (``replay_world``; None: the ideal twin, truth = ``params``, every error off)."""
    from planecal.twin import Twin, TwinOptions

    qe = np.asarray(qe, np.int64)
    n = len(qe)
    plate = np.zeros(n, int) if plate is None else np.asarray(plate, int)
    if params.n_planes != len(scene.plates):
        raise InputError(f"parameters hold {params.n_planes} plane(s), scene {scene.name} "
                         f"has {len(scene.plates)} plate(s)")
    if n and plate.max() >= params.n_planes:
        raise InputError(f"samples refer to plate {plate.max() + 1}, the parameters hold "
                         f"{params.n_planes} plane(s)")
    if world is None:
        twin = Twin(scene, truth=params, options=TwinOptions.exact())
    else:
        twin = Twin(scene, truth=world, options=options or TwinOptions.exact())
    analytic = predict(scene.robot, qe, params, plate) * 1e3
    margins = edge_margins(scene, params, qe, plate)
    rows = []
    for i in range(n):
        twin.set_counts(qe[i])
        h = twin.hit()
        t_mm = None if h.distance_m is None else h.distance_m * 1e3
        on_plate = h.plate is not None and h.plate == plate[i]
        rows.append({
            "index": i, "measured_mm": float(d_mm[i]), "twin_mm": t_mm,
            "analytic_mm": float(analytic[i]), "hit": h.name or "nothing",
            "on_plate": bool(on_plate), "edge_margin_mm": float(margins[i] * 1e3),
            "twin_minus_measured_mm": None if (t_mm is None or not on_plate) else float(t_mm - d_mm[i]),
            "twin_minus_analytic_mm": None if (t_mm is None or not on_plate) else float(t_mm - analytic[i]),
        })
    hits = [r for r in rows if r["on_plate"]]
    diff = np.array([r["twin_minus_measured_mm"] for r in hits])
    agree = np.array([r["twin_minus_analytic_mm"] for r in hits])
    summary = {
        "samples": n, "plate_hits": len(hits), "misses": n - len(hits),
        "mean_diff_mm": float(diff.mean()) if len(hits) else None,
        "std_diff_mm": float(diff.std(ddof=1)) if len(hits) > 1 else None,
        "max_abs_diff_mm": float(np.max(np.abs(diff))) if len(hits) else None,
        "rms_diff_mm": float(np.sqrt(np.mean(diff ** 2))) if len(hits) else None,
        "max_abs_twin_minus_analytic_mm": float(np.max(np.abs(agree))) if len(hits) else None,
        "min_edge_margin_mm": float(margins.min() * 1e3) if n else None,
    }
    return {"scene": scene.name, "rows": rows, "summary": summary}


def edge_margins(scene, params: CellParams, qe, plate) -> np.ndarray:
    """Distance [m] of each analytic hit point from the nearest edge of its plate as the
    twin places it (negative: outside the plate)."""
    from planecal.model.measurement import plane_distance, sensor_in_base
    from planecal.model.encoder import counts_to_joints

    q = counts_to_joints(scene.robot, qe)
    o_b, z_b = sensor_in_base(scene.robot, q, params)
    n = params.planes[plate]
    d = plane_distance(n, o_b, z_b)
    p = o_b + d[:, None] * z_b
    out = np.empty(len(qe))
    for i in range(len(qe)):
        pl = scene.plates[plate[i]]
        F = pl.frame(params.planes[plate[i]])
        u, v = (p[i] - F[:3, 3]) @ F[:3, 0], (p[i] - F[:3, 3]) @ F[:3, 1]
        out[i] = min(u, pl.size[0] - u, v, pl.size[1] - v)
    return out
