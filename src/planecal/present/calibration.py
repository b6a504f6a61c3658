"""Every rendering of a calibration, in one place (lmfit's ``printfuncs`` has the same
shape): the result file's JSON document (``document``), and, from that document only, the
parameter table (``parameter_rows``), the findings (``findings``) and the terminal report
(``text``). The HTML report (``present.report.calibration``), the Rerun recording
(``present.rerun.fit``) and the Python API's summary take their rows and findings from
here, so a label cannot disagree with the settings the result was made with.

Model error, everywhere in planecal: predicted - measured (the fit's residual;
docs/FORMATS.md).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from planecal.base.errors import InputError
from planecal.estimation.calibrate import Calibration, encoder_offsets
from planecal.estimation.verdict import verdict_of
from planecal.estimation.identifiability import Excluded
from planecal.io.params import kinematics_to_dict, nonkinematic_to_dict, params_to_dict

MODEL_ERROR = "predicted - measured"


def describe_excluded(e: Excluded | dict) -> str:
    """Why a candidate parameter stayed at its initial value, in one line."""
    e = e if isinstance(e, dict) else asdict(e)
    name, reason = e["parameter"], e["reason"]
    if reason == "no_effect":
        return f"{name}: no effect on any distance of these samples"
    if reason == "scale":
        return (f"{name}: sets the arm's scale, which a distance sensor reads only through "
                "its own gain: kept at robot.json's value (--free-scale frees it where a "
                "length reference fixes the scale)")
    if reason == "held_out":
        return (f"{name}: its family predicts held-out samples worse than the model without "
                "it (the selection)")
    mix = " ".join(f"{v:+.4g}*{k}" for k, v in (e.get("combination") or {}).items())
    return f"{name}: a combination of others (acts as {mix})"


def _std_blocks(res) -> dict:
    layout, std = res.layout, res.std

    def s(name):
        v = std[layout.index(name)]
        return None if not np.isfinite(v) else float(v)

    def ss(group):
        return [s(n) for n in group.names]
    out = {"joint_offsets_rad": ss(layout.group("joint_offsets")),
           "planes": [{"n_tilde": ss(g)} for g in layout.groups_of("plane")],
           "sensor": {"origin_m": ss(layout.group("sensor_origin")), "phi_y_rad": s("phi_y"),
                      "phi_z_rad": s("phi_z")}}
    if layout.groups_of("joint_geometry") or layout.groups_of("compliance"):
        g = np.full((6, 4), np.nan)
        for grp in layout.groups_of("joint_geometry"):
            g[grp.index] = std[layout.slice(grp.name)]
        base = std[layout.slice("base")] if layout.groups_of("base_frame") else np.full(6, np.nan)
        comp = (std[layout.slice("compliance")] if layout.groups_of("compliance")
                else np.full(6, np.nan))
        out["kinematics"] = kinematics_to_dict(g, base, comp)
    if layout.groups_of("gear") or layout.groups_of("backlash") or layout.groups_of("laser"):
        sd = res.params.with_vector(std, layout)  # the same fields, holding stds
        out["nonkinematic"] = nonkinematic_to_dict(res.params, sd)
    return out


def _parameters(cal: Calibration) -> list[dict]:
    """Every parameter of the layout by name: value, initial value, std (null where fixed,
    excluded or not identifiable), SI unit, display unit and scale, and its status."""
    res = cal.result
    layout = res.layout
    x, x0, std = res.params.to_vector(layout), res.initial.to_vector(layout), res.std
    excluded = {e.parameter: e.reason for e in cal.excluded}
    bad = set(res.identifiability.not_identifiable)
    rows = []
    for i, p in enumerate(layout.params):
        if p.name in excluded:
            status = "excluded: " + excluded[p.name]
        elif not res.free[i]:
            status = "fixed"
        elif p.name in bad:
            status = "not identifiable"
        else:
            status = "fitted"
        rows.append({"name": p.name, "value": float(x[i]), "initial": float(x0[i]),
                     "std": float(std[i]) if np.isfinite(std[i]) else None, "unit": p.unit,
                     "display_unit": p.display_unit, "display_scale": p.display_scale,
                     "status": status})
    return rows


def _controller_offsets(cal: Calibration) -> dict:
    """The joint offsets an encoder can take (``calibrate.encoder_offsets``), or why none."""
    res = cal.result
    try:
        delta, fitted, kept = encoder_offsets(res.layout, res.free, res.params, res.initial)
    except InputError as e:  # the reason, in one line
        return {"joint_offsets_rad": None, "reason": str(e)}
    return {"joint_offsets_rad": [float(v) for v in delta], "calibrated": fitted,
            "kept_initial": kept, "reason": None}


def document(cal: Calibration, robot=None, accuracy=None) -> dict:
    """The result file's keys (docs/FORMATS.md): the parameter file's (the identified
    values), ``std`` in the same shape, ``parameters`` (every parameter by name, with its
    status), the fit's figures, ``identifiability``, ``free``, ``covariance``,
    ``history``, ``initial``, ``calibration`` (the settings: level, compliance, ...),
    ``base_set`` and ``excluded``, ``encoder_offsets`` (what a controller can take),
    ``selection`` (the families chosen by held-out prediction, ``estimation.selection``),
    ``verdict`` (the calibration judged at the tool, ``estimation.verdict``: what export,
    urdf and compensate refuse) and, with ``robot``, the robot's name and description hash;
    with ``accuracy`` (``estimation.accuracy.Accuracy``) its figures."""
    res = cal.result
    out = params_to_dict(res.params)
    out["std"] = _std_blocks(res)
    if "kinematics" in out["std"] and "kinematics" not in out:  # still a whole-model result
        out["kinematics"] = kinematics_to_dict(res.params.geometry, res.params.base,
                                               res.params.compliance)
    if "nonkinematic" in out["std"] and "nonkinematic" not in out:  # still level 3's
        out["nonkinematic"] = nonkinematic_to_dict(res.params)
    out["parameters"] = _parameters(cal)
    out["model_error"] = MODEL_ERROR
    out["residual_rms_mm"] = res.rms_mm()
    out["residual_rms_initial_mm"] = res.rms_mm(initial=True)
    out["residual_max_mm"] = float(np.max(np.abs(res.residuals_m[res.used])) * 1e3)
    out["iterations"] = res.iterations
    out["converged"] = res.converged
    out["status"] = cal.status
    out["outliers"] = [int(i) for i in res.outliers]
    out["samples_used"] = int(res.used.sum())
    out["identifiability"] = res.identifiability.to_dict()
    out["free"] = res.layout.names_of(res.free)
    out["covariance"] = res.covariance.to_dict()
    out["history"] = [asdict(it) for it in res.history]
    out["initial"] = params_to_dict(res.initial)
    bs = cal.base_set
    out["calibration"] = cal.settings.to_dict()
    out.update({"level": cal.level, "compliance": cal.compliance, "base_set": list(bs.base),
                "candidates": list(bs.free),
                "excluded": [{"parameter": e.parameter, "reason": e.reason,
                              "combination": dict(e.combination)} for e in bs.excluded],
                "base_set_tolerance": bs.tol,
                "geometry_prior_m_rad": out["calibration"]["geometry_prior_m_rad"]})
    out["encoder_offsets"] = _controller_offsets(cal)
    if cal.selection is not None:
        out["selection"] = cal.selection.to_dict()
    out["verdict"] = verdict_of(cal).to_dict()
    if robot is not None:
        out["robot"] = {"name": robot.name, "sha256": robot.digest}
    if accuracy is not None:
        out["accuracy"] = accuracy.to_dict()
    return out


# ----- from the document ----------------------------------------------------------------------

@dataclass(frozen=True)
class Row:
    name: str
    value: float
    initial: float | None
    std: float | None
    unit: str
    status: str


def parameter_rows(doc: dict) -> list[Row]:
    """The parameter table of a result document, in the layout's order (older results
    without ``parameters``: their level-1 keys)."""
    if isinstance(doc.get("parameters"), list):
        return [Row(p["name"], float(p["value"]), p.get("initial"), p.get("std"), p["unit"],
                    p.get("status", "fitted")) for p in doc["parameters"]]
    std = doc.get("std") if isinstance(doc.get("std"), dict) else {}

    def sd(*keys):
        v = std
        for k in keys:
            if isinstance(v, dict):
                v = v.get(k)
            elif isinstance(v, list) and isinstance(k, int) and k < len(v):
                v = v[k]
            else:
                return None
        return None if v is None or isinstance(v, (dict, list)) else float(v)
    free = set(doc.get("free") or [])

    def row(name, v, s, unit):
        return Row(name, float(v), None, s, unit, "fitted" if name in free else "fixed")
    rows = [row(f"delta{i + 1}", v, sd("joint_offsets_rad", i), "rad")
            for i, v in enumerate(doc["joint_offsets_rad"])]
    s = doc["sensor"]
    rows += [row(f"o_{c}", v, sd("sensor", "origin_m", i), "m")
             for i, (c, v) in enumerate(zip("xyz", s["origin_m"]))]
    rows += [row("phi_y", s["phi_y_rad"], sd("sensor", "phi_y_rad"), "rad"),
             row("phi_z", s["phi_z_rad"], sd("sensor", "phi_z_rad"), "rad")]
    for k, p in enumerate(doc["planes"]):
        rows += [row(f"n{k + 1}_{c}", v, sd("planes", k, "n_tilde", i), "1/m")
                 for i, (c, v) in enumerate(zip("xyz", p["n_tilde"]))]
    return rows


def label(doc: dict) -> str:
    """What the result is: 'offsets', 'full + compliance', 'nonkinematic' (level 3 has the
    compliance always), ... (older results: offsets)."""
    from planecal.model.levels import LEVELS, with_compliance
    level = doc.get("level") if doc.get("level") in LEVELS else "offsets"
    plus = doc.get("compliance") and not with_compliance(level, False)
    return level + (" + compliance" if plus else "")


@dataclass(frozen=True)
class Finding:
    text: str
    warning: bool


def findings(doc: dict) -> list[Finding]:
    """What the result says about itself, in order: the noise model, the scale of the fit,
    the base set and what it left out, then each identifiability warning and note."""
    ident = doc.get("identifiability") if isinstance(doc.get("identifiability"), dict) else {}
    out = []
    if ident.get("weighted"):
        out.append(Finding(f"weighted by the repeatability noise model: variance factor "
                           f"{ident.get('variance_factor', float('nan')):.3g} (1: the "
                           "model's noise level fits the residuals; the std include it)", False))
    obs = ident.get("observability") or {}
    if "sigma_mm" in ident:
        out.append(Finding(f"sigma {ident['sigma_mm']:.4g} mm   scaled condition number "
                           f"{ident.get('condition_number_scaled', float('nan')):.4g}   O1 "
                           f"{obs.get('O1', float('nan')):.3g}  O2 "
                           f"{obs.get('O2', float('nan')):.3g}", False))
    if doc.get("base_set") is not None:
        cand = doc.get("candidates") or doc.get("free") or []
        out.append(Finding(f"level {label(doc)}: {len(doc['base_set'])} of {len(cand)} "
                           "candidate parameters identifiable from these samples (pivoted QR, "
                           f"|R_kk|/|R_00| >= {doc.get('base_set_tolerance', 0):g})", False))
    for e in doc.get("excluded") or []:
        if e.get("reason") != "held_out":  # a family at once: ``selection_lines``
            out.append(Finding("EXCLUDED " + describe_excluded(e), False))
    for name in ident.get("no_effect", []):
        out.append(Finding(f"no effect: {name} does not change any distance in this data",
                           True))
    for pd in ident.get("poorly_determined", []):
        noise = pd.get("noise_std")
        why = ("the data barely depends on it" if noise is None or noise > pd["limit"] else
               f"the model's mismatch (residuals {ident['residual_over_noise']:.1f}x the noise; "
               f"{noise:.3g} at the noise model's level)")
        out.append(Finding(f"not identifiable in practice: {pd['parameter']} (std "
                           f"{pd['std']:.3g} above {pd['limit']:g}): {why}", True))
    for pd in ident.get("mismatch_inflated", []):
        out.append(Finding(
            f"poorly determined through model mismatch: {pd['parameter']} (std {pd['std']:.3g} "
            f"above {pd['limit']:g}; at the noise model's level {pd['noise_std']:.3g}): the "
            f"residuals are {ident['residual_over_noise']:.1f}x the noise, errors the model "
            "lacks (a fuller model, --level full, may explain them)", True))
    for d in ident.get("unidentifiable_directions", []):
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in d.items())
        out.append(Finding(f"not identifiable: {', '.join(d)} move together without changing "
                           f"any distance (direction {mix})", True))
    for w in ident.get("weak_directions", []):
        mix = " ".join(f"{v:+.3f}*{k}" for k, v in w["direction"].items())
        out.append(Finding(f"weakly identifiable (scaled singular value ratio "
                           f"{w['scaled_singular_ratio']:.2e}): {mix}", True))
    for pr in ident.get("correlated_pairs", []):  # the std include it: a property, no fault
        out.append(Finding(f"correlated: {pr['a']} ~ {pr['b']} (rho {pr['rho']:+.4f}): these "
                           "poses move them together; their std and the position error "
                           "account for it", False))
    if not doc.get("converged", True):
        out.append(Finding(f"stopped after {doc.get('iterations')} iterations (max_iter) "
                           "before the correction fell below the limit", True))
    return out


def _value(r: Row) -> str:
    return f"{r.value:>14.7g}"


def text(doc: dict, n_zero: int = 0) -> str:
    """The terminal report of a result document."""
    lines = [f"{'parameter':<10} {'value':>14} {'std':>11} {'correction':>13}  unit"]
    for r in parameter_rows(doc):
        sd = {"fitted": None, "fixed": "fixed", "not identifiable": "NOT IDENT."}.get(
            r.status, "excluded")
        if sd is None:
            sd = f"{r.std:.3e}" if r.std is not None else "n/a"
        corr = "" if r.initial is None else f"{r.value - r.initial:>13.4e}"
        lines.append(f"{r.name:<10} {_value(r)} {sd:>11} {corr:>13}  {r.unit}")
    lines.append("")
    n_all = doc.get("samples_used", 0) + len(doc.get("outliers") or [])
    lines.append(f"samples used {doc.get('samples_used')} of {n_all}"
                 + (f", {n_zero} laser zeros skipped" if n_zero else ""))
    lines.append(f"model error ({MODEL_ERROR}) RMS  before {doc['residual_rms_initial_mm']:.4f} "
                 f"mm   after {doc['residual_rms_mm']:.4f} mm   max after "
                 f"{doc['residual_max_mm']:.4f} mm")
    lines.append(f"iterations {doc['iterations']}" + ("" if doc.get("converged") else
                                                       " (not converged)"))
    outl = doc.get("outliers") or []
    lines.append("outliers " + (", ".join(str(i) for i in outl) if outl else "none"))
    for f in findings(doc):
        lines.append(("WARNING " if f.warning else "") + f.text)
    eo = doc.get("encoder_offsets")
    if isinstance(eo, dict) and eo.get("reason"):
        lines.append(f"NOTE no encoder offsets for a controller: {eo['reason']}")
    lines.extend(selection_lines(doc))
    lines.extend(accuracy_lines(doc))
    lines.extend(verdict_lines(doc))
    return "\n".join(lines)


FAMILY_TEXT = {"geometry": "the joint geometry", "compliance": "the joint compliance",
               "gear": "the gear harmonics", "backlash": "the backlash",
               "laser": "the laser's linearity"}


def selection_lines(doc: dict) -> list[str]:
    """Which families the held-out samples chose (``estimation.selection``), in one line."""
    sel = doc.get("selection")
    if not isinstance(sel, dict):
        return []
    head = (f"selection ({sel['folds']}-fold held-out residuals): level {sel['asked']} "
            f"frees {', '.join(FAMILY_TEXT[f] for f in sel['kept']) or 'no family'}")
    gone = [f"{FAMILY_TEXT[x['family']]} (held-out rms {x['held_out_with_mm']:.4f} mm with "
            f"it, {x['held_out_without_mm']:.4f} without)" for x in sel.get("left_out", [])]
    rej, tool = sel.get("rejected"), sel.get("at_tool_mm")
    line = head + ("; left out, predicting held-out samples worse: " + "; ".join(gone)
                   if gone else "" if rej else "; every family of the level predicts them "
                   "better")
    if rej and tool:
        line += (f"; the held-out samples preferred freeing "
                 f"{', '.join(FAMILY_TEXT[f] for f in rej['families']) or 'no family'}"
                 + ("" if rej.get("geometry_prior") else " without the geometry prior")
                 + f", which the reference model puts further off at the tool ({tool[1]:.3f} "
                 f"mm against {tool[0]:.3f}): kept as asked")
    elif tool:
        line += f" (at the tool {tool[1]:.3f} mm against {tool[0]:.3f} as asked)"
    return [line]


SCALE_TEXT = {"joint_geometry": "geometry", "base_frame": "base", "compliance": "compliance",
              "gear": "gear", "backlash": "backlash", "laser": "laser"}


def _scales(scale) -> str:
    if not isinstance(scale, dict):
        return "-"
    return ", ".join(f"{SCALE_TEXT.get(k, k)} x{v:.2g}" for k, v in scale.items())


def verdict_lines(doc: dict) -> list[str]:
    """What the calibration says of itself at the tool (``estimation.verdict``): one line
    for the figure, one (a WARNING) where a simpler level is better, one saying why where
    the verdict is uncertain."""
    v = doc.get("verdict")
    if not isinstance(v, dict):
        return []
    beside = "; ".join(f"{c['level']} {c['tool_mm']:.3f}" for c in v.get("comparisons", []))
    out = [f"verdict {v['grade']}: predicted position error at the tool {v['tool_mm']:.3f} mm "
           f"rms over the samples' poses, AP near them {v['band_mm'][0]:.3f}-{v['band_mm'][1]:.3f} mm "
           f"(10-90 %); judged against level 3's whole model with the robot class's errors, "
           f"scaled by these samples ({_scales(v.get('scale'))})"
           + (f"; the simpler levels on the same samples: {beside} mm" if beside else "")]
    if v["grade"] == "worse":
        out.append("WARNING " + "; ".join(v["reasons"]) + ": export, urdf and compensate "
                   "refuse this result without --force")
    elif v["grade"] == "uncertain":
        # not an alarm: the figure stands, its band is what is in doubt
        out.append("the verdict is uncertain because " + "; ".join(v["reasons"]))
    return out


def accuracy_lines(doc: dict) -> list[str]:
    """The result's accuracy figures beside the verdict's estimate (``estimation.accuracy``),
    labelled: what each includes."""
    a = doc.get("accuracy")
    if not isinstance(a, dict):
        return []
    return [f"at the tool from the noise model alone {a['noise_only_mm']:.3f} mm rms "
            f"({a['noise_sigma_mm']:.4f} mm a sample); the fit's own covariance at its "
            f"residual level {a['residual_sigma_mm']:.4f} mm: {a.get('covariance_mm', 0):.3f} mm "
            f"({a['error_directions']:.1f} effective directions)",
            (f"held-out residuals ({a['folds']}-fold cross-validation, {a.get('held_out')} "
             f"samples) rms {a['cv_residual_rms_mm']:.4f} mm against "
             f"{a['in_sample_rms_mm']:.4f} mm in the fit"
             if a.get("cv_residual_rms_mm") is not None else
             "held-out residuals: too few samples to calibrate without a fold of them")]
