import numpy as np
import pytest

from planecal.base.errors import InputError
from planecal.model.geometry import (COLLISION_MARGIN, HEAD_EXTENTS, KINDS, LinkMesh, StaticMesh,
                               robot_link_meshes, scene_meshes, tool_meshes)
from planecal.model.kinematics import link_frames
from planecal.model.robot import load_robot
from planecal.model.scene import load_scene

ROBOT = load_robot()


def _inside_convex(mesh, points, tol=1e-9):
    # a convex hull: every point on the inner side of every face plane
    n, c = mesh.face_normals, mesh.triangles_center
    return np.all(np.einsum("pfk,fk->pf", points[:, None, :] - c[None], n) <= tol, axis=1)


@pytest.mark.parametrize("kind", KINDS)
def test_link_meshes_watertight_convex_every_frame(kind):
    links = robot_link_meshes(ROBOT, kind)
    assert sorted({lm.body for lm in links}) == [0, 1, 2, 3, 4, 5, 6]
    assert len({lm.name for lm in links}) == len(links)
    for lm in links + tool_meshes(load_scene(), kind):
        assert isinstance(lm, LinkMesh)
        assert lm.mesh.is_watertight and lm.mesh.is_volume
        assert lm.mesh.is_convex, lm.name  # the exact oracle (MuJoCo) needs convex pieces
        assert np.array_equal(lm.T_body_mesh, np.eye(4))


def _face_planes(mesh):
    n = mesh.face_normals
    return n, np.einsum("fk,fk->f", n, mesh.triangles_center)


@pytest.mark.parametrize("margin", [None, 0.0, 0.010])
def test_collision_contains_visual_grown_by_the_margin(margin):
    """Every visual vertex lies inside its collision piece, at least the margin deep
    below every collision face. For convex pieces that is exact: the collision piece
    contains every point within the margin of the visual piece."""
    m = COLLISION_MARGIN if margin is None else margin
    for scene in (load_scene("thesis_final"), load_scene("appendix_d")):
        col = robot_link_meshes(ROBOT, "collision", margin_m=margin) \
            + tool_meshes(scene, "collision", margin_m=margin)
        vis = robot_link_meshes(ROBOT, "visual") + tool_meshes(scene, "visual")
        assert [c.name for c in col] == [v.name for v in vis]
        for c, v in zip(col, vis):
            assert c.body == v.body
            assert _inside_convex(c.mesh, v.mesh.vertices).all(), c.name
            n, b = _face_planes(c.mesh)
            depth = (b - (v.mesh.vertices @ n.T).max(0)).min()
            assert depth >= m - 1e-9, (c.name, depth)
            assert v.mesh.volume < c.mesh.volume or m == 0


def test_collision_envelope_is_tight():
    """No collision piece reaches more than the margin + 3.5 mm beyond the planes of its
    visual piece (polygon corners and cylinder end rims), nor less than the margin."""
    scene = load_scene()
    col = robot_link_meshes(ROBOT, "collision") + tool_meshes(scene, "collision")
    vis = robot_link_meshes(ROBOT, "visual") + tool_meshes(scene, "visual")
    for c, v in zip(col, vis):
        n, b = _face_planes(v.mesh)
        reach = (c.mesh.vertices @ n.T - b).max()
        assert COLLISION_MARGIN - 1e-9 <= reach <= COLLISION_MARGIN + 0.0035, (c.name, reach)


def test_margin_covers_joint_offsets_of_the_seeds_size():
    """COLLISION_MARGIN's reason (geometry docstring): joint offsets as large as the
    seed identified (Table 10, joints 2-5), of either sign, move no link or tool vertex
    farther than the margin, over random configurations."""
    import itertools
    scene = load_scene()
    parts = robot_link_meshes(ROBOT, "visual") + tool_meshes(scene, "visual")
    mag = np.array([0.0, 0.000762, 0.001237, 0.000731, 4.851769e-5, 0.0])
    Q = np.random.default_rng(0).uniform(*ROBOT.limits.T, (1500, 6))
    F0 = link_frames(ROBOT.kinematics, Q)
    worst = 0.0
    for signs in itertools.product((1, -1), repeat=3):
        F1 = link_frames(ROBOT.kinematics.with_offsets(mag * np.array([0, 1, *signs, 0])), Q)
        for p in parts:
            V = p.mesh.vertices
            X0 = np.einsum("nab,vb->nva", F0[:, p.body, :3, :3], V) + F0[:, p.body, None, :3, 3]
            X1 = np.einsum("nab,vb->nva", F1[:, p.body, :3, :3], V) + F1[:, p.body, None, :3, 3]
            worst = max(worst, np.linalg.norm(X1 - X0, axis=-1).max())
    assert 0.003 < worst <= COLLISION_MARGIN


def test_envelope_matches_dh_dimensions():
    # at q = 0 the arm reaches the flange at x = 1.315 m, z = 1.65 m: the envelope covers
    # the flange and the arm's joints, and the base stands on the floor
    F = link_frames(ROBOT.kinematics, np.zeros(6))
    for kind in KINDS:
        pts = np.concatenate([lm.mesh.vertices @ F[lm.body, :3, :3].T + F[lm.body, :3, 3]
                              for lm in robot_link_meshes(ROBOT, kind)])
        lo, hi = pts.min(0), pts.max(0)
        assert hi[0] >= 1.315 and hi[2] >= 1.65 + 0.15 and lo[2] <= 0.0
    # each joint's axis (through frame i-1's origin along its z) runs through a piece of
    # the body the joint turns, and the flange face is the flange's top
    pieces = {}
    for lm in robot_link_meshes(ROBOT, "visual"):
        pieces.setdefault(lm.body, []).append(lm.mesh)
    t = np.linspace(-1.0, 1.0, 201)[:, None]
    for body in range(1, 7):
        T = np.linalg.inv(F[body]) @ F[body - 1]
        axis = T[:3, 3] + t * T[:3, 2]
        assert any(_inside_convex(m, axis).any() for m in pieces[body]), body
    flange = pieces[6][0]
    assert flange.vertices[:, 2].max() == pytest.approx(0.0, abs=1e-12)


def _cylinders(name):
    """The MC70's shapes.json cylinders of piece ``name`` (from, to, radius)."""
    from planecal.model.geometry import robot_shapes
    piece = [p for p in robot_shapes(ROBOT).pieces if p.name == name][0]
    return [(np.array(c.p0), np.array(c.p1), c.r) for c in piece.primitives]


def test_upper_arm_beside_the_forearm_plane():
    """The upper arm is a beam on the +z2 side of the arm's plane (z2 = 0, where the
    forearm swings), so the forearm passes beside it (datasheet J3 +260/-146 deg)."""
    (p0, p1, _), _ = _cylinders("upper_arm")
    UPPER_ARM_Z = (p0[2], p1[2])
    assert UPPER_ARM_Z == (0.16, 0.32)
    arm = [lm for lm in robot_link_meshes(ROBOT, "visual") if lm.name == "upper_arm"][0]
    z = arm.mesh.vertices[:, 2]
    assert z.min() == pytest.approx(UPPER_ARM_Z[0]) and z.max() == pytest.approx(UPPER_ARM_Z[1])
    forearm = [lm for lm in robot_link_meshes(ROBOT, "visual") if lm.name == "forearm"][0]
    assert np.abs(forearm.mesh.vertices[:, 0]).max() < UPPER_ARM_Z[0]  # its half width


@pytest.mark.parametrize("q5_deg", [-125, -90, 90, 125])
def test_wrist_clears_the_forearm_up_to_the_j5_limit(q5_deg):
    """Datasheet J5 +-125 deg: bent to its limit, the J6 housing and the flange (bodies 5
    and 6) stay 15 mm short of the forearm's end between the prongs (in frame 4, the
    forearm along +y4), and fit between the prongs at any angle."""
    FORK_CROTCH = _cylinders("forearm")[0][0][1]  # the forearm's end, from the J5 axis
    FORK_INNER = _cylinders("wrist_fork_p")[0][0][2]  # the prongs' inner faces
    assert (FORK_CROTCH, FORK_INNER) == (0.17, 0.095)
    q = np.deg2rad([0, 0, 0, 0, q5_deg, 0])
    F = link_frames(ROBOT.kinematics, q)
    to4 = np.linalg.inv(F[4])
    for lm in robot_link_meshes(ROBOT, "visual"):
        if lm.body in (5, 6):
            T = to4 @ F[lm.body]
            X = lm.mesh.vertices @ T[:3, :3].T + T[:3, 3]
            assert X[:, 1].max() < FORK_CROTCH - 0.015, lm.name
            assert np.abs(X[:, 2]).max() < FORK_INNER, lm.name


def test_laser_head_beam_exit_at_sensor_origin():
    scene = load_scene()
    from planecal.model.geometry import sensor_pose
    T = sensor_pose(scene.sensor_origin, scene.phi_y, scene.phi_z)
    for kind, grow in (("visual", 0.0), ("collision", COLLISION_MARGIN)):
        head = [m for m in tool_meshes(scene, kind) if m.name == "laser_head"][0]
        local = (head.mesh.vertices - T[:3, 3]) @ T[:3, :3]
        # the head lies behind the exit face (sensor z <= 0), the beam leaves its centre
        assert local[:, 2].max() == pytest.approx(grow, abs=1e-12)
        assert np.allclose(local[:, :2].mean(0), 0, atol=1e-12)
        assert np.allclose(head.box_extents, HEAD_EXTENTS + 2 * grow)


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


def test_bad_kind_or_margin():
    with pytest.raises(InputError):
        robot_link_meshes(ROBOT, "fancy")
    for bad in (-0.001, float("nan")):
        with pytest.raises(InputError):
            robot_link_meshes(ROBOT, "collision", margin_m=bad)
        with pytest.raises(InputError):
            tool_meshes(load_scene(), "collision", margin_m=bad)


def test_a_robot_without_shapes_json_is_told_so(tmp_path):
    # issue 23: shapes come from the description (the UR5 has them now); a robot.json
    # without a shapes.json beside it gets one line naming the file it lacks
    (tmp_path / "robot.json").write_text(load_robot("ur5").source.read_text())
    with pytest.raises(InputError, match=r"shapes.json: no link shapes for .*UR5"):
        robot_link_meshes(load_robot(tmp_path))
    assert len(robot_link_meshes(load_robot("ur5"))) == 7
