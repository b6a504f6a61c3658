"""Does a cell identify what it is meant to calibrate? ``planecal scene new``'s check of
each cell it builds, on the pose plan the cell's default run would use.

The plan: the poses the sampling run itself visits for the default 150 samples and seed
0 (``planning.run_design``: the ``Planner``, IK from the previous pose, target and path
collision-checked), and their robot time (``sampling.tour``). On them, the calibration's
own base-set selection at the asked ``level`` (``calibrate.base_set``) and the predicted
covariance of the base set under the twin's noise model (``design.design_covariances``,
the sandwich std that ``plan`` and ``layouts`` predict).

The bound: every parameter of the level that moves the tool point (the arm's and the
sensor's) must be determined well enough that its predicted std alone moves the tool
point by at most ``BOUND_MM``, RMS over the run's poses (its std times its column of the
tool point's Jacobian, ``design.tool_rows``: the beam point at the standoff, in the
robot's frame). The plates' parameters (the cell's, not the robot's: they do not move
the tool point) are held to ``PRACTICAL_SHARE`` of their ``practical_std`` (what
``calibrate`` calls identifiable in practice). Every joint offset the level frees
(delta2..delta5: a plane cannot see delta1, delta6) must be in the base set. Chosen on
thesis_final (one plate: 0.056 mm at most), ur5_table (0.091 mm), the KR 16's and the IRB
4600's one-plate cells (0.064, 0.073 mm), the MC70's default one-plate cell (0.069 mm);
the KR 210's one-plate cell, whose delta2 is 0.9995 correlated with the plate's normal,
gives 0.91 mm (two plates: 0.068 mm).

That at level offsets. At full and nonkinematic, whose parameters are many and
correlated (the tool point's error is what they are for, stated beside), every
parameter is held to ``PRACTICAL_SHARE`` of its practical std (the realistic world's
mismatch inflates a fit's std over the noise model's: the KR 210's one-plate cell at
level full is at 0.95 of it, and its calibration there could not identify delta4 and
alpha2; three plates: 0.094).

The robot time per sample is stated against thesis_final's (``REFERENCE_S_PER_SAMPLE``:
17 s, measured the same way) and warned about above ``SLOW_FACTOR`` times it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planecal.base.errors import InputError

BOUND_MM = 0.2  # a parameter's predicted std may move the tool point this much at most
PRACTICAL_SHARE = 0.5  # of its practical std, a parameter held to that (module docstring)
SAMPLES = 150  # the default run's (rehearse, sample)
REFERENCE_S_PER_SAMPLE = 17.1  # thesis_final's default run, measured as here
SLOW_FACTOR = 3.0


@dataclass
class CellVerdict:
    """What ``check_cell`` found (module docstring)."""
    level: str
    plates: int
    samples: int
    ok: bool
    worst: str  # the parameter nearest (or furthest past) its bound
    worst_mm: float  # its effect at the tool [mm] (level offsets)
    tool_mm: float  # predicted tool-point error, 1 sigma, the noise model's [mm]
    seconds_per_sample: float
    reasons: list[str] = field(default_factory=list)  # why not, each naming a parameter
    worst_practical: tuple = ("", 0.0)  # (parameter, std / practical std) of those so held

    def line(self) -> str:
        """One line: the verdict, the predicted tool error and the robot time."""
        head = (f"{self.plates} plate(s), level {self.level}, the default run's "
                f"{self.samples} poses: ")
        held = (f"the others' at most {self.worst_practical[1]:.2g} of their practical std "
                f"({self.worst_practical[0]})")
        what = ((f"identifiable: every parameter's predicted std moves the tool point "
                 f"{self.worst_mm:.3g} mm at most (bound {BOUND_MM:g} mm; {self.worst}), "
                 if self.worst else "identifiable: ") + held
                if self.ok else "not identifiable: " + "; ".join(self.reasons[:3])
                + (f" (and {len(self.reasons) - 3} more)" if len(self.reasons) > 3 else ""))
        return (f"{head}{what}; predicted tool error {self.tool_mm:.3g} mm (1 sigma, the "
                f"noise model's); robot time {self.seconds_per_sample:.3g} s per sample "
                f"(thesis_final: {REFERENCE_S_PER_SAMPLE:g} s)")

    def slow(self) -> bool:
        return self.seconds_per_sample > SLOW_FACTOR * REFERENCE_S_PER_SAMPLE


def check_cell(scene, level: str = "offsets", samples: int = SAMPLES, seed: int = 0,
               checker=None) -> CellVerdict:
    """The cell's verdict at ``level`` (module docstring)."""
    from planecal.estimation.calibrate import CalibrationSettings, base_set
    from planecal.estimation.noise import repeatability_sigma, sample_sigma_m
    from planecal.model.encoder import counts_to_joints, joints_to_counts
    from planecal.model.levels import PLANE_BLIND_OFFSETS
    from planecal.model.measurement import predict_with_jacobian
    from planecal.model.scene import nominal_params
    from planecal.safety.collision import CollisionWorld
    from planecal.sampling import tour
    from planecal.studies.design import design_covariances, predicted_tool_mm, tool_rows
    from planecal.studies.planning import run_design

    robot = scene.robot
    settings = CalibrationSettings(level=level)
    level = settings.level
    checker = CollisionWorld(scene) if checker is None else checker
    try:
        qe, plate, visits = run_design(scene, samples, seed, checker, with_visits=True)
    except InputError as e:
        return CellVerdict(level, len(scene.plates), samples, False, "", np.inf, np.inf,
                           np.inf, [str(e)])
    start = joints_to_counts(robot, scene.calibration_q)
    per = tour.robot_time_s(visits, start, robot) / max(len(qe), 1)
    nominal = nominal_params(scene)
    layout, bs = base_set(robot, qe, nominal, plate, settings)
    free = bs.mask(layout)
    _, J = predict_with_jacobian(robot, qe, nominal, plate, layout)
    cov = design_covariances(J, layout, free, repeatability_sigma(robot, robot.repeatability_m),
                             sample_sigma_m(0.001))["sandwich"]
    std = np.sqrt(np.diag(cov))
    T = tool_rows(scene, counts_to_joints(robot, qe), nominal, layout, free)
    tool = predicted_tool_mm(T, cov)
    # each parameter's lever: how far a unit of it moves the tool point, RMS over the poses
    levers = np.sqrt(np.mean(np.sum(T ** 2, axis=1), axis=0))
    reasons, worst, worst_mm, practical = [], "", 0.0, ("", 0.0)
    wanted = [n for n in layout.group("joint_offsets").names if n not in PLANE_BLIND_OFFSETS]
    for name in wanted:
        if name not in bs.base:
            why = next((e.reason for e in bs.excluded if e.parameter == name), "not free")
            reasons.append(f"{name} cannot be determined ({why})")
    corr = cov / np.outer(std, std)
    for k, name in enumerate(bs.base):
        lever = levers[k] if settings.level == "offsets" and levers[k] > 0 else None
        if lever is None:
            ratio = std[k] / layout.practical_std([name])[0]
            practical = max(practical, (name, ratio), key=lambda t: t[1])
            if ratio > PRACTICAL_SHARE:
                reasons.append(f"{name}'s predicted std {std[k]:.3g} is {ratio:.2g} of its "
                               f"practical std (bound {PRACTICAL_SHARE:g})")
            continue
        mm = std[k] * lever * 1e3
        if mm > worst_mm:
            worst, worst_mm = name, mm
        if mm > BOUND_MM:
            c = np.abs(corr[k]).copy()
            c[k] = 0
            j = int(np.argmax(c))
            reasons.append(f"{name}'s predicted std {std[k]:.3g} {layout.param(name).unit} moves "
                           f"the tool point {mm:.3g} mm (bound {BOUND_MM:g} mm; correlated "
                           f"{corr[k, j]:.4f} with {bs.base[j]})")
    return CellVerdict(level, len(scene.plates), int(len(qe)), not reasons, worst, worst_mm,
                       tool, per, reasons, practical)
