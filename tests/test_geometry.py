import numpy as np
import pytest

from planecal.errors import InputError
from planecal.geometry import (KINDS, LinkMesh, StaticMesh, robot_link_meshes, scene_meshes,
                               tool_meshes)
from planecal.robot import fk_frames, load_robot
from planecal.scene import load_scene

ROBOT = load_robot()


def _inside_convex(mesh, points, tol=1e-9):
    # a convex hull: every point on the inner side of every face plane
    n, c = mesh.face_normals, mesh.triangles_center
    return np.all(np.einsum("pfk,fk->pf", points[:, None, :] - c[None], n) <= tol, axis=1)


@pytest.mark.parametrize("kind", KINDS)
def test_link_meshes_watertight_every_frame(kind):
    links = robot_link_meshes(ROBOT, kind)
    assert sorted({lm.body for lm in links}) == [0, 1, 2, 3, 4, 5, 6]
    assert len({lm.name for lm in links}) == len(links)
    for lm in links:
        assert isinstance(lm, LinkMesh)
        assert lm.mesh.is_watertight and lm.mesh.is_volume
        assert np.array_equal(lm.T_body_mesh, np.eye(4))


def test_visual_inside_collision():
    scene = load_scene()
    col = robot_link_meshes(ROBOT, "collision") + tool_meshes(scene, "collision")
    vis = robot_link_meshes(ROBOT, "visual") + tool_meshes(scene, "visual")
    for c, v in zip(col, vis):
        assert c.name == v.name
        assert _inside_convex(c.mesh, v.mesh.vertices).all(), c.name
        assert v.mesh.volume < c.mesh.volume


def test_envelope_matches_dh_dimensions():
    # at q = 0 the arm reaches the flange at x = 1.315 m, z = 1.65 m: the collision
    # envelope covers the flange and the arm's joints, and the base stands on the floor
    F = fk_frames(ROBOT, np.zeros(6))
    pts = np.concatenate([lm.mesh.vertices @ F[lm.body, :3, :3].T + F[lm.body, :3, 3]
                          for lm in robot_link_meshes(ROBOT)])
    lo, hi = pts.min(0), pts.max(0)
    assert hi[0] >= 1.315 and hi[2] >= 1.65 + 0.15 and lo[2] <= 0.0
    # joint origins lie inside their link's envelope
    for lm in robot_link_meshes(ROBOT)[1:]:
        if lm.name != "forearm":  # the forearm tube ends before the wrist centre
            assert _inside_convex(lm.mesh, np.zeros((1, 3))).all(), lm.name


def test_laser_head_beam_exit_at_sensor_origin():
    scene = load_scene()
    head = [m for m in tool_meshes(scene, "visual") if m.name == "laser_head"][0]
    from planecal.geometry import sensor_pose
    T = sensor_pose(scene.sensor_origin, scene.phi_y, scene.phi_z)
    local = (head.mesh.vertices - T[:3, 3]) @ T[:3, :3]
    # the head lies behind the exit face (sensor z <= 0), the beam leaves its centre
    assert local[:, 2].max() == pytest.approx(-0.001, abs=1e-12)
    assert np.allclose(local[:, :2].mean(0), 0, atol=1e-12)
    assert np.allclose(head.box_extents, [0.028, 0.018, 0.058])


def test_scene_meshes_plates_stands_floor():
    scene = load_scene("thesis_final")
    ms = scene_meshes(scene)
    kinds = [m.kind for m in ms]
    assert kinds == ["plate", "stand", "floor"]
    for m in ms:
        assert isinstance(m, StaticMesh) and m.mesh.is_watertight
    plate = scene.plates[0]
    F = plate.frame()
    # the measured face holds the corner, and every plate vertex is on or behind the face
    d = (ms[0].mesh.vertices - F[:3, 3]) @ F[:3, 2]
    assert d.max() == pytest.approx(0, abs=1e-12) and d.min() == pytest.approx(-plate.thickness)
    assert np.all(np.abs(ms[0].mesh.vertices @ plate.n_tilde - 1)[d > -1e-9] < 1e-12)
    # the stand reaches from the floor up to the plate's underside, touching, not entering
    assert ms[1].mesh.bounds[0, 2] == pytest.approx(scene.floor_z)
    top = ms[1].mesh.bounds[1, 2]
    assert top > ms[0].mesh.bounds[0, 2] + 0.01
    assert _inside_convex(ms[0].mesh, ms[1].mesh.vertices, tol=-1e-9).sum() == 0
    assert _inside_convex(ms[0].mesh, ms[1].mesh.vertices[ms[1].mesh.vertices[:, 2] > top - 1e-9],
                          tol=1e-9).sum() >= 1  # a top corner or edge on the underside
    assert ms[2].mesh.bounds[1, 2] == pytest.approx(scene.floor_z)


def test_scene_meshes_on_perturbed_planes():
    scene = load_scene()
    n = scene.plates[0].n_tilde * 1.01
    plate = scene_meshes(scene, [n])[0]
    face = plate.mesh.vertices[np.abs(plate.mesh.vertices @ n - 1) < 1e-9]
    assert len(face) == 4
    with pytest.raises(InputError):
        scene_meshes(scene, np.zeros((2, 3)) + n)


def test_bad_kind():
    with pytest.raises(InputError):
        robot_link_meshes(ROBOT, "fancy")


def test_other_robot_has_no_shapes():
    with pytest.raises(InputError):
        robot_link_meshes(load_robot("ur5"))
