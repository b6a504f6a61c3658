"""planecal.model.mesh: hulls against trimesh's own, the disk cache (hit == miss, a damaged or
unwritable cache is ignored), and the properties the checker and the twin read."""
import numpy as np
import pytest
import trimesh

from planecal.model import mesh as M


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("PLANECAL_CACHE_DIR", str(tmp_path / "cache"))
    cache = M._HullCache()
    monkeypatch.setattr(M, "_CACHE", cache)
    return cache


def _points(seed=0, n=60):
    return np.random.default_rng(seed).normal(size=(n, 3)) * [0.3, 0.2, 0.1]


def test_hull_is_trimesh_hull_and_closed(fresh_cache):
    P = _points()
    m = M.convex_hull(P)
    ref = trimesh.convex.convex_hull(P)
    assert m.volume == pytest.approx(ref.volume, rel=1e-12)
    assert np.allclose(m.bounds, ref.bounds)
    tm = m.to_trimesh()
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    # outward normals: every hull vertex is on the inner side of every face plane
    d = np.einsum("pfk,fk->pf", P[:, None] - m.triangles_center[None], m.face_normals)
    assert d.max() < 1e-12


def test_hull_of_clustered_points_is_closed(fresh_cache):
    """Points in pairs a few nm apart, each grown by a 4 mm margin (a collision envelope
    round an STL's corners): trimesh's hull merges them and leaves holes; the hull is
    then qhull's own, closed, outward, with scipy's volume."""
    from scipy.spatial import ConvexHull
    rng = np.random.default_rng(0)
    H = rng.normal(size=(30, 3))
    H = 0.1 * H / np.linalg.norm(H, axis=1)[:, None]
    H = np.concatenate([H, H + rng.normal(scale=3e-9, size=H.shape)])
    U = rng.normal(size=(12, 3))
    P = (H[:, None, :] + 0.004 * U[None] / np.linalg.norm(U, axis=1)[:, None]).reshape(-1, 3)
    assert not trimesh.convex.convex_hull(P).is_watertight  # the case this is about
    tm = M.convex_hull(P).to_trimesh()
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.volume == pytest.approx(ConvexHull(P).volume, rel=1e-12)
    # outward: every point inside every face's plane, to the rounding of the normals of
    # the nm-sized triangles between a pair (2.6e-11 m here)
    d = np.einsum("pfk,fk->pf", P[:, None] - tm.triangles_center[None], tm.face_normals)
    assert d.max() < 1e-9


def test_cache_hit_equals_miss_and_survives_the_process(fresh_cache, monkeypatch):
    P = _points(1)
    first = M.convex_hull(P)
    assert fresh_cache.path().exists()
    again = M._HullCache()  # a new process: reads the file
    monkeypatch.setattr(M, "_CACHE", again)
    import builtins
    real_import = builtins.__import__

    def no_trimesh(name, *a, **k):
        if name == "trimesh":
            raise AssertionError("a cached hull must not need trimesh")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_trimesh)
    hit = M.convex_hull(P)
    monkeypatch.setattr(builtins, "__import__", real_import)
    assert np.array_equal(hit.vertices, first.vertices)
    assert np.array_equal(hit.faces, first.faces)


def test_a_new_process_reads_only_the_hulls_it_asks_for(fresh_cache, monkeypatch):
    """The cache file holds every hull a user's runs (or a test suite) ever met; a new
    process reads the entries it asks for, not the whole file (it read all 1,290 of a
    suite-grown 7.8 MB file, 0.17 s of every rehearse's start-up), and a hull put after
    that keeps every other one in the file."""
    hulls = [M.convex_hull(_points(10 + k)) for k in range(12)]
    again = M._HullCache()
    monkeypatch.setattr(M, "_CACHE", again)
    hit = M.convex_hull(_points(13))
    assert np.array_equal(hit.vertices, hulls[3].vertices)
    assert len(again._hulls) == 1
    M.convex_hull(_points(99))  # a miss: written with all twelve others
    third = M._HullCache()
    monkeypatch.setattr(M, "_CACHE", third)
    for k in range(12):
        assert np.array_equal(M.convex_hull(_points(10 + k)).faces, hulls[k].faces)
    assert len(third._hulls) == 12


def test_damaged_or_unwritable_cache_is_ignored(tmp_path, monkeypatch):
    bad = tmp_path / "cache"
    bad.mkdir()
    monkeypatch.setenv("PLANECAL_CACHE_DIR", str(bad))
    cache = M._HullCache()
    cache.path().write_bytes(b"not an npz file")
    monkeypatch.setattr(M, "_CACHE", cache)
    m = M.convex_hull(_points(2))
    assert m.volume > 0
    # a cache directory that is a file: nothing can be written, the hull still comes
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("PLANECAL_CACHE_DIR", str(blocker / "sub"))
    monkeypatch.setattr(M, "_CACHE", M._HullCache())
    assert M.convex_hull(_points(3)).volume > 0


def test_box_and_prism_volumes(fresh_cache):
    T = np.eye(4)
    T[:3, :3] = trimesh.transformations.rotation_matrix(0.7, [1, 2, 3])[:3, :3]
    T[:3, 3] = [1.0, -2.0, 0.5]
    b = M.box([0.3, 0.2, 0.1], T)
    assert b.volume == pytest.approx(0.006, rel=1e-12)
    assert np.allclose(b.vertices.mean(0), T[:3, 3])
    n, r, h = 16, 0.2, 0.5
    p = M.prism(r, h, n)
    # a regular n-gon of circumradius r: area n/2 r^2 sin(2 pi / n)
    assert p.volume == pytest.approx(n / 2 * r * r * np.sin(2 * np.pi / n) * h, rel=1e-12)


def test_bad_points_are_refused():
    with pytest.raises(ValueError):
        M.convex_hull(np.zeros((3, 3)))
    with pytest.raises(ValueError):
        M.convex_hull(np.full((5, 3), np.nan))


def test_vertex_normals_point_out_of_a_box(fresh_cache):
    b = M.box([2.0, 2.0, 2.0])
    n = b.vertex_normals
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    # every corner's normal points away from the centre, into its own octant
    assert np.all(np.sign(n) == np.sign(b.vertices))
