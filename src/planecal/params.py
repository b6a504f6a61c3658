"""Parameter files (JSON), the format others script against:

    {"joint_offsets_rad": [6 numbers],
     "planes": [{"n_tilde": [x, y, z]}, ...],
     "sensor": {"origin_m": [x, y, z], "phi_y_rad": .., "phi_z_rad": ..}}

Result files hold the same keys plus ``std`` (same shape, null where not identifiable),
``residual_rms_mm``, ``iterations``, ``outliers`` and ``identifiability``.
"""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from planecal.cell import CellParams
from planecal.errors import InputError


def params_to_dict(p: CellParams) -> dict:
    return {
        "joint_offsets_rad": [float(v) for v in p.joint_offsets],
        "planes": [{"n_tilde": [float(v) for v in n]} for n in p.planes],
        "sensor": {"origin_m": [float(v) for v in p.sensor_origin],
                   "phi_y_rad": float(p.phi_y), "phi_z_rad": float(p.phi_z)},
    }


def _numbers(path, key, value, n):
    if not isinstance(value, list) or len(value) != n:
        raise InputError(f"{path}: '{key}' must be a list of {n} numbers")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{path}: '{key}' holds {v!r}, not a finite number")
        out.append(float(v))
    return out


def params_from_dict(d: dict, path: str = "<params>") -> CellParams:
    if not isinstance(d, dict):
        raise InputError(f"{path}: a parameter file is a JSON object")
    for key in ("joint_offsets_rad", "planes", "sensor"):
        if key not in d:
            raise InputError(f"{path}: missing key '{key}'")
    offsets = _numbers(path, "joint_offsets_rad", d["joint_offsets_rad"], 6)
    planes = d["planes"]
    if not isinstance(planes, list) or not planes:
        raise InputError(f"{path}: 'planes' must be a non-empty list of {{\"n_tilde\": [x, y, z]}}")
    n = [_numbers(path, f"planes[{i}].n_tilde", (p or {}).get("n_tilde") if isinstance(p, dict)
                  else None, 3) for i, p in enumerate(planes)]
    s = d["sensor"]
    if not isinstance(s, dict):
        raise InputError(f"{path}: 'sensor' must be an object")
    origin = _numbers(path, "sensor.origin_m", s.get("origin_m"), 3)
    angles = _numbers(path, "sensor.phi_y_rad/phi_z_rad", [s.get("phi_y_rad"), s.get("phi_z_rad")], 2)
    return CellParams(offsets, origin, angles[0], angles[1], n)


def load_json(path: str | Path) -> dict:
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}:{e.lineno}: invalid JSON: {e.msg}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None


def load_params(path: str | Path) -> CellParams:
    return params_from_dict(load_json(path), str(path))


def save_json(path: str | Path, data: dict, fsync: bool = False) -> None:
    """Write JSON to a temp file and rename it over ``path``: a reader (or a resumed run)
    sees the old or the new file, never a torn one."""
    path = Path(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(json.dumps(data, indent=2, default=_jsonable) + "\n")
            if fsync:
                f.flush()
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:  # disk full, a kill: no temp file left behind
        tmp.unlink(missing_ok=True)
        raise


def save_params(path: str | Path, p: CellParams) -> None:
    save_json(path, params_to_dict(p))


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    raise TypeError(f"not JSON serializable: {type(v).__name__}")
