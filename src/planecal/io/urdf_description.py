"""robot.json's document for an imported URDF (``planecal robot import``;
``io.urdf_import`` reads the chain, shapes and masses): the chain as written (numbers to
1e-12, angles within 1e-11 rad of a multiple of 90 deg as that multiple), the joint
limits and names, and the encoder and controller model a URDF does not have
(``EncoderSettings``: counts per revolution, zero at mid-range, the tick, the step and
trip limits from the joints' URDF velocities, ``DEFAULT_VELOCITY`` for a joint without
one, said in a warning), the masses and optionally the payload and repeatability.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.io.urdf_import import N, Imported
from planecal.model.kinematics import rpy_angles

DEFAULT_VELOCITY = 1.0  # rad/s: a joint whose URDF gives no velocity (the controller model's)


@dataclass(frozen=True)
class EncoderSettings:
    """The encoder and controller model an imported robot gets (the URDF has none)."""
    counts_per_rev: int = 1 << 20
    bits: int = 24
    tick_s: float = 0.008
    speed_fraction: float = 0.1  # of the slowest joint's URDF velocity, per tick
    max_step_counts: int | None = None
    trip_step_counts: int | None = None
    repeatability_mm: float | None = None  # None: not written (model.robot's default)
    payload_kg: float | None = None
    controller: str | None = None


def description(path: Path, imp: Imported, name: str, enc: EncoderSettings) -> dict:
    """robot.json's document for an import (module docstring)."""
    gain = enc.counts_per_rev / (2 * math.pi)
    zero = 1 << (enc.bits - 1)
    steps = _steps(path, imp, gain, enc)
    home_q = np.where((imp.limits[:, 0] <= 0) & (imp.limits[:, 1] >= 0), 0.0,
                      imp.limits.mean(axis=1))
    kin = imp.kin
    doc = {
        "format": "planecal-robot/1", "name": name,
        "source": (f"imported from {path.name} (URDF robot {imp.name!r}, base link "
                   f"{imp.root!r}, flange link {imp.tip!r}) by planecal robot import"),
        "chain": {
            "convention": "modified DH with Hayati's beta: T = B prod_i Rx(alpha_i) Tx(a_i) "
                          "Ry(beta_i) Rz(theta0_i + q_i) Tz(d_i) F (planecal.model.kinematics); "
                          "q = the URDF's joint values",
            "joints": [{"alpha_rad": _r(kin.alpha[i], True), "a_m": _r(kin.a[i]),
                        "beta_rad": _r(kin.beta[i], True),
                        "theta0_rad": _r(kin.theta[i], True), "d_m": _r(kin.d[i])}
                       for i in range(N)],
            "base": _frame(kin.base), "flange": _frame(kin.flange)},
        "joint_names": [j.name for j in imp.joints],
        "joint_limits_deg": [[round(float(np.rad2deg(lo)), 9), round(float(np.rad2deg(hi)), 9)]
                             for lo, hi in imp.limits],
        "encoder": {"gain_counts_per_rad": [gain] * N, "offset_counts": [zero] * N,
                    "bits": enc.bits, "coupling": [],
                    "coupling_note": f"not in the URDF: {enc.counts_per_rev} counts per "
                                     "revolution of the joint, zero at mid-range, coupling "
                                     "as given (planecal robot import's settings; "
                                     "C = I but for the entries listed)"},
        "inverse_kinematics": None,
        "controller": {"kind": enc.controller, "tick_s": enc.tick_s,
                       "max_step_counts": steps[0], "trip_step_counts": steps[1],
                       "home_counts": [int(round(zero + gain * q)) for q in home_q]},
        "masses_source": ("the URDF's <inertial> elements, in each link's frame (links fixed "
                          "to the base carry no joint torque and are left out)"
                          if imp.masses else "the URDF has no masses on its moving links"),
        "masses": imp.masses,
    }
    if enc.payload_kg is not None:
        doc["payload_kg"] = enc.payload_kg
    if enc.repeatability_mm is not None:
        doc["repeatability_mm"] = enc.repeatability_mm
    return doc


def _steps(path: Path, imp: Imported, gain: float, enc: EncoderSettings) -> tuple[int, int]:
    """(max, trip) step counts per tick: given, or from the URDF's joint velocities."""
    if enc.max_step_counts is not None and enc.trip_step_counts is not None:
        return enc.max_step_counts, enc.trip_step_counts
    vel = imp.velocities.copy()
    none = [j.name for j, v in zip(imp.joints, vel) if not v > 0]
    if none:
        vel[vel <= 0] = DEFAULT_VELOCITY
        imp.warnings.append(
            f"joints {', '.join(none)} have no velocity limit in the URDF: the controller "
            f"model takes {DEFAULT_VELOCITY:g} rad/s ({np.rad2deg(DEFAULT_VELOCITY):.0f} deg/s) "
            "for them; give --max-step-counts and --trip-step-counts for the real controller")
    slow = int(np.argmin(vel))
    # a hair of rounding forgiven: planecal urdf writes trip / (gain tick) as the velocity
    full = vel[slow] * gain * enc.tick_s * (1 + 1e-12)
    trip = enc.trip_step_counts or max(2, int(full))
    step = enc.max_step_counts or max(1, min(trip - 1, int(enc.speed_fraction * full)))
    return step, trip


def _frame(T: np.ndarray) -> dict:
    return {"xyz_m": [_r(v) for v in T[:3, 3]],
            "rpy_rad": [_r(v, True) for v in rpy_angles(T[:3, :3])]}


def _r(v, angle: bool = False) -> float:
    """A chain number as written: rounded to 1e-12 (m or rad; the flange moves < 1e-11 m),
    so that 0.035 is not 0.03500000000000003 and no -6e-17 stands for 0; an angle within
    1e-11 rad of a multiple of 90 deg is that multiple (the URDF's axes are mostly so; the
    flange moves < 1e-10 m)."""
    x = float(v)
    if angle and abs(x - round(x / (np.pi / 2)) * (np.pi / 2)) < 1e-11:
        x = round(x / (np.pi / 2)) * (np.pi / 2)
        return 0.0 if x == 0 else x
    x = round(x, 12)
    return 0.0 if x == 0 else x
