"""Plate layouts (issue 13 item 5): for every subset of 1, 2 and 3 of a scene's plates,
which parameters the samples can identify and how well (the predicted std).

Per subset: ``samples`` collision-free poses of the sampling run's own distribution on those
plates, an equal share per plate (``planning.candidates`` plate by plate, with the full
scene's collision checker, so the other plates still stand in the cell; plate i's draws
are the same in every subset that holds it), the distance Jacobian at the scene's nominal
parameters over the chosen layout (``cell.predict_with_jacobian``: level 1's, or any larger
layout), then the rank test below on the free columns, and the predicted std of the base
set: the unweighted fit's sandwich covariance under the twin's noise model (repeatability
projected per pose + the laser's 100-reading mean; ``planning.predicted_std``, as ``plan``).

Rank test (``rank_test``). The free columns are scaled to unit norm (units and magnitudes
out of the way); the singular values give the rank (s_k / s_0 above ``tol``); a
rank-revealing QR with column pivoting (``scipy.linalg.qr(..., pivoting=True)``) picks
that many columns as the base set, in pivot order. Every other free parameter is excluded
with its reason: ``no_effect`` (its column is zero: it changes no distance) or
``combination`` (its column is, to ``tol``, a combination of the base set's; the
coefficients, unscaled to SI units, by least squares). Which member of a degenerate family
stays in the base set is the pivoting's choice, not a physical statement (delta1 and the
planes' turn about the base axis are one direction; either carries it).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from itertools import combinations

import numpy as np
import scipy.linalg

from planecal.model.cell import predict_with_jacobian
from planecal.base.errors import InputError
from planecal.studies.common import BUFFER_LEN

FORMAT = "planecal-layouts/1"
DEFAULT_TOL = 1e-6


@dataclass(frozen=True)
class RankTest:
    free: list  # the candidate names
    base: list  # the identifiable base set, in layout order
    excluded: dict  # name -> "no_effect" | "combination"
    combinations: dict = field(default_factory=dict)  # excluded name -> {base name: coef}
    rank: int = 0
    singular_ratios: list = field(default_factory=list)  # s_k / s_0, descending
    pivot_order: list = field(default_factory=list)


def rank_test(J: np.ndarray, names: list, tol: float = DEFAULT_TOL) -> RankTest:
    """The base set of the columns of J (N, p) named ``names`` (module docstring)."""
    norms = np.linalg.norm(J, axis=0)
    scale = norms.max() if norms.size else 0.0
    zero = norms <= 1e-12 * max(scale, 1e-300)
    A = J / np.where(zero, 1.0, norms)
    A[:, zero] = 0.0
    s = np.linalg.svd(A, compute_uv=False)
    ratios = s / s[0] if s.size and s[0] > 0 else np.zeros_like(s)
    rank = int(np.sum(ratios > tol))
    _, _, piv = scipy.linalg.qr(A, mode="economic", pivoting=True)
    keep = sorted(piv[:rank])
    base = [names[i] for i in keep]
    excluded, combos = {}, {}
    Jb = J[:, keep]
    for i in piv[rank:]:
        if zero[i]:
            excluded[names[i]] = "no_effect"
            continue
        excluded[names[i]] = "combination"
        coef, *_ = np.linalg.lstsq(Jb, J[:, i], rcond=None)
        big = np.abs(coef) > 1e-9 * np.abs(coef).max()
        combos[names[i]] = {names[k]: float(c) for k, c, b in zip(keep, coef, big) if b}
    return RankTest(list(names), base, excluded, combos, rank, ratios.tolist(),
                    [names[i] for i in piv])


def subscene(scene, plates: tuple):
    """The scene with only the plates ``plates`` (0-based indices), for drawing poses and
    the nominal parameters (the collision checker keeps the whole scene)."""
    return replace(scene, plates=[scene.plates[i] for i in plates],
                   name=f"{scene.name}[{'+'.join(scene.plates[i].name for i in plates)}]")


def subsets(n_plates: int, sizes=(1, 2, 3)) -> list[tuple]:
    return [c for k in sizes if k <= n_plates for c in combinations(range(n_plates), k)]


def layout_study(scene, layout_for, free_names=None, samples: int = 150, seed: int = 0,
                 checker=None, sizes=(1, 2, 3), tol: float = DEFAULT_TOL,
                 repeatability_mm: float | None = None, laser_noise_mm: float = 0.001) -> dict:
    """The study (module docstring). ``layout_for(n_planes) -> ParamLayout``: the model's
    parameters (level 1: ``layout.level1_layout``); ``free_names``: the ``--free`` spec
    (None: the layout's default free set). Returns a dict (``FORMAT``) with a row per
    subset: plates, samples, free, base (identifiable), excluded (with reason and
    combination), rank, predicted std of the base set (SI units) and its ratio to each
    parameter's ``practical_std``."""
    from planecal.model.scene import nominal_params
    from planecal.studies.montecarlo import MCSettings, joint_sigma
    from planecal.studies.planning import candidates, predicted_std

    if samples < 13:
        raise InputError(f"--samples must be at least 13, got {samples}")
    js = joint_sigma(scene.robot, MCSettings(repeatability_mm=repeatability_mm))
    sig_l = laser_noise_mm * 1e-3 / np.sqrt(BUFFER_LEN)
    rows = []
    for subset in subsets(len(scene.plates), sizes):
        sub = subscene(scene, subset)
        layout = layout_for(len(subset))
        free = layout.free_from_names(free_names)
        qe, plate = [], []
        for k, i in enumerate(subset):  # an equal share per plate, drawn plate by plate
            n_k = samples // len(subset) + (k < samples % len(subset))
            c, _, _ = candidates(subscene(scene, (i,)), n_k, seed + 1000 * i, checker)
            if len(c) < n_k:
                raise InputError(f"plate {scene.plates[i].name}: only {len(c)} "
                                 f"collision-free poses for {n_k} samples")
            qe.append(c)
            plate.append(np.full(len(c), k))
        qe, plate = np.vstack(qe), np.concatenate(plate)
        _, J = predict_with_jacobian(scene.robot, qe, nominal_params(sub), plate, layout)
        fnames = layout.names_of(free)
        rt = rank_test(J[:, free], fnames, tol)
        base = layout.mask(rt.base)
        std, _ = predicted_std(J, layout, base, js, sig_l)
        std = dict(zip(rt.base, std.tolist()))
        practical = dict(zip(rt.base, layout.practical_std(rt.base)))
        rows.append({
            "plates": [scene.plates[i].name for i in subset], "plate_indices": list(subset),
            "samples": int(len(qe)), "free": fnames, "base": rt.base, "rank": rt.rank,
            "excluded": [{"parameter": k, "reason": v, "combination": rt.combinations.get(k, {})}
                         for k, v in rt.excluded.items()],
            "std": std,
            "std_over_practical": {k: (std[k] / practical[k] if practical[k] else None)
                                   for k in rt.base},
            "units": {k: layout.param(k).unit for k in rt.base},
            "smallest_singular_ratio": rt.singular_ratios[rt.rank - 1] if rt.rank else 0.0,
        })
    return {"format": FORMAT, "scene": scene.name, "samples": samples, "seed": seed,
            "tolerance": tol, "noise": {"joint_sigma_rad": js, "laser_sample_sigma_m": sig_l},
            "layouts": rows}


def format_layouts(res: dict, display) -> str:
    """A table per subset: parameter, predicted std (display units); then what is
    excluded and why. ``display(name) -> (scale, unit)``."""
    from planecal.studies.common import table
    out = [f"plate layouts of {res['scene']}: {res['samples']} collision-free random poses "
           f"per layout (seed {res['seed']}), std predicted at the twin's noise "
           f"(repeatability {res['noise']['joint_sigma_rad'] * 1e6:.1f} urad per joint, "
           f"laser {res['noise']['laser_sample_sigma_m'] * 1e9:.0f} nm per sample)"]
    names = []
    for r in res["layouts"]:
        for n in r["free"]:
            if n not in names:
                names.append(n)
    head = ["parameter"] + ["+".join(r["plates"]) for r in res["layouts"]]
    rows = []
    for n in names:
        row = [n]
        for r in res["layouts"]:
            if n in r["std"]:
                sc, unit = display(n)
                row.append(f"{r['std'][n] * sc:.3g} {unit}")
            elif any(e["parameter"] == n for e in r["excluded"]):
                row.append("excluded")
            else:
                row.append("-")
        rows.append(row)
    out.append(table(head, rows))
    for r in res["layouts"]:
        if r["excluded"]:
            out.append(f"{'+'.join(r['plates'])}: rank {r['rank']} of {len(r['free'])}; "
                       + "; ".join(_why(e) for e in r["excluded"]))
    return "\n".join(out)


def _why(e: dict) -> str:
    if e["reason"] == "no_effect":
        return f"{e['parameter']}: no effect on any distance"
    mix = " ".join(f"{v:+.3g}*{k}" for k, v in list(e["combination"].items())[:4])
    more = " ..." if len(e["combination"]) > 4 else ""
    return f"{e['parameter']}: a combination of others ({mix}{more})"
