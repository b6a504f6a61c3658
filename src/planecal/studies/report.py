"""Plots of the studies, as Rerun recordings (``--rrd``): matplotlib is not a dependency
and Rerun (``planecal.rerun_log``) is, so the plots a person would rather look at go to an
.rrd file (``planecal view FILE``):

* Monte Carlo: per free parameter a histogram (BarChart) of the run errors normalised by
  that run's Cramer-Rao std (should look standard normal), the chi-square values of the
  offsets against the chi2(k) density, and with ``--slope`` the empirical and CR spread
  on a ``samples`` timeline (log10 values, the N^-1/2 line has slope -0.5).
* Bootstrap: per parameter the subset spread (independent-corrected) and the fits'
  reported std on a ``subset_size`` timeline.
Terminal tables and JSON carry every number; the recordings are for looking.
"""
from __future__ import annotations

import numpy as np

BINS = np.linspace(-4, 4, 33)


def _open(path_arg, command, scene_name):
    from planecal.rerun_log.common import open_recording, recording_path
    path = recording_path(path_arg, command, scene_name)
    return open_recording(path, name=f"planecal {command}"), path


def log_montecarlo(path_arg, res: dict):
    import rerun as rr
    from scipy import stats

    from planecal.rerun_log.common import close_recording
    rec, path = _open(path_arg, "montecarlo", res["settings"]["scene"])
    E = np.asarray(res.get("run_errors", []))
    C = np.asarray(res.get("run_crb_std", []))
    for i, n in enumerate(res["free"]):
        if E.size:
            h, _ = np.histogram(E[:, i] / C[:, i], BINS)
            rec.log(f"normalized_error/{n}", rr.BarChart(h.astype(float)), static=True)
    c = res.get("chi2_offsets_reported")
    if c and c.get("values"):
        edges = np.linspace(0, max(20.0, max(c["values"])), 41)
        h, _ = np.histogram(c["values"], edges)
        rec.log("chi2/offsets_observed", rr.BarChart(h.astype(float)), static=True)
        mid = (edges[1:] + edges[:-1]) / 2
        expect = stats.chi2.pdf(mid, c["dof"]) * len(c["values"]) * (edges[1] - edges[0])
        rec.log("chi2/offsets_expected", rr.BarChart(expect), static=True)
    sl = res.get("slope")
    if sl:
        for row in sl["rows"]:
            rec.set_time("samples", sequence=int(row["samples"]))
            for n in sl["slopes"]:
                rec.log(f"log10_spread/{n}/empirical", rr.Scalars(np.log10(row[n]["empirical_std"])))
                rec.log(f"log10_spread/{n}/crb", rr.Scalars(np.log10(row[n]["crb_std"])))
    close_recording(rec)
    return path


def log_bootstrap(path_arg, res: dict):
    import rerun as rr

    from planecal.rerun_log.common import close_recording
    rec, path = _open(path_arg, "bootstrap", "pool")
    for e in res["sizes"]:
        rec.set_time("subset_size", sequence=int(e["size"]))
        for n, v in e["params"].items():
            if np.isfinite(v["std_independent"]):
                rec.log(f"spread/{n}/subsets_independent", rr.Scalars(v["std_independent"]))
            if v["reported_std"] is not None:
                rec.log(f"spread/{n}/fit_reported", rr.Scalars(v["reported_std"]))
    close_recording(rec)
    return path
