"""Plate layouts (issue 13 item 5): for every subset of 1, 2 and 3 of a scene's plates,
which parameters the samples can identify and how well (the predicted std).

Per subset: ``samples`` collision-free poses of the sampling run's own distribution on those
plates, an equal share per plate (``planning.candidates`` plate by plate, with the full
scene's collision checker, so the other plates still stand in the cell; plate i's draws
are the same in every subset that holds it), then the calibration's own base-set selection
on them at the scene's nominal parameters (``estimation.calibrate.base_set``, with the
study's ``CalibrationSettings``: the level, the compliance, the candidates, the arm's scale
kept): exactly what ``planecal calibrate`` would fit from such poses. The predicted std of
the base set: the unweighted fit's sandwich covariance under the twin's noise model
(repeatability projected per pose + the laser's 100-reading mean;
``design.predicted_std``, as ``plan``).
"""
from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.calibrate import CalibrationSettings, base_set
from planecal.estimation.noise import repeatability_sigma, sample_sigma_m
from planecal.model.measurement import predict_with_jacobian

FORMAT = "planecal-layouts/1"


def subscene(scene, plates: tuple):
    """The scene with only the plates ``plates`` (0-based indices), for drawing poses and
    the nominal parameters (the collision checker keeps the whole scene)."""
    return replace(scene, plates=[scene.plates[i] for i in plates],
                   name=f"{scene.name}[{'+'.join(scene.plates[i].name for i in plates)}]")


def subsets(n_plates: int, sizes=(1, 2, 3)) -> list[tuple]:
    return [c for k in sizes if k <= n_plates for c in combinations(range(n_plates), k)]


def layout_study(scene, settings: CalibrationSettings = CalibrationSettings(),
                 samples: int = 150, seed: int = 0, checker=None, sizes=(1, 2, 3),
                 repeatability_mm: float | None = None, laser_noise_mm: float = 0.001) -> dict:
    """The study (module docstring) with the calibration's ``settings``. Returns a dict
    (``FORMAT``) with a row per subset: plates, samples, free (the candidates), base
    (identifiable), excluded (with reason and combination), rank, predicted std of the
    base set (SI units) and its ratio to each parameter's ``practical_std``."""
    from planecal.model.scene import nominal_params
    from planecal.studies.design import predicted_std
    from planecal.studies.planning import candidates

    if samples < 13:
        raise InputError(f"--samples must be at least 13, got {samples}")
    rep = scene.robot.repeatability_m if repeatability_mm is None else repeatability_mm * 1e-3
    js = repeatability_sigma(scene.robot, rep) if rep > 0 else 0.0
    sig_l = sample_sigma_m(laser_noise_mm)
    rows = []
    for subset in subsets(len(scene.plates), sizes):
        sub = subscene(scene, subset)
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
        nominal = nominal_params(sub)
        layout, bs = base_set(scene.robot, qe, nominal, plate, settings)
        _, J = predict_with_jacobian(scene.robot, qe, nominal, plate, layout)
        std, _ = predicted_std(J, layout, bs.mask(layout), js, sig_l)
        std = dict(zip(bs.base, std.tolist()))
        practical = dict(zip(bs.base, layout.practical_std(bs.base)))
        rows.append({
            "plates": [scene.plates[i].name for i in subset], "plate_indices": list(subset),
            "samples": int(len(qe)), "free": list(bs.free), "base": list(bs.base),
            "rank": bs.rank,
            "excluded": [{"parameter": e.parameter, "reason": e.reason,
                          "combination": dict(e.combination)} for e in bs.excluded],
            "std": std,
            "std_over_practical": {k: (std[k] / practical[k] if practical[k] else None)
                                   for k in bs.base},
            "units": {k: layout.param(k).unit for k in bs.base},
            "smallest_singular_ratio": bs.r_ratios[bs.rank - 1] if bs.rank else 0.0,
        })
    return {"format": FORMAT, "scene": scene.name, "samples": samples, "seed": seed,
            "calibration": settings.to_dict(), "tolerance": settings.base_tolerance,
            "noise": {"joint_sigma_rad": js, "laser_sample_sigma_m": sig_l},
            "layouts": rows}
