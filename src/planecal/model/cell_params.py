"""The cell's parameters (``CellParams``): the joint offsets, the sensor pose on the flange,
the planes, and the corrections of the nominal model (joint geometry, base frame,
compliance); their vector goes through a ``planecal.model.layout.ParamLayout`` by group,
so no code knows an offset. The distance model that reads them is
``planecal.model.measurement``, one for every layout."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from planecal.model.layout import Group, ParamLayout, level1_layout


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

    @property
    def n_planes(self) -> int:
        return len(self.planes)

    @property
    def has_corrections(self) -> bool:
        """Whether any geometry, base frame or compliance correction is non-zero (else the
        model is robot.json's chain with joint offsets)."""
        return bool(self.geometry.any() or self.base.any() or self.compliance.any())

    def to_vector(self, layout: ParamLayout | None = None) -> np.ndarray:
        """The values in ``layout``'s order (default: the level-1 layout of this many planes)."""
        layout = layout or level1_layout(self.n_planes)
        x = np.empty(len(layout))
        for g in layout.groups:
            x[layout.slice(g.name)] = self._group_values(g)
        return x

    @classmethod
    def from_vector(cls, x: np.ndarray, layout: ParamLayout) -> "CellParams":
        """The parameters held by a vector in ``layout``'s order."""
        x = np.asarray(x, float)
        if x.shape != (len(layout),):
            raise ValueError(f"a vector of {x.shape} for a layout of {len(layout)} parameters")
        p = cls(planes=np.zeros((layout.n_planes, 3)))
        for g in layout.groups:
            p._set_group_values(g, x[layout.slice(g.name)])
        return p

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
        else:
            raise ValueError(f"the cell model has no parameters of kind {g.kind!r}")

    def copy(self) -> "CellParams":
        return CellParams(self.joint_offsets.copy(), self.sensor_origin.copy(), self.phi_y,
                          self.phi_z, self.planes.copy(), self.geometry.copy(),
                          self.base.copy(), self.compliance.copy())
