"""The cell's parameters (``CellParams``): the joint offsets, the sensor pose on the flange,
the planes, and the corrections of the nominal model (joint geometry, base frame,
compliance; level 3's gear harmonics and backlash); their vector goes through a ``planecal.model.layout.ParamLayout`` by group,
so no code knows an offset. The distance model that reads them is
``planecal.model.measurement``, one for every layout."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planecal.model.layout import Group, ParamLayout, gear_term, laser_term, level1_layout


@dataclass
class CellParams:
    joint_offsets: np.ndarray = field(default_factory=lambda: np.zeros(6))
    sensor_origin: np.ndarray = field(default_factory=lambda: np.zeros(3))
    phi_y: float = 0.0
    phi_z: float = 0.0
    planes: np.ndarray = field(default_factory=lambda: np.zeros((1, 3)))
    # corrections of the nominal model (planecal.model.measurement), zero by default
    geometry: np.ndarray | None = None  # (6, 4) per joint: modified-DH alpha, a, beta, d
    base: np.ndarray | None = None  # (6,) base frame error x, y, z [m], rx, ry, rz [rad]
    compliance: np.ndarray | None = None  # (6,) c_j = 1/k_j [rad/(N m)]
    # level 3: gear harmonics (joint 0-based, cycles per revolution) with their (sin, cos)
    # amplitudes [rad] (K, 2), and each joint's backlash (full width) [rad]
    gear_terms: tuple = ()
    gear: np.ndarray | None = None
    backlash: np.ndarray | None = None
    # the laser's linearity error: (sin, cos) amplitudes [m] (K, 2) of each order (cycles
    # over the measuring range ``laser_range_m``, the scene's)
    laser_orders: tuple = ()
    laser: np.ndarray | None = None
    laser_range_m: tuple = (0.065, 0.095)

    def __post_init__(self):
        self.geometry = (np.zeros((6, 4)) if self.geometry is None
                         else np.asarray(self.geometry, float).reshape(6, 4).copy())
        self.base = np.zeros(6) if self.base is None else np.asarray(self.base, float).reshape(6).copy()
        self.compliance = (np.zeros(6) if self.compliance is None
                           else np.asarray(self.compliance, float).reshape(6).copy())
        self.joint_offsets = np.asarray(self.joint_offsets, float).reshape(6)
        self.sensor_origin = np.asarray(self.sensor_origin, float).reshape(3)
        self.planes = np.asarray(self.planes, float).reshape(-1, 3)
        self.phi_y = float(self.phi_y)
        self.phi_z = float(self.phi_z)
        self.gear_terms = tuple((int(j), int(f)) for j, f in self.gear_terms)
        self.gear = (np.zeros((len(self.gear_terms), 2)) if self.gear is None
                     else np.asarray(self.gear, float).reshape(len(self.gear_terms), 2).copy())
        self.backlash = (np.zeros(6) if self.backlash is None
                         else np.asarray(self.backlash, float).reshape(6).copy())
        self.laser_orders = tuple(int(k) for k in self.laser_orders)
        self.laser = (np.zeros((len(self.laser_orders), 2)) if self.laser is None
                      else np.asarray(self.laser, float).reshape(-1, 2).copy())
        self.laser_range_m = (float(self.laser_range_m[0]), float(self.laser_range_m[1]))

    @property
    def n_planes(self) -> int:
        return len(self.planes)

    @property
    def has_corrections(self) -> bool:
        """Whether any geometry, base frame, compliance, gear or backlash correction is
        non-zero (else the model is robot.json's chain with joint offsets)."""
        return bool(self.geometry.any() or self.base.any() or self.compliance.any()
                    or self.gear.any() or self.backlash.any() or self.laser.any())

    @property
    def joint_errors(self) -> bool:
        """Whether the joint angles carry a pose-dependent error (compliance, gear,
        backlash): ``planecal.model.measurement.effective_joints``."""
        return bool(self.compliance.any() or self.gear.any() or self.backlash.any())

    def gear_amplitude(self, joint: int, order: int) -> np.ndarray:
        """(sin, cos) amplitude [rad] of joint ``joint``'s (0-based) harmonic ``order``
        (zero for a term these parameters do not hold)."""
        try:
            return self.gear[self.gear_terms.index((joint, order))]
        except ValueError:
            return np.zeros(2)

    def to_vector(self, layout: ParamLayout | None = None) -> np.ndarray:
        """The values in ``layout``'s order (default: the level-1 layout of this many planes)."""
        layout = layout or level1_layout(self.n_planes)
        x = np.empty(len(layout))
        for g in layout.groups:
            x[layout.slice(g.name)] = self._group_values(g)
        return x

    @classmethod
    def from_vector(cls, x: np.ndarray, layout: ParamLayout) -> "CellParams":
        """The parameters held by a vector in ``layout``'s order (the rest at their
        defaults; ``with_vector`` keeps another's)."""
        return cls(planes=np.zeros((layout.n_planes, 3))).with_vector(x, layout)

    # the one place that maps layout groups to fields (both directions)
    def _group_values(self, g: Group) -> np.ndarray:
        if g.kind == "joint_offsets":
            return self.joint_offsets
        if g.kind == "sensor_origin":
            return self.sensor_origin
        if g.kind == "sensor_angles":
            return np.array([self.phi_y, self.phi_z])
        if g.kind == "plane":
            return self.planes[g.index]
        if g.kind == "joint_geometry":
            return self.geometry[g.index]
        if g.kind == "base_frame":
            return self.base
        if g.kind == "compliance":
            return self.compliance
        if g.kind == "gear":
            out = []
            for name in g.names:
                j, f, t = gear_term(name)
                out.append(self.gear_amplitude(j - 1, f)["sc".index(t)])
            return np.array(out, float)
        if g.kind == "backlash":
            return self.backlash
        if g.kind == "laser":
            amp = dict(zip(self.laser_orders, self.laser))
            return np.array([amp.get(k, np.zeros(2))["sc".index(t)]
                             for k, t in map(laser_term, g.names)], float)
        raise ValueError(f"the cell model has no parameters of kind {g.kind!r}")

    def _set_group_values(self, g: Group, v: np.ndarray) -> None:
        if g.kind == "joint_offsets":
            self.joint_offsets = v.copy()
        elif g.kind == "sensor_origin":
            self.sensor_origin = v.copy()
        elif g.kind == "sensor_angles":
            self.phi_y, self.phi_z = float(v[0]), float(v[1])
        elif g.kind == "plane":
            self.planes[g.index] = v
        elif g.kind == "joint_geometry":
            self.geometry[g.index] = v
        elif g.kind == "base_frame":
            self.base = v.copy()
        elif g.kind == "compliance":
            self.compliance = v.copy()
        elif g.kind == "gear":
            terms = list(self.gear_terms)
            amp = {t: a for t, a in zip(terms, self.gear)}
            for name, value in zip(g.names, v):
                j, f, t = gear_term(name)
                key = (j - 1, f)
                if key not in amp:
                    terms.append(key)
                    amp[key] = np.zeros(2)
                amp[key] = amp[key].copy()
                amp[key]["sc".index(t)] = value
            self.gear_terms = tuple(terms)
            self.gear = np.array([amp[t] for t in terms], float).reshape(len(terms), 2)
        elif g.kind == "backlash":
            self.backlash = v.copy()
        elif g.kind == "laser":
            amp = {k: a.copy() for k, a in zip(self.laser_orders, self.laser)}
            for name, value in zip(g.names, v):
                k, t = laser_term(name)
                amp.setdefault(k, np.zeros(2))["sc".index(t)] = value
            self.laser_orders = tuple(amp)
            self.laser = np.array(list(amp.values()), float).reshape(-1, 2)
        else:
            raise ValueError(f"the cell model has no parameters of kind {g.kind!r}")

    def copy(self) -> "CellParams":
        """A copy whose arrays are its own (its fields already checked: no __post_init__,
        the fit copies once an iteration)."""
        p = object.__new__(CellParams)
        for name, v in self.__dict__.items():
            p.__dict__[name] = v.copy() if isinstance(v, np.ndarray) else v
        return p

    def with_vector(self, x: np.ndarray, layout: ParamLayout) -> "CellParams":
        """A copy with the values of a vector in ``layout``'s order (what the layout does
        not hold, e.g. the laser's measuring range, stays)."""
        x = np.asarray(x, float)
        if x.shape != (len(layout),):
            raise ValueError(f"a vector of {x.shape} for a layout of {len(layout)} parameters")
        p = self.copy()
        if p.n_planes != layout.n_planes:
            p.planes = np.zeros((layout.n_planes, 3))
        for g in layout.groups:
            p._set_group_values(g, x[layout.slice(g.name)])
        return p
