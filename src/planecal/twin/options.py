"""The twin's options: which error sources it runs and how large (an error profile's,
``twin.profile.ErrorProfile.options``; ``TwinOptions.exact()`` turns every one off)."""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from planecal.base.errors import InputError
from planecal.twin.errors import JointErrors


@dataclass(frozen=True)
class TwinOptions:
    """Behaviour of the twin. ``exact()`` turns every error source off.

    servo: 'ideal' or 'lag' (first order, ``tau_s``); laser_noise_mm: Gaussian std of a
    reading; laser_quantum_mm: rounding of a reading; repeatability_mm: None = the
    robot's (robot.json), 0 = off; stiffness_nm_per_rad: the stiffness of each joint that
    yields to gravity, 6 values (None: rigid) or (k2, k3), None = all rigid; backlash_rad:
    (6,) backlash, None = off; backlash_preload_nm: (6,) the gravity torque that holds a
    joint on one flank of its backlash (None or 0: by the direction of motion);
    laser_linearity_mm: amplitude of the laser's linearity error (0.7 and 0.3 of it at one
    and two periods over the window, phases from the truth); quantization: the motors'
    sub-count positions; gear:
    harmonics of the gear transmission error, (joint 1-based, amplitude rad, cycles per
    revolution) each, their phases from the truth; payload: (mass kg, centre of mass in
    the flange frame m) of the tool, for the gravity torque; noise_seed: seed of the noise
    streams (None: derived from the truth seed); check_steps: trip on FD11 encoder jumps.
    An error profile (``twin.profile``) makes these from its file."""
    servo: str = "lag"
    tau_s: float = 0.03
    laser_noise_mm: float = 0.001
    laser_quantum_mm: float | None = None
    laser_linearity_mm: float = 0.0
    repeatability_mm: float | None = None
    stiffness_nm_per_rad: tuple | None = None
    backlash_rad: tuple | None = None
    backlash_preload_nm: tuple | None = None
    quantization: bool = False
    gear: tuple = ()
    payload: tuple | None = None
    thermal: tuple | None = None
    noise_seed: int | None = None
    check_steps: bool = True

    def __post_init__(self):
        if self.servo not in ("ideal", "lag"):
            raise InputError(f"twin: servo must be 'ideal' or 'lag', got {self.servo!r}")
        for name in ("tau_s", "laser_noise_mm", "laser_quantum_mm", "repeatability_mm",
                     "laser_linearity_mm"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v >= 0 and (v > 0 or name != "tau_s")):
                raise InputError(f"twin: {name} must be a finite number >= 0"
                                 f"{' (> 0)' if name == 'tau_s' else ''}, got {v!r}")

    @classmethod
    def exact(cls, **kw) -> "TwinOptions":
        base = cls(servo="ideal", laser_noise_mm=0.0, repeatability_mm=0.0)
        return replace(base, **kw)

    def joint_errors(self, robot, gear_phases=()) -> JointErrors:
        """The tick's joint errors; ``gear_phases``: the truth's, one per harmonic (none:
        all 0; options without gear harmonics ignore them)."""
        rep = robot.repeatability_m if self.repeatability_mm is None else self.repeatability_mm * 1e-3
        comp = None
        if self.stiffness_nm_per_rad is not None:
            k = list(self.stiffness_nm_per_rad)
            k = [None, *k, None, None, None] if len(k) == 2 else k
            comp = tuple(0.0 if v is None else 1.0 / float(v) for v in k)
        phases = tuple(gear_phases) if self.gear else ()
        phases = phases or (0.0,) * len(self.gear)
        if len(phases) != len(self.gear):
            raise InputError(f"twin: {len(phases)} gear phases for {len(self.gear)} harmonics")
        gear = [[] for _ in range(robot.n_joints)]
        for (joint, amp, cycles), phi in zip(self.gear, phases):
            gear[int(joint) - 1].append((amp, cycles, phi))
        return JointErrors(repeatability_m=rep, quantization=self.quantization,
                           gear=tuple(tuple(g) for g in gear), backlash_rad=self.backlash_rad,
                           backlash_preload_nm=self.backlash_preload_nm,
                           compliance_rad_per_nm=comp)
