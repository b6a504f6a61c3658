"""Closed convex triangle meshes, and their convex hulls cached on disk.

Every shape planecal builds (link pieces, tool, plates, stands, floor, obstacles, the
collision checker's hulls of revolution) is the convex hull of a few points. ``Mesh``
holds one: ``vertices`` (n, 3) in metres, ``faces`` (m, 3) oriented outwards, and the
handful of properties the twin, the checker and the exports read (``triangles``,
``bounds``, ``volume``, ``is_convex``, ``is_watertight``, ``is_volume``).

``convex_hull(points)`` computes the hull with trimesh (qhull) and caches the result by
the points' bytes, in memory and in one file under the user's cache directory
(``planecal.base.paths.cache_dir()``: ``$PLANECAL_CACHE_DIR``, else
``$XDG_CACHE_HOME/planecal``, else ``~/.cache/planecal``; the file name carries trimesh's
version). A hull is a pure function of its points, so a
cached hull is the hull trimesh would return. The point of the cache is start-up time:
importing trimesh (and the scipy modules it pulls in) costs about 0.5 s of every
``planecal rehearse``; with the hulls cached, trimesh is imported only when a shape
changes. An unreadable or unwritable cache is ignored (the hull is computed).
``to_trimesh()`` gives a ``trimesh.Trimesh`` for what needs trimesh's own features
(file export, concatenation).
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from planecal.base.paths import cache_dir


@dataclass(frozen=True, eq=False)
class Mesh:
    """A closed triangle mesh with outward faces (a convex hull unless ``is_convex`` says
    otherwise)."""
    vertices: np.ndarray
    faces: np.ndarray
    is_convex: bool = True
    is_watertight: bool = True

    @property
    def triangles(self) -> np.ndarray:
        """(m, 3, 3) corner coordinates of every face."""
        return self.vertices[self.faces]

    @property
    def face_normals(self) -> np.ndarray:
        """(m, 3) outward unit normals."""
        t = self.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @property
    def vertex_normals(self) -> np.ndarray:
        """(n, 3) unit normals per vertex: the area-weighted mean of its faces' normals
        (for shading)."""
        t = self.triangles
        area_n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # 2 x area x normal
        acc = np.zeros_like(self.vertices)
        for k in range(3):
            np.add.at(acc, self.faces[:, k], area_n)
        norm = np.linalg.norm(acc, axis=1, keepdims=True)
        return acc / np.where(norm > 0, norm, 1.0)

    @property
    def triangles_center(self) -> np.ndarray:
        """(m, 3) centroid of every face."""
        return self.triangles.mean(axis=1)

    @property
    def bounds(self) -> np.ndarray:
        """[[x, y, z] min, [x, y, z] max]."""
        return np.array([self.vertices.min(0), self.vertices.max(0)])

    @property
    def volume(self) -> float:
        """Enclosed volume (m^3): the divergence theorem over the outward faces."""
        a, b, c = (self.triangles[:, i] for i in range(3))
        return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)

    @property
    def is_volume(self) -> bool:
        return self.is_watertight and self.volume > 0

    def transformed(self, T: np.ndarray) -> "Mesh":
        """The mesh moved by the 4x4 transform T (rigid: faces keep their orientation)."""
        T = np.asarray(T, float)
        return Mesh(self.vertices @ T[:3, :3].T + T[:3, 3], self.faces, self.is_convex,
                    self.is_watertight)

    def to_trimesh(self):
        """The same mesh as a ``trimesh.Trimesh`` (imports trimesh)."""
        import trimesh
        return trimesh.Trimesh(self.vertices.copy(), self.faces.copy(), process=False)


class _HullCache:
    """Hulls by key, read from one ``.npz`` file as they are asked for (the file holds every
    shape this user's runs have met: a few hundred kB for a cell, megabytes after a test
    suite; a run reads its thirty hulls, not the whole file) and appended to it."""

    def __init__(self):
        self._hulls: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._file = None  # the open NpzFile (None: not opened yet; False: none readable)
        self._path: Path | None = None

    def path(self) -> Path:
        if self._path is None:
            try:
                ver = metadata.version("trimesh")
            except metadata.PackageNotFoundError:  # pragma: no cover - a dependency
                ver = "unknown"
            self._path = cache_dir() / f"hulls-trimesh{ver}.npz"
        return self._path

    def _stored(self):
        if self._file is None:
            try:
                self._file = np.load(self.path())
                self._names = set(self._file.files)
            except (OSError, ValueError):
                self._file = False  # no cache yet, or unreadable: computed again
        return self._file

    def _read(self, key: str):
        z = self._stored()
        if key not in self._hulls and z is not False and key + "_V" in self._names:
            try:
                self._hulls[key] = (z[key + "_V"], z[key + "_F"])
            except (OSError, ValueError, KeyError):
                pass  # a damaged entry: computed again
        return self._hulls.get(key)

    def get(self, key: str):
        return self._read(key)

    def put(self, key: str, V: np.ndarray, F: np.ndarray) -> None:
        z = self._stored()
        if z is not False:  # the file is rewritten whole: every stored hull read first
            for name in self._names:
                if name.endswith("_V"):
                    self._read(name[:-2])
        self._hulls[key] = (V, F)
        arrays = {}
        for k, (v, f) in self._hulls.items():
            arrays[k + "_V"], arrays[k + "_F"] = v, f
        path = self.path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".hulls-", suffix=".npz")
            try:
                with os.fdopen(fd, "wb") as fh:
                    np.savez(fh, **arrays)
                os.replace(tmp, path)  # atomic: readers see the old file or the new one
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError:
            pass  # a read-only home: the hull stays cached in this process only


_CACHE = _HullCache()


def convex_hull(points) -> Mesh:
    """The convex hull of points (n, 3): a closed, outward-oriented ``Mesh``."""
    P = np.ascontiguousarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 4 or not np.all(np.isfinite(P)):
        raise ValueError(f"convex_hull: need (n >= 4, 3) finite points, got {P.shape}")
    key = "h" + hashlib.sha256(P.tobytes() + repr(P.shape).encode()).hexdigest()[:32]
    hit = _CACHE.get(key)
    if hit is None:
        import trimesh
        tm = trimesh.convex.convex_hull(P)
        if tm.is_watertight:
            hit = (np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64))
        else:  # trimesh merged points closer than its tolerance and broke faces
            hit = _qhull(P)
        _CACHE.put(key, *hit)
    V, F = hit
    return Mesh(V.copy(), F.copy())


def _qhull(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hull's vertices and triangles from qhull as it gives them (closed: every edge
    of its triangulated facets joins two), each turned outward by its facet's plane. For
    points trimesh's hull cannot close: clusters within its merging tolerance (the
    margin grown round an STL's float32 corners)."""
    from scipy.spatial import ConvexHull
    h = ConvexHull(P)
    index = np.full(len(P), -1, np.int64)
    index[h.vertices] = np.arange(len(h.vertices))
    V, F = P[h.vertices], index[h.simplices]
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    inward = np.einsum("ij,ij->i", n, h.equations[:, :3]) < 0
    F[inward] = F[inward][:, ::-1]
    return V, F


def box(extents, pose=None) -> Mesh:
    """A box of full ``extents`` centred at ``pose`` (4x4; default identity)."""
    half = np.asarray(extents, float) / 2
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1)
                        for sz in (-1, 1)]) * half
    m = convex_hull(corners)
    return m if pose is None else m.transformed(pose)


def prism(radius: float, height: float, sections: int, pose=None) -> Mesh:
    """A right prism of ``sections`` sides whose corners lie on a circle of ``radius``
    about z, ``height`` long, centred at ``pose`` (4x4; default identity)."""
    ang = 2 * np.pi * np.arange(sections) / sections
    ring = np.c_[radius * np.cos(ang), radius * np.sin(ang), np.zeros(sections)]
    h = np.array([0.0, 0.0, height / 2])
    m = convex_hull(np.concatenate([ring - h, ring + h]))
    return m if pose is None else m.transformed(pose)


def read_stl(path) -> Mesh:
    """A binary STL file as a ``Mesh`` (metres as written; shared corners merged). Neither
    convex nor closed is assumed: ``is_watertight`` says whether every edge joins exactly
    two triangles. ValueError (one line) for a file that is not a binary STL."""
    data = Path(path).read_bytes()
    if len(data) < 84:
        raise ValueError(f"{path}: too short for a binary STL ({len(data)} bytes)")
    n = int(np.frombuffer(data, "<u4", 1, 80)[0])
    if len(data) != 84 + 50 * n:
        what = "an ASCII STL (convert it to binary)" if data[:5] == b"solid" else "not a binary STL"
        raise ValueError(f"{path}: {what}: {len(data)} bytes for {n} triangles")
    rec = np.frombuffer(data, np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                        n, 84)
    corners = rec["v"].reshape(-1, 3).astype(float)
    if not np.all(np.isfinite(corners)):
        raise ValueError(f"{path}: a vertex is not a finite number")
    V, idx = np.unique(corners, axis=0, return_inverse=True)
    F = idx.reshape(-1, 3).astype(np.int64)
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    edges = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return Mesh(V, F, is_convex=False, is_watertight=bool(len(F) and np.all(counts == 2)))


def write_stl(path, mesh: Mesh) -> None:
    """``mesh`` as a binary STL file (float32 corners, outward normals)."""
    T = mesh.triangles.astype("<f4")
    rec = np.zeros(len(T), np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    rec["n"] = mesh.face_normals.astype("<f4")
    rec["v"] = T
    with open(path, "wb") as f:
        f.write(b"planecal".ljust(80, b" "))
        f.write(np.array([len(T)], "<u4").tobytes())
        f.write(rec.tobytes())
