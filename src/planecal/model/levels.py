"""What a calibration level is, in one place: a parameter layout (which parameters the model
has and which are free by default), never a branch in the code that fits or uses it
(seed chapter 5).

    offsets (level 1)  the joint offsets, the sensor, one plane per plate
    full    (level 2)  the whole kinematic model: per joint modified-DH alpha, a, beta
                       (where axes are parallel), d; the base frame; the sensor; the planes
    compliance         J2 and J3's joint compliance (gravity torque from robot.json's link
                       masses; seed 5.4), at either level
    nonkinematic       (level 3, seed 5.4) the whole model with compliance, each joint's
                       gear harmonics (robot.json's ``transmission`` orders) and backlash
                       (its flank from the recorded approach direction or the gravity
                       torque: ``measurement.backlash_sides``)

The seed's names "1", "2" and "3" are accepted for offsets, full and nonkinematic. The arm's scale (its two
longest link lengths, ``scale_lengths``) is in the whole model's layout but is kept fixed
unless a length reference fixes the scale (a plane and a laser see it only through the
laser's gain).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from planecal.base.errors import InputError

if TYPE_CHECKING:  # (the names a level means come first: every command's --level choices)
    from planecal.model.layout import ParamLayout
    from planecal.model.robot import Robot

LEVELS = ("offsets", "full", "nonkinematic")
ALIASES = {"1": "offsets", "2": "full", "3": "nonkinematic"}
PLANE_BLIND_OFFSETS = ("delta1", "delta6")  # turns of the plates / the sensor's roll


# level 3's terms trade with the joint geometry (J1-J3's once-per-revolution harmonics
# above all): its fit pulls the geometry towards robot.json's with a machining and assembly
# tolerance class (0.2 mm, 0.2 mrad; --geometry-prior changes it)
DEFAULT_GEOMETRY_PRIOR = {"nonkinematic": (2e-4, 2e-4)}


def whole_model(level: str) -> bool:
    """Whether a level frees the kinematic model beyond the joint offsets (levels 2, 3)."""
    return level_name(level) != "offsets"


def with_compliance(level: str, compliance: bool) -> bool:
    """Whether a level's model has the joint compliance: asked for, or level 3's."""
    return compliance or level_name(level) == "nonkinematic"


def level_name(level: str) -> str:
    """A level's name (``LEVELS``) from a level or the seed's number; InputError otherwise."""
    name = ALIASES.get(str(level), str(level))
    if name not in LEVELS:
        raise InputError(f"unknown level {level!r}: one of {', '.join(LEVELS)} "
                         f"(the seed's {', '.join(ALIASES)})")
    return name


def layout_for(robot: Robot, n_planes: int, level: str = "offsets",
               compliance: bool = False) -> ParamLayout:
    """The parameter layout of a level (module docstring); level 3 always has compliance."""
    from planecal.model.kinematics import parallel_pairs
    from planecal.model.layout import (ParamLayout, compliance_group, level1_layout,
                                       level2_layout, level3_layout)
    name = level_name(level)
    if name == "offsets":
        base = level1_layout(n_planes)
        return base if not compliance else ParamLayout(list(base.groups) + [compliance_group()])
    parallel = tuple(i + 1 for i in parallel_pairs(robot.kinematics))
    if name == "full":
        return level2_layout(n_planes, parallel, compliance)
    return level3_layout(n_planes, parallel, robot.gear_orders)


def scale_lengths(robot: Robot, k: int = 2) -> list[str]:
    """The ``k`` longest link lengths of the robot's model (``a{j}``/``d{j}`` names; the
    MC70: a3 = 0.9 m, d4 = 0.99 m). Together with the planes' distances they set the arm's
    scale, which 65-95 mm laser readings see only through the sensor's own gain: a gain
    error of 0.1 % (the ZS-LD80's linearity class) makes a free-scale fit put the tool up
    to 2 mm off over a 2 m reach (docs/STUDIES.md, "Level 2")."""
    kin = robot.kinematics
    lengths = [(abs(v), f"a{j + 1}") for j, v in enumerate(kin.a)]
    lengths += [(abs(v), f"d{j + 1}") for j, v in enumerate(kin.d)]
    return [name for _, name in sorted(lengths, reverse=True)[:k]]


def pinned_scale(robot: Robot, layout: ParamLayout) -> list[str]:
    """The scale lengths a layout holds (fixed unless a length reference frees them)."""
    return [n for n in scale_lengths(robot) if n in layout.names]


# The robot class's magnitudes of what the levels model beyond the cell's frames and the
# joint offsets: the reference model of ``estimation.reference`` (what a calibration's
# figures at the tool are judged against) puts a prior of these stds on each, scaled by one
# factor the samples choose. Geometry: level 3's machining and assembly class (as
# ``DEFAULT_GEOMETRY_PRIOR``); the base frame: a floor mounting's millimetre and milliradian;
# compliance: a deflection of 0.5 mrad at the largest gravity torque the samples put on the
# joint (the realistic MC70's J2 deflects 0.2-0.4 mrad, a UR5's shoulder ~1.8 mrad); level
# 3's terms: their layout priors (``layout.prior_std``).
CLASS_GEOMETRY = (2e-4, 2e-4)  # m, rad
CLASS_BASE = (1e-3, 1e-3)  # m, rad
CLASS_DEFLECTION_RAD = 5e-4


def class_std(layout: ParamLayout, name: str, torque_max_nm) -> float:
    """The class std (above) of parameter ``name`` of ``layout``, inf for the cell's frames
    and the joint offsets (no class: the data alone); ``torque_max_nm`` (6,): each joint's
    largest gravity torque over the samples (a compliance's)."""
    p = layout.param(name)
    kind = layout.group(p.group).kind
    if kind == "joint_geometry":
        return CLASS_GEOMETRY[0] if p.unit == "m" else CLASS_GEOMETRY[1]
    if kind == "base_frame":
        return CLASS_BASE[0] if p.unit == "m" else CLASS_BASE[1]
    if kind == "compliance":
        return CLASS_DEFLECTION_RAD / max(float(torque_max_nm[int(name[1:]) - 1]), 1.0)
    return float("inf") if p.prior_std is None else float(p.prior_std)
