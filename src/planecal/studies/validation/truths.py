"""Validation over truths, and what each error source leaves (``breakdown``)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.calibrate import CalibrationSettings
from planecal.estimation.verdict import verdict_of
from planecal.studies.validation.run import validate
from planecal.studies.validation.settings import FIGURE_KEYS, ValidationSettings
from planecal.twin.world import SOURCES


def run_jobs(fn, items: list, engine=1, label: str = "validate", quiet: bool = True) -> list:
    """``[fn(item) for item in items]`` on ``engine`` (an open ``studies.distributed.Engine``
    or a job count: ``studies.common.parallel_map``)."""
    from planecal.base.progress import Progress
    from planecal.studies.common import parallel_map
    items = list(items)
    return parallel_map(fn, items, engine, Progress(label, len(items), quiet=quiet))


@dataclass(frozen=True)
class TruthJob:
    """One truth of ``validate_truth``: the world (scene, error profile, truth seed, the
    error families switched ``off``), the calibration set (rehearsal ``samples`` and
    ``seed``, or a planned pose list ``poses``), how it is calibrated (and, ``beside``,
    each lower level too: ``levels_beside``) and the validation settings.

    Each truth samples its own calibration set: rehearsal seed ``seed + truth_seed``
    (``sampling_seed``), so truth t at seed 0 is ``planecal rehearse --seed t``'s run and
    the truths are independent draws of the noise as well as of the world. (With one
    seed for all, the truths shared the repeatability's draws: on an ideal UR5 the five
    truths' tool-point errors were one 2-sigma draw, 0.08-0.11 mm against the
    covariance's 0.04, while five seeds of one truth gave 0.013-0.067, rms 0.047.)"""
    @property
    def sampling_seed(self) -> int:
        """The seed of this truth's calibration run: ``seed + truth_seed``."""
        return self.seed + self.truth_seed

    scene: str
    errors: str
    truth_seed: int
    samples: int = 150
    seed: int = 0
    offsets_all: bool = False
    poses: tuple | None = None
    settings: ValidationSettings = field(default_factory=ValidationSettings)
    off: tuple = ()
    calibration: CalibrationSettings = field(default_factory=CalibrationSettings)
    beside: bool = True
    aim_samples: int = 0  # with ``poses``: a first random run that aims them
    # (``rehearsal.staged_samples``); 0: the list as it is
    robot_minutes: float | None = None  # the calibration run's robot-time budget

    def rehearsal(self):
        """The calibration set's rehearsal (``studies.rehearsal``): run 0 of these settings
        (seed ``sampling_seed``, world ``truth_seed``)."""
        from planecal.studies.rehearsal import RehearsalSettings
        return RehearsalSettings(scene=self.scene, seed=self.sampling_seed, errors=self.errors,
                                 samples=len(self.poses) if self.poses else self.samples,
                                 truth_seed=self.truth_seed, offsets_all=self.offsets_all,
                                 poses=self.poses, clearance_m=self.settings.clearance_m,
                                 robot_minutes=self.robot_minutes)


def levels_beside(cal: CalibrationSettings) -> list[CalibrationSettings]:
    """The calibrations a validation at ``cal`` commands side by side on the same poses:
    each level of ``model.levels.LEVELS`` below ``cal``'s -- the lowest as it is (offsets
    only: what a controller takes as encoder offsets), the others with ``cal``'s
    compliance -- with the same fit options, then ``cal`` itself."""
    from planecal.model.levels import LEVELS
    below = LEVELS[:LEVELS.index(cal.level)]
    return [CalibrationSettings(level=lv, compliance=cal.compliance and k > 0,
                                options=cal.options, base_tolerance=cal.base_tolerance)
            for k, lv in enumerate(below)] + [cal]


def validate_truth(job: TruthJob) -> dict:
    """Draw the world, sample a calibration set on its twin, calibrate it from the nominal
    values (the one calibration, at the job's level and, ``beside``, each lower one),
    validate them all on the same world and poses (package docstring). A set the sampling
    run gives up on: ``{"truth_seed", "failed"}``."""
    return truth_run(job)[0]


def truth_run(job: TruthJob) -> tuple[dict, object, tuple | None]:
    """``validate_truth``'s result, the validated calibration (``fit.Result``, None if the
    sampling gave up) and its samples ``(qe, d_m, plate)``: what a recording draws."""
    from planecal.estimation.calibrate import calibrate
    from planecal.estimation.compensate import CalibratedModel
    from planecal.model.scene import nominal_params
    from planecal.studies.common import cached_scene, cached_world
    from functools import partial

    from planecal.studies.rehearsal import pose_list_samples, staged_samples, twin_samples
    from planecal.twin.world import sources_on, without

    st = job.settings
    reh = job.rehearsal()
    scene = cached_scene(job.scene)
    world, opts = without(*reh.world(0), job.off)
    try:
        sample = (twin_samples if not job.poses else pose_list_samples if not job.aim_samples
                  else partial(staged_samples, aim_samples=job.aim_samples))
        qe, d, plate, direction, rejected, robot = sample(scene, world, reh,
                                                             job.sampling_seed, opts, True)
        # too few samples for a calibration (a run its robot-time budget cut short): this
        # truth fails with the reason, the others stand
        cals = [(s.label, calibrate(scene.robot, qe, d, nominal_params(scene), plate, s,
                                    direction, scene.references))
                for s in (levels_beside(job.calibration) if job.beside else [job.calibration])]
    except (RuntimeError, InputError) as e:
        return {"truth_seed": job.truth_seed, "off": list(job.off), "failed": str(e)}, None, None
    fits = [(label, c.result) for label, c in cals]
    fit = fits[-1][1]
    v = validate(scene, world, [CalibratedModel(scene.robot, f.params, label)
                                for label, f in fits], qe, st,
                 cached_world(job.scene, st.clearance_m), [f for _, f in fits], opts,
                 direction)
    for row, (_, f), (_, c) in zip(v["levels"], fits, cals):
        row["max_model_error_mm"] = float(np.abs(f.residuals_m).max() * 1e3)
        row["converged"] = bool(f.converged)
        if not job.off:  # what each calibration says of itself (estimation.verdict)
            row.update(verdict_row(verdict_of(c)))
    v["truth_seed"] = job.truth_seed
    v["level"] = job.calibration.level
    v["compliance"] = job.calibration.compliance
    v["calibration_settings"] = job.calibration.to_dict()
    v["off"] = list(job.off)
    v["sources"] = sources_on(scene.robot, world, opts)
    v["calibration"] = {"samples": len(d), "rejected": rejected, **robot,
                        "fit_rms_mm": fit.rms_mm(),
                        "max_model_error_mm": float(np.abs(fit.residuals_m).max() * 1e3),
                        "converged": bool(fit.converged),
                        "offsets_std_rad": fit.std[fit.layout.slice("joint_offsets")]}
    v["truth_offsets_rad"] = world.params.joint_offsets
    v["calibrated_offsets_rad"] = fit.params.joint_offsets
    if not job.off:  # what the calibration says of itself, beside what the twin measures
        from planecal.estimation.accuracy import accuracy
        acc = accuracy(scene.robot, cals[-1][1], qe, d, plate, direction, scene.references,
                       scene.laser_range_mm)
        v["accuracy"] = acc.to_dict()
        v["predicted_tool_mm"] = acc.tool_point_mm
        v["predicted_band_mm"] = [acc.one_calibration_p10_mm, acc.one_calibration_p90_mm]
        v["verdict"] = verdict_of(cals[-1][1]).grade
    return v, fit, (qe, d, plate)


def verdict_row(verdict) -> dict:
    """A level's verdict beside its validated figures: its estimate at the tool, the band of
    AP near the samples, its grade and the simpler levels it is no better than."""
    return {"predicted_tool_mm": verdict.tool_mm, "predicted_band_mm": list(verdict.band_mm),
            "verdict": verdict.grade, "worse_than": list(verdict.worse_than),
            "comparisons": verdict.to_dict()["comparisons"]}


TRUTH_KEYS = ("truth_seed", *FIGURE_KEYS, "ap_tool_ratio", "gauge_error_before_mm",
              "gauge_error_after_mm", "predicted_tool_mm", "predicted_band_mm", "verdict")
LEVEL_KEYS = ("ap_after_tool_mm", "ap_after_flange_mm", "ap_after_tool_cell_mm",
              "rp_after_tool_mm", "ap_floor_tool_mm", "ap_after_tool_standard_mm",
              "ap_floor_tool_standard_mm")


def truth_row(v: dict) -> dict:
    """The per-truth entry of a validation over truths (``truths`` in its JSON): every
    model's figures (``FIGURE_KEYS``), each level's beside (``levels``), the named TCPs',
    the ISO poses' distances to the nearest sample and the fit's largest residual."""
    row = {k: v.get(k) for k in TRUTH_KEYS}
    cal = v.get("calibration") or {}
    row["max_model_error_mm"] = cal.get("max_model_error_mm")
    row["samples"] = cal.get("samples")
    row["robot_time_s"] = cal.get("robot_time_s")  # the calibration run's (both stages)
    row["offset_error_rad"] = (v.get("residual_offset_error") or {}).get("offset_error_rad")
    row["levels"] = v.get("levels") or []
    row["tcps"] = v.get("tcps") or []
    for key, cube in (("", v.get("cube") or {}), ("standard_", v.get("standard_cube") or {})):
        row[f"{key}cube_edge_mm"] = None if "edge_m" not in cube else cube["edge_m"] * 1e3
        row[f"{key}nearest_sample_mm"] = cube.get("nearest_sample_mm")
    row["standard_cube_failed"] = (v.get("standard_cube") or {}).get("failed")
    row["gauge_failed"] = v.get("gauge_failed")
    row["cell_frame_shift_mm"] = (None if not v.get("cell_frame")
                                  else float(np.max(v["cell_frame"]["shift_mm"])))
    return row


def _stat(rows: list[dict], key: str, f):
    vals = [r[key] for r in rows if r.get(key) is not None]
    return float(f(vals)) if vals else None


def summarize(results: list[dict]) -> tuple[dict, dict, dict]:
    """(summary, the median truth's result, the worst truth's): median and worst over the
    truths of each figure, and of each level's beside (``levels_summary``: label, median
    and worst of ``LEVEL_KEYS``); the worst truth: the largest AP after calibration at the tool
    point; the median truth: the one whose AP after is the median, the lower one of an
    even count."""
    ok = [v for v in results if "failed" not in v]
    if not ok:
        raise InputError("no truth could be validated: "
                         + "; ".join(f"truth {v['truth_seed']}: {v['failed']}" for v in results))
    after = np.array([v["ap_after_tool_mm"] for v in ok])
    order = np.argsort(after, kind="stable")
    med = ok[int(order[(len(ok) - 1) // 2])]
    worst = ok[int(order[-1])]
    out = {"truths": [truth_row(v) for v in ok],
           "failed_truths": [{"truth_seed": v["truth_seed"], "reason": v["failed"]}
                             for v in results if "failed" in v],
           "median_truth_seed": med["truth_seed"], "worst_truth_seed": worst["truth_seed"]}
    for key in FIGURE_KEYS:
        base = key[:-3]
        out[f"{base}_median_mm"] = _stat(ok, key, np.median)
        out[f"{base}_worst_mm"] = _stat(ok, key, np.max)
    for key in ("gauge_error_before_mm", "gauge_error_after_mm"):
        base = key[:-3]
        out[f"{base}_median_mm"] = _stat(ok, key, np.median)
        out[f"{base}_worst_mm"] = _stat(ok, key, lambda x: max(x, key=abs))
    levels = []
    for k, row in enumerate(ok[0]["levels"]):
        rows = [v["levels"][k] for v in ok]
        levels.append({"level": row["level"], **{
            f"{key[:-3]}_{what}_mm": _stat(rows, key, f) for key in LEVEL_KEYS
            for what, f in (("median", np.median), ("worst", np.max))}})
    out["levels_summary"] = levels
    return out, med, worst


def breakdown_variants(sources: list[str], mode: str = "alone") -> list[tuple[str, tuple]]:
    """(label, families switched off). Both modes: all sources, all but the noise (the
    same poses rehearsed without repeatability, quantisation and the laser's noise: what
    the noise adds is the difference), ..., none of them. 'alone': each family alone
    (the noise's too), the others off; 'off': each mismatch family switched off in turn,
    the noise off as well (so its share is not the noise's draw through another fit)."""
    if mode not in ("off", "alone"):
        raise InputError(f"--breakdown: 'off', 'alone' or 'none', got {mode!r}")
    noisy = "noise" in sources
    rows = [("all sources", ())] + ([("all but the noise", ("noise",))] if noisy else [])
    if mode == "off":
        rows += [(f"all but the noise and {f}", ("noise", f)) if noisy else
                 (f"without {f}", (f,)) for f in sources if f != "noise"]
    else:
        rows += [(f"{f} alone", tuple(g for g in sources if g != f)) for f in sources]
    rows.append(("none (cell only)", tuple(sources)))
    return rows


BREAKDOWN_KEYS = ("ap_before_tool_mm", "ap_after_tool_mm", "ap_after_tool_cell_mm",
                  "ap_after_flange_mm", "ap_floor_tool_mm", "ap_oracle_tool_mm",
                  "rp_after_tool_mm")


def breakdown(job: TruthJob, mode: str = "alone", engine=1, quiet: bool = True) -> dict:
    """``job``'s truth repeated with each error family switched off (``mode`` 'off') or on
    alone ('alone'), and without the noise, the gauge block, the standard's cube and the
    lower levels skipped: per variant the figures of ``BREAKDOWN_KEYS`` (the same
    rehearsal seed: the same pose draws), and which families the level models."""
    from dataclasses import replace

    from planecal.model.levels import layout_for
    from planecal.studies.common import cached_scene
    from planecal.studies.validation.floors import modelled_sources
    from planecal.twin.world import source_labels, sources_on
    world = job.rehearsal().world(0)
    scene = cached_scene(job.scene)
    on = sources_on(scene.robot, *world)
    variants = breakdown_variants(on, mode)
    st = replace(job.settings, gauge=False, standard_cube=False)
    res = run_jobs(validate_truth, [replace(job, off=off, settings=st, beside=False)
                                    for _, off in variants], engine, "breakdown", quiet)
    rows = []
    for (label, off), v in zip(variants, res):
        row = {"variant": label, "off": list(off)}
        if "failed" in v:
            row["failed"] = v["failed"]
        else:
            row.update({k: v[k] for k in BREAKDOWN_KEYS})
            row["max_model_error_mm"] = v["calibration"]["max_model_error_mm"]
        rows.append(row)
    labels = source_labels(world[1])
    cal = job.calibration
    layout = layout_for(scene.robot, len(scene.plates), cal.level, cal.compliance)
    return {"truth_seed": job.truth_seed, "mode": mode, "sources": on, "variants": rows,
            "what": {f: labels[f] for f in on},
            "modelled": [f for f in modelled_sources(layout) if f in on]}


def cannot_remove(bd: dict) -> list[dict]:
    """From a breakdown: per error family but the noise, what it leaves in AP after
    calibration at the tool point, the noise kept out of it: alone, its variant minus the
    cell alone; off, all but the noise minus all but the noise and it (a world without
    noise: all sources minus without it). Largest first; ``modelled``: whether the level
    has parameters for it."""
    rows = {r["variant"]: r for r in bd["variants"] if "failed" not in r}
    noisy = "noise" in bd["sources"]
    base = rows.get("all but the noise" if noisy else "all sources")
    none = rows.get("none (cell only)")
    out = []
    for f in bd["sources"]:
        if f == "noise":
            continue
        if bd["mode"] == "off":
            r = rows.get(f"all but the noise and {f}" if noisy else f"without {f}")
            ref, share_of = base, lambda r_: base["ap_after_tool_mm"] - r_["ap_after_tool_mm"]
        else:
            r = rows.get(f"{f} alone")
            ref, share_of = none, lambda r_: r_["ap_after_tool_mm"] - none["ap_after_tool_mm"]
        if r is None or ref is None:
            continue
        out.append({"source": f, "what": bd.get("what", SOURCES).get(f, SOURCES[f]),
                    "ap_after_tool_share_mm": float(share_of(r)),
                    "ap_after_tool_variant_mm": r["ap_after_tool_mm"],
                    "modelled": f in (bd.get("modelled") or [])})
    return sorted(out, key=lambda x: -x["ap_after_tool_share_mm"])


def noise_share(bd: dict) -> dict | None:
    """From a breakdown: what the noise does to AP after calibration at the tool point:
    with every source (``with_mm``), without the noise (``without_mm``: the same poses
    rehearsed noise-free), their difference (``share_mm``), the noise alone on the cell
    (``alone_mm``, mode 'alone'), and whether it dominates (``dominates``: it adds more
    than all the rest leaves). None where the world has no noise or a variant failed."""
    rows = {r["variant"]: r for r in bd["variants"] if "failed" not in r}
    a, w = rows.get("all sources"), rows.get("all but the noise")
    if "noise" not in bd["sources"] or a is None or w is None:
        return None
    alone = rows.get("noise alone")
    share = a["ap_after_tool_mm"] - w["ap_after_tool_mm"]
    return {"what": bd.get("what", SOURCES).get("noise", SOURCES["noise"]),
            "with_mm": a["ap_after_tool_mm"], "without_mm": w["ap_after_tool_mm"],
            "share_mm": float(share), "alone_mm": None if alone is None
            else alone["ap_after_tool_mm"], "dominates": bool(share > w["ap_after_tool_mm"])}
