"""Robot description, loaded from models/<robot>/robot.json: the nominal kinematic chain,
joint limits, encoder model, controller limits and link masses.

robot.json holds standard DH (MODEL-NOTES), ``T_i = Rz(theta_i) Tz(d_i) Tx(a_i)
Rx(alpha_i)`` with ``theta_i = q_i + delta_i + theta0_i``; ``q`` are joint angles from the
encoder model and ``delta`` the joint offsets that calibration identifies. The chain every
computation uses is ``Robot.kinematics`` (``planecal.model.kinematics``: modified DH with
Hayati's beta, made from that table exactly). SI units (m, rad).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.formats.base import read_json, validate
from planecal.formats.robot import RobotFile
from planecal.base.paths import data_folder
from planecal.model.kinematics import Kinematics, from_standard_dh

DEFAULT_ROBOT = "mc70"


@dataclass(frozen=True)
class Robot:
    name: str
    theta0: np.ndarray  # (6,) rad
    d: np.ndarray  # (6,) m
    a: np.ndarray  # (6,) m
    alpha: np.ndarray  # (6,) rad
    limits: np.ndarray  # (6, 2) rad, [lower, upper]
    gains: np.ndarray  # (6,) counts/rad
    qe0: np.ndarray  # (6,) counts at the zero reference
    coupling: np.ndarray  # (6, 6) C with q = C x
    encoder_bits: int
    ik_kind: str | None
    repeatability_m: float
    tick_s: float
    max_step_counts: int
    trip_step_counts: int
    home_counts: np.ndarray  # (6,) int64
    source: Path | None = None
    # (standard DH frame, centre of mass in it [m] (3,), mass [kg]): the arm's masses
    masses: tuple = ()
    kinematics: Kinematics | None = None  # the nominal chain (made from the DH table)
    digest: str = ""  # SHA-256 of the description's content (``description_digest``)

    def __post_init__(self):
        if self.kinematics is None:
            object.__setattr__(self, "kinematics",
                               from_standard_dh(self.theta0, self.d, self.a, self.alpha))

    @property
    def n_joints(self) -> int:
        return len(self.d)

def load_robot(name_or_path: str | Path = DEFAULT_ROBOT) -> Robot:
    """Load a robot description: a name under models/ (``mc70``) or a path to robot.json.
    Validated by ``planecal.formats.robot.RobotFile``; one-line InputError otherwise."""
    p = Path(name_or_path)
    if not p.suffix and len(p.parts) == 1:  # a name, not a path
        p = data_folder("models") / str(name_or_path) / "robot.json"
    raw = read_json(p, "robot description")
    rf = validate(RobotFile, raw, p, "robot description")
    enc, ctrl = rf.encoder, rf.controller
    return Robot(
        name=rf.name,
        theta0=np.array([j.theta0_rad for j in rf.dh]),
        d=np.array([j.d_m for j in rf.dh]),
        a=np.array([j.a_m for j in rf.dh]),
        alpha=np.array([j.alpha_rad for j in rf.dh]),
        limits=np.deg2rad(np.array(rf.joint_limits_deg, float)),
        gains=np.array(enc.gain_counts_per_rad, float),
        qe0=np.array(enc.offset_counts, float),
        coupling=enc.coupling_matrix(),
        encoder_bits=enc.bits,
        ik_kind=rf.inverse_kinematics,
        repeatability_m=rf.repeatability_mm * 1e-3,
        tick_s=ctrl.tick_s,
        max_step_counts=ctrl.max_step_counts,
        trip_step_counts=ctrl.trip_step_counts,
        home_counts=np.array(ctrl.home_counts, np.int64),
        source=p,
        masses=tuple((m.frame, np.array(m.com_m, float), m.mass_kg) for m in rf.masses),
        digest=description_digest(raw),
    )


def description_digest(raw) -> str:
    """SHA-256 of a robot description's content (canonical JSON: key order and spacing do
    not matter): what a result records to say which robot it was made for."""
    text = json.dumps(raw, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(text.encode()).hexdigest()


def within_limits(robot: Robot, q: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    q = np.asarray(q, float)
    return np.all((q >= robot.limits[:, 0] - tol) & (q <= robot.limits[:, 1] + tol), axis=-1)
