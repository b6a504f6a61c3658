"""Parameter files (JSON), the format others script against:

    {"format": "planecal-params/1",
     "joint_offsets_rad": [6 numbers],
     "planes": [{"n_tilde": [x, y, z]}, ...],
     "sensor": {"origin_m": [x, y, z], "phi_y_rad": .., "phi_z_rad": ..}}

Result files (``planecal-result/1``) hold the same keys plus ``std`` (same shape, null
where not identifiable), ``residual_rms_mm``, ``iterations``, ``outliers``,
``identifiability`` and ``provenance``. The models and their checks are in
``planecal.formats.params``; files without ``format`` (older ones) are read alike.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.model.cell_params import CellParams
from planecal.formats.base import json_values, read_json, validate
from planecal.formats.params import PARAMS_FORMAT, RESULT_FORMAT, ParamsFile, ResultFile


def params_to_dict(p: CellParams) -> dict:
    """The file's keys; ``kinematics`` (level 2's corrections) only where one is non-zero,
    so a level-1 file is what it always was."""
    out = {
        "joint_offsets_rad": [float(v) for v in p.joint_offsets],
        "planes": [{"n_tilde": [float(v) for v in n]} for n in p.planes],
        "sensor": {"origin_m": [float(v) for v in p.sensor_origin],
                   "phi_y_rad": float(p.phi_y), "phi_z_rad": float(p.phi_z)},
    }
    if p.has_corrections:
        out["kinematics"] = kinematics_to_dict(p.geometry, p.base, p.compliance)
    if p.gear.any() or p.backlash.any() or p.laser.any():
        out["nonkinematic"] = nonkinematic_to_dict(p)
    return out


def _num(e):
    return None if e is None or not np.isfinite(e) else float(e)


def nonkinematic_to_dict(p: CellParams, std: CellParams | None = None) -> dict:
    """The ``nonkinematic`` object (level 3) of ``p``'s gear harmonics, backlash and laser
    linearity; with ``std`` (the same fields holding standard deviations, NaN where none)
    the std block's, without the measuring range."""
    v = p if std is None else std
    out = {"gear": [{"joint": j + 1, "cycles_per_rev": f, "sin_rad": _num(a[0]),
                     "cos_rad": _num(a[1])} for (j, f), a in zip(p.gear_terms, v.gear)],
           "backlash_rad": [_num(b) for b in v.backlash],
           "laser_linearity": [{"cycles_per_range": k, "sin_m": _num(a[0]), "cos_m": _num(a[1])}
                               for k, a in zip(p.laser_orders, v.laser)]}
    if std is None:
        out["laser_range_m"] = [float(e) for e in p.laser_range_m]
    return out


def kinematics_to_dict(geometry, base, compliance) -> dict:
    """The ``kinematics`` object from (6, 4) geometry [alpha, a, beta, d], base (6,) and
    compliance (6,) (values or std; None/NaN become null)."""
    def row(v):
        return [None if e is None or not np.isfinite(e) else float(e) for e in v]
    g = np.asarray(geometry, float)
    return {"alpha_rad": row(g[:, 0]), "a_m": row(g[:, 1]), "beta_rad": row(g[:, 2]),
            "d_m": row(g[:, 3]), "base": row(np.asarray(base, float)),
            "compliance_rad_per_nm": row(np.asarray(compliance, float))}


def params_from_dict(d, path: str = "<params>") -> CellParams:
    """CellParams from a parsed parameter (or result) file, validated by
    ``planecal.formats.params.ParamsFile`` (a result file, ``format`` planecal-result/1,
    by ``ResultFile``: every field a command may read from it, its controller offsets
    and its residual level included); one-line InputError otherwise."""
    result = isinstance(d, dict) and d.get("format") == RESULT_FORMAT
    pf = validate(ResultFile if result else ParamsFile, d, path,
                  "result file" if result else "parameter file")
    s = pf.sensor
    k = pf.kinematics
    extra = {} if k is None else {
        "geometry": np.array([k.alpha_rad, k.a_m, k.beta_rad, k.d_m], float).T,
        "base": k.base, "compliance": k.compliance_rad_per_nm}
    nk = pf.nonkinematic
    if nk is not None:
        extra.update(gear_terms=tuple((g.joint - 1, g.cycles_per_rev) for g in nk.gear),
                     gear=np.array([[g.sin_rad, g.cos_rad] for g in nk.gear], float),
                     backlash=nk.backlash_rad,
                     laser_orders=tuple(h.cycles_per_range for h in nk.laser_linearity),
                     laser=np.array([[h.sin_m, h.cos_m] for h in nk.laser_linearity], float),
                     laser_range_m=tuple(nk.laser_range_m))
    return CellParams(pf.joint_offsets_rad, s.origin_m, s.phi_y_rad, s.phi_z_rad,
                      [p.n_tilde for p in pf.planes], **extra)


def load_json(path: str | Path, what: str = "JSON file"):
    """Parsed JSON, read within planecal's bounds (size, nesting, binary data); one-line
    InputError otherwise. Validation is the caller's (``planecal.formats``)."""
    return read_json(path, what)


def load_params(path: str | Path, robot=None) -> CellParams:
    """The parameters of a parameter or result file; with ``robot``, a result made for
    another robot is refused (``check_robot``)."""
    doc = read_json(path, "parameter file")
    if robot is not None:
        check_robot(doc, robot, path)
    return params_from_dict(doc, str(path))


def check_robot(doc, robot, path) -> None:
    """InputError (one line) where the parameter or result document ``doc`` records that it
    was made for another robot than ``robot``: another name, or the same name with another
    description (its SHA-256, ``model.robot.description_digest``). A file that records no
    robot (a hand-written parameter file, older results: the provenance's name only) is
    checked by what it records."""
    if not isinstance(doc, dict):
        return
    rec = doc.get("robot")
    prov = doc.get("provenance")
    name = rec.get("name") if isinstance(rec, dict) else (
        prov.get("robot") if isinstance(prov, dict) else None)
    digest = rec.get("sha256") if isinstance(rec, dict) else None
    if isinstance(name, str) and name != robot.name:
        raise InputError(f"{path}: made for the robot {name!r}, not {robot.name!r} "
                         "(give the robot it was made for, or recalibrate)")
    if isinstance(digest, str) and robot.digest and digest != robot.digest:
        raise InputError(f"{path}: made for another description of {robot.name!r} "
                         f"(SHA-256 {digest[:12]}..., this one {robot.digest[:12]}...): its "
                         "parameters belong to that robot model; recalibrate")


def save_json(path: str | Path, data: dict, fsync: bool = False) -> None:
    """Write JSON to a temp file and rename it over ``path``: a reader (or a resumed run)
    sees the old or the new file, never a torn one. The one JSON writer of planecal's
    files: a number that is not defined (NaN, an infinity) is written as null, never as
    NaN or Infinity (``formats.base.json_values``)."""
    path = Path(path)
    text = json.dumps(json_values(data), indent=2, default=_jsonable, allow_nan=False) + "\n"
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # disk full, a kill: no temp file left behind
        tmp.unlink(missing_ok=True)
        raise


def save_params(path: str | Path, p: CellParams) -> None:
    save_json(path, {"format": PARAMS_FORMAT, **params_to_dict(p)})


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"not JSON serializable: {type(v).__name__}")


def recorded_samples(doc: dict, result_path, flag: str = "--samples",
                     strict: bool = True) -> list[Path]:
    """The sample files a result's provenance records (role ``samples``), found here with
    the recorded content (relative paths: from the working directory, then beside the
    result). InputError for a recorded file that is missing or changed (naming ``flag``,
    the option that gives them instead); not ``strict``: those left out."""
    prov = doc.get("provenance") if isinstance(doc, dict) else None
    entries = prov.get("inputs") if isinstance(prov, dict) else None
    found = []
    for e in entries if isinstance(entries, list) else []:
        if not isinstance(e, dict) or e.get("role") != "samples" or not e.get("path"):
            continue
        p = Path(str(e["path"]))
        cands = [p] if p.is_absolute() else [p, Path(result_path).parent / p]
        hit = next((c for c in cands if c.is_file()), None)
        if hit is None and not strict:
            continue
        if hit is None:
            raise InputError(f"{result_path}: its samples file {p} is not here; give the "
                             f"calibration's samples with {flag}")
        with open(hit, "rb") as f:
            digest = hashlib.file_digest(f, "sha256").hexdigest()
        if e.get("sha256") and digest != e["sha256"]:
            if not strict:
                continue
            raise InputError(f"{hit}: not the samples file {result_path} was made from (its "
                             f"SHA-256 differs); give the calibration's samples with {flag}")
        found.append(hit)
    return found
