"""The parameter layout: which parameters a calibration problem has, in which order, in
which unit, and which of them are fitted by default.

Every module addresses parameters by name (``layout.index("delta3")``) or by group
(``layout.slice("sensor_origin")``, ``layout.columns("plane")``), never by an offset into
the vector: the layout is built once per problem and passed around, and the vector order,
the tables, the result files and the recordings all read their names from it.

A layout is an ordered sequence of groups; a group is an ordered sequence of parameters
of one *kind* (what the measurement model does with them: ``joint_offsets``,
``sensor_origin``, ``sensor_angles``, ``plane``), with an index among the groups of its
kind (``plane2`` is the ``plane`` group with index 1). Each parameter carries its SI unit,
its display scale and unit for printed tables, and the standard deviation above which the
fit calls it "not identifiable in practice" (the data barely depends on it).

Level 1 (seed chapter 5, ``level1_layout``): the joint offsets, the sensor (origin in the
flange frame, two beam angles) and one n~ per plane, in the order the seed uses (6.3).
A larger model (the whole kinematic chain per joint, a base frame, compliance) is more
groups of new kinds: a builder composes them, the measurement model fills their Jacobian
columns by ``slice``/``columns``, and nothing that only reads names changes.

This module sits low in the data path: it knows names and positions, not the model.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Iterable, Sequence

import numpy as np

from planecal.base.errors import InputError


@dataclass(frozen=True)
class Param:
    name: str
    unit: str  # SI unit of the value
    group: str  # name of the group that holds it
    display_scale: float  # printed value = value * display_scale, in display_unit
    display_unit: str
    practical_std: float  # a std above this: not identifiable in practice (SI unit)
    free_by_default: bool = True
    # a prior's std (SI unit) about the initial value: what the robot's class makes likely
    # (level 3's terms: the fit is a maximum a posteriori one); None: none
    prior_std: float | None = None


@dataclass(frozen=True)
class Group:
    name: str  # unique within a layout: "joint_offsets", "sensor_origin", "plane2"
    kind: str  # what the model does with it: "joint_offsets", "sensor_angles", "plane"
    index: int  # which group of its kind (plane2 -> 1); 0 for a kind that occurs once
    params: tuple[Param, ...]

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.params]

    def __len__(self) -> int:
        return len(self.params)


class ParamLayout:
    """An ordered set of named parameter groups (module docstring). Immutable."""

    def __init__(self, groups: Iterable[Group]):
        self._groups = tuple(groups)
        params = [p for g in self._groups for p in g.params]
        self._params = tuple(params)
        self._names = tuple(p.name for p in params)
        self._index = {n: i for i, n in enumerate(self._names)}
        if len(self._index) != len(self._names):
            dup = sorted({n for n in self._names if self._names.count(n) > 1})
            raise ValueError(f"parameter layout: names used twice: {', '.join(dup)}")
        by_name = {g.name: g for g in self._groups}
        if len(by_name) != len(self._groups):
            raise ValueError("parameter layout: two groups share a name")
        self._by_group = by_name
        self._slices = {}
        start = 0
        for g in self._groups:
            if any(p.group != g.name for p in g.params):
                raise ValueError(f"parameter layout: group {g.name} holds another group's parameter")
            self._slices[g.name] = slice(start, start + len(g))
            start += len(g)
        self._kinds: dict[str, list[Group]] = {}
        for g in self._groups:
            self._kinds.setdefault(g.kind, []).append(g)
        self._columns = {}
        for kind, gs in self._kinds.items():
            gs.sort(key=lambda g: g.index)
            if [g.index for g in gs] != list(range(len(gs))):
                raise ValueError(f"parameter layout: the {kind} groups are not numbered 0..{len(gs) - 1}")
            if len({len(g) for g in gs}) != 1:
                raise ValueError(f"parameter layout: the {kind} groups differ in size")
            cols = np.array([np.arange(self._slices[g.name].start, self._slices[g.name].stop)
                             for g in gs], int)
            cols.flags.writeable = False
            self._columns[kind] = cols

    # ----- names and positions -----
    @property
    def names(self) -> list[str]:
        return list(self._names)

    @property
    def units(self) -> list[str]:
        return [p.unit for p in self._params]

    @property
    def params(self) -> tuple[Param, ...]:
        return self._params

    @property
    def groups(self) -> tuple[Group, ...]:
        return self._groups

    def __len__(self) -> int:
        return len(self._names)

    def __repr__(self) -> str:
        return f"ParamLayout({', '.join(g.name for g in self._groups)}; {len(self)} parameters)"

    def _unknown(self, name: str) -> InputError:
        return InputError(f"unknown parameter {name!r}; known: {', '.join(self._names)}")

    def index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise self._unknown(name) from None

    def indices(self, names: Iterable[str]) -> np.ndarray:
        return np.array([self.index(n) for n in names], int)

    def param(self, name: str) -> Param:
        return self._params[self.index(name)]

    def group(self, name: str) -> Group:
        try:
            return self._by_group[name]
        except KeyError:
            raise KeyError(f"no parameter group {name!r} in {self!r}") from None

    def slice(self, group: str) -> slice:
        """The vector positions of one group (e.g. ``J[:, layout.slice("sensor_origin")]``)."""
        self.group(group)
        return self._slices[group]

    def groups_of(self, kind: str) -> list[Group]:
        """The groups of one kind, by their index."""
        return list(self._kinds.get(kind, []))

    def columns(self, kind: str) -> np.ndarray:
        """Vector positions of the groups of one kind, (groups, group size), read-only:
        row k holds the k-th group's positions (e.g. ``columns("plane")[plate]``)."""
        try:
            return self._columns[kind]
        except KeyError:
            raise KeyError(f"no parameter group of kind {kind!r} in {self!r}") from None

    @property
    def n_planes(self) -> int:
        return len(self._kinds.get("plane", []))

    # ----- display and limits -----
    def display(self, name: str) -> tuple[float, str]:
        """(scale, unit) to print a value or std of ``name``: value * scale in unit."""
        p = self.param(name)
        return p.display_scale, p.display_unit

    def practical_std(self, names: Sequence[str] | None = None) -> np.ndarray:
        """Practical identifiability limits of ``names`` (default: all), SI units."""
        ps = self._params if names is None else [self.param(n) for n in names]
        return np.array([p.practical_std for p in ps], float)

    # ----- free masks -----
    def mask(self, names: Iterable[str]) -> np.ndarray:
        """Boolean mask over the vector, True at ``names``."""
        m = np.zeros(len(self), bool)
        m[self.indices(list(names))] = True
        return m

    def names_of(self, mask: np.ndarray) -> list[str]:
        """The names where ``mask`` is True, in vector order."""
        mask = np.asarray(mask, bool)
        if mask.shape != (len(self),):
            raise ValueError(f"mask of {mask.shape} over a layout of {len(self)} parameters")
        return [n for n, f in zip(self._names, mask) if f]

    @property
    def default_free(self) -> np.ndarray:
        """The parameters a calibration fits unless told otherwise. In level 1, all but
        delta1 and delta6: no plane calibration can separate delta1 from the planes'
        rotation about the base z axis, nor delta6 from the sensor's roll about the flange
        axis (seed 6.2); freeing them gives directions the data cannot see."""
        return np.array([p.free_by_default for p in self._params], bool)

    def free_mask(self, free) -> np.ndarray:
        """A free mask from a bool mask, parameter names (a list or the --free comma
        string, "all") or None (``default_free``)."""
        if free is None:
            return self.default_free
        if isinstance(free, str):
            return self.free_from_names(free)
        arr = np.asarray(free)
        if arr.dtype == bool:
            if arr.shape != (len(self),):
                raise ValueError(f"free mask of {arr.shape} over {len(self)} parameters")
            return arr.copy()
        return self.free_from_names(list(free))

    def free_from_names(self, spec) -> np.ndarray:
        """The --free option: parameter names as a comma-separated string or a list; "all"
        frees everything; None or empty gives ``default_free``. InputError names an
        unknown parameter and lists the known ones."""
        if spec is None or (isinstance(spec, str) and not spec.strip()) or \
                (not isinstance(spec, str) and len(spec) == 0):
            return self.default_free
        wanted = [w.strip() for w in (spec.split(",") if isinstance(spec, str) else spec)]
        mask = np.zeros(len(self), bool)
        for name in filter(None, wanted):
            if name == "all":
                mask[:] = True
            elif name in self._index:
                mask[self._index[name]] = True
            else:
                raise InputError(f"--free: unknown parameter {name!r}; "
                                 f"known: {', '.join(self._names)}")
        if not mask.any():
            raise InputError(f"--free: no parameter named in {spec!r}")
        return mask


# ----- level 1: joint offsets, sensor, one n~ per plane ------------------------------------

RAD = dict(unit="rad", display_scale=1e6, display_unit="urad", practical_std=0.01)
METRE = dict(unit="m", display_scale=1e6, display_unit="um", practical_std=0.01)
# n~ components: |n~| ~ 1/distance of the plane from the base origin
PER_METRE = dict(unit="1/m", display_scale=1e3, display_unit="1e-3/m", practical_std=0.1)


def joint_offsets_group() -> Group:
    """delta1..delta6 [rad]: theta_i = q_i + delta_i + theta0_i. delta1 and delta6 are
    fixed by default (``ParamLayout.default_free``)."""
    name = "joint_offsets"
    return Group(name, name, 0, tuple(
        Param(f"delta{i}", group=name, free_by_default=i not in (1, 6), **RAD)
        for i in range(1, 7)))


def sensor_origin_group() -> Group:
    """o_x, o_y, o_z [m]: the beam origin in the flange frame."""
    name = "sensor_origin"
    return Group(name, name, 0, tuple(Param(f"o_{c}", group=name, **METRE) for c in "xyz"))


def sensor_angles_group() -> Group:
    """phi_y, phi_z [rad]: the beam z_f = Rz(phi_z) Ry(phi_y) e_z in the flange frame."""
    name = "sensor_angles"
    return Group(name, name, 0, tuple(Param(f"phi_{c}", group=name, **RAD) for c in "yz"))


def plane_group(k: int) -> Group:
    """n~ of plane k (0-based) in the base frame, named n{k+1}_x.. [1/m]: n~ . p = 1."""
    name = f"plane{k + 1}"
    return Group(name, "plane", k, tuple(Param(f"n{k + 1}_{c}", group=name, **PER_METRE)
                                         for c in "xyz"))


@lru_cache(maxsize=None)
def level1_layout(n_planes: int) -> ParamLayout:
    """The seed's model (levels of chapter 5: level 1, joint offsets): joint offsets,
    sensor origin and beam angles shared by all samples, one n~ per plane (seed 6.3). The
    vector order is [delta1..6, o_x, o_y, o_z, phi_y, phi_z, n1_x, n1_y, n1_z, n2_x, ...]."""
    if n_planes < 1:
        raise ValueError(f"a calibration needs at least one plane, got {n_planes}")
    return ParamLayout([joint_offsets_group(), sensor_origin_group(), sensor_angles_group(),
                        *(plane_group(k) for k in range(n_planes))])


# ----- level 2: the whole kinematic model (issue 13) ---------------------------------------

JOINT_GEOMETRY = ("alpha", "a", "beta", "d")  # per joint, modified DH (kinematics.py)
BASE_FRAME = ("x", "y", "z", "rx", "ry", "rz")
# compliance c = 1/k [rad/(N m)]: printed in urad per kN m; a std above 1e-5 rad/(N m)
# (a joint as soft as 1e5 N m/rad) is no stiffness the data has seen
COMPLIANCE = dict(unit="rad/(N m)", display_scale=1e9, display_unit="urad/kNm",
                  practical_std=1e-5)


def joint_geometry_group(j: int, parallel: tuple[int, ...]) -> Group:
    """Corrections of joint j's (1-based) modified-DH alpha{j}, a{j}, beta{j} (Hayati's,
    free by default only where axes j-1 and j are parallel), d{j}."""
    name = f"joint{j}"
    units = {"alpha": RAD, "a": METRE, "beta": RAD, "d": METRE}
    return Group(name, "joint_geometry", j - 1, tuple(
        Param(f"{k}{j}", group=name, free_by_default=(k != "beta" or j in parallel), **units[k])
        for k in JOINT_GEOMETRY))


def base_frame_group() -> Group:
    """The robot base in the cell: base_x, base_y, base_z [m], base_rx, base_ry, base_rz
    [rad] (kinematics.frame_error)."""
    name = "base"
    return Group(name, "base_frame", 0, tuple(
        Param(f"base_{c}", group=name, **(METRE if len(c) == 1 else RAD)) for c in BASE_FRAME))


def compliance_group(free_joints: tuple[int, ...] = (2, 3)) -> Group:
    """c1..c6 [rad/(N m)], theta_j += c_j tau_j(q) (gravity torque); c2, c3 free by default."""
    name = "compliance"
    return Group(name, name, 0, tuple(
        Param(f"c{j}", group=name, free_by_default=j in free_joints, **COMPLIANCE)
        for j in range(1, 7)))


@lru_cache(maxsize=None)
def level2_layout(n_planes: int, parallel: tuple[int, ...] = (3,),
                  compliance: bool = False) -> ParamLayout:
    """The whole kinematic model (seed chapter 5, level 2; level 3's joint compliance with
    ``compliance``): level 1's groups in level 1's order, then joint1..joint6 (modified-DH
    corrections), the base frame and the compliance. delta1 and delta6 stay fixed by
    default, as in level 1: no plane calibration can tell J1's zero from the plates' turn
    about the base z axis, nor J6's from the sensor's roll, whatever else is free; which of
    the other parameters the data can separate is decided from the data
    (``planecal.estimation.identifiability.select_base``), not assumed."""
    groups = list(level1_layout(n_planes).groups)
    groups += [joint_geometry_group(j, tuple(parallel)) for j in range(1, 7)]
    groups.append(base_frame_group())
    if compliance:
        groups.append(compliance_group())
    return ParamLayout(groups)


# ----- level 3: non-kinematic errors (seed 5.4) ---------------------------------------------

# a gear harmonic's amplitude [rad]: a reducer's transmission error is below 1 arcmin (291
# urad) peak to peak, so an amplitude is about 1e-4 rad (the prior's std); a std above 1 mrad
# is no harmonic the data has seen. Backlash alike (lost motion below 1 arcmin).
GEAR = dict(unit="rad", display_scale=1e6, display_unit="urad", practical_std=1e-3,
            prior_std=1e-4)
BACKLASH = dict(unit="rad", display_scale=1e6, display_unit="urad", practical_std=1e-3,
                prior_std=1e-4)
_GEAR_NAME = re.compile(r"h(\d+)_(\d+)([sc])")


def gear_name(joint: int, order: int, trig: str) -> str:
    """The name of joint ``joint``'s (1-based) harmonic of ``order`` cycles per output
    revolution: ``h3_40s`` is J3's sin(40 q3) amplitude, ``h3_40c`` its cos(40 q3)'s."""
    return f"h{joint}_{order}{trig}"


def gear_term(name: str) -> tuple[int, int, str]:
    """(joint 1-based, order, "s" or "c") of a gear harmonic's name (``gear_name``)."""
    m = _GEAR_NAME.fullmatch(name)
    if m is None:
        raise KeyError(f"{name!r} is not a gear harmonic's name")
    return int(m.group(1)), int(m.group(2)), m.group(3)


def gear_group(orders: tuple[tuple[int, ...], ...]) -> Group:
    """The gear transmission error of every joint (level 3): theta_j += sum_f h{j}_{f}s
    sin(f q_j) + h{j}_{f}c cos(f q_j), q_j the joint angle from the encoder model, f the
    reducer's periods per output revolution (``orders[j - 1]``, robot.json's
    ``transmission``)."""
    name = "gear"
    return Group(name, "gear", 0, tuple(
        Param(gear_name(j, f, t), group=name, **GEAR)
        for j, fs in enumerate(orders, 1) for f in fs for t in "sc"))


def backlash_group(n_joints: int = 6) -> Group:
    """b1..b6 [rad], each joint's lost motion (full width): theta_j -= b_j / 2 * side_j,
    side_j the flank the joint rests on (+1, -1; 0 unknown: the middle), from the recorded
    approach direction or the gravity torque (``planecal.model.measurement.backlash_sides``)."""
    name = "backlash"
    return Group(name, "backlash", 0, tuple(
        Param(f"b{j}", group=name, **BACKLASH) for j in range(1, n_joints + 1)))


# the laser's linearity: the ZS-LD80's is +-0.1 % of its 30 mm full scale (30 um, the
# prior's std)
LASER = dict(unit="m", display_scale=1e6, display_unit="um", practical_std=1e-4,
             prior_std=3e-5)
LASER_ORDERS = (1, 2)  # cycles over the laser's measuring range
_LASER_NAME = re.compile(r"lin(\d+)([sc])")


def laser_name(order: int, trig: str) -> str:
    """``lin1s``: the laser's linearity error's sin(2 pi x) amplitude, x the reading's place
    in the sensor's measuring range (0 at its near end, 1 at its far end)."""
    return f"lin{order}{trig}"


def laser_term(name: str) -> tuple[int, str]:
    """(order, "s" or "c") of a laser linearity parameter's name (``laser_name``)."""
    m = _LASER_NAME.fullmatch(name)
    if m is None:
        raise KeyError(f"{name!r} is not a laser linearity parameter's name")
    return int(m.group(1)), m.group(2)


def laser_group(orders: tuple[int, ...] = LASER_ORDERS) -> Group:
    """The laser's linearity error (level 3): a reading is d + sum_k lin{k}s sin(2 pi k x)
    + lin{k}c cos(2 pi k x), x = (d - near) / (far - near) over the sensor's measuring
    range (the scene's ``sensor.range_mm``; the ZS-LD80: +-0.1 % of its 30 mm)."""
    name = "laser"
    return Group(name, "laser", 0, tuple(
        Param(laser_name(k, t), group=name, **LASER) for k in orders for t in "sc"))


@lru_cache(maxsize=None)
def level3_layout(n_planes: int, parallel: tuple[int, ...],
                  orders: tuple[tuple[int, ...], ...]) -> ParamLayout:
    """Non-kinematic calibration (seed 5.4, level 3): the whole model with compliance
    (``level2_layout``), then every joint's gear harmonics and backlash, and the laser's
    linearity."""
    groups = list(level2_layout(n_planes, parallel, True).groups)
    return ParamLayout(groups + [gear_group(orders), backlash_group(len(orders)),
                                 laser_group()])


_KIND_OF_NAME = (  # a parameter's name -> its quantity (the groups above name them so)
    (r"delta\d+|phi_[yz]|alpha\d+|beta\d+|base_r[xyz]", RAD),
    (r"o_[xyz]|a\d+|d\d+|base_[xyz]", METRE),
    (r"n\d+_[xyz]", PER_METRE),
    (r"c\d+", COMPLIANCE),
    (r"h\d+_\d+[sc]", GEAR),
    (r"b\d+", BACKLASH),
    (r"lin\d+[sc]", LASER),
)


def layout_prior(layout: ParamLayout) -> tuple:
    """((name, std), ...): the prior of every parameter the layout gives one
    (``Param.prior_std``: level 3's gear harmonics, backlash and laser linearity)."""
    return tuple((p.name, p.prior_std) for p in layout.params if p.prior_std is not None)


def quantity_of(name: str) -> dict:
    """The unit, display scale and unit and practical std of a parameter named as the
    groups above name them (for files that hold names only: study results); KeyError for
    a name no group gives."""
    for pattern, q in _KIND_OF_NAME:
        if re.fullmatch(pattern, name):
            return {k: v for k, v in q.items() if k != "prior_std"}
    raise KeyError(f"no parameter group names a parameter {name!r}")


def display_of(name: str) -> tuple[float, str]:
    """(scale, unit) to print a value or std of the parameter ``name`` (``quantity_of``)."""
    q = quantity_of(name)
    return q["display_scale"], q["display_unit"]
