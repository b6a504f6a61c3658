"""URDF export, read back by an independent URDF library (yourdfpy), not by planecal:
its forward kinematics at planecal's joint angles q must give planecal's flange and sensor
poses, nominal and calibrated, and its meshes must sit where planecal.model.geometry puts them."""
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

yourdfpy = pytest.importorskip("yourdfpy")

from planecal.model.cell_params import CellParams
from planecal.model.measurement import sensor_in_base  # noqa: E402
from planecal.cli import main  # noqa: E402
from planecal.model.geometry import robot_link_meshes, sensor_pose, tool_meshes  # noqa: E402
from planecal.io.params import load_params  # noqa: E402
from repo import repo_path  # noqa: E402
from planecal.model.kinematics import fk, link_frames  # noqa: E402
from planecal.model.scene import load_scene, nominal_params  # noqa: E402
from planecal.io.urdf import urdf_text  # noqa: E402

TABLE10 = str(repo_path("examples", "table10_params.json"))


def _random_q(robot, rng, n):
    return rng.uniform(robot.limits[:, 0], robot.limits[:, 1], (n, 6))


def _check_kinematics(urdf_path, robot, params, n=200, seed=0):
    u = yourdfpy.URDF.load(str(urdf_path), build_scene_graph=True, load_meshes=False)
    assert u.actuated_joint_names == [f"joint{i}" for i in range(1, 7)]
    rng = np.random.default_rng(seed)
    worst_flange = worst_laser = 0.0
    for q in _random_q(robot, rng, n):
        u.update_cfg(q)
        T = u.get_transform("flange", "base")
        T_ref = fk(robot.kinematics.with_offsets(params.joint_offsets), q)
        worst_flange = max(worst_flange, float(np.abs(T - T_ref).max()))
        L = u.get_transform("laser", "base")
        o_b, z_b = sensor_in_base(robot, q[None], params)
        L_ref = T_ref @ sensor_pose(params.sensor_origin, params.phi_y, params.phi_z)
        worst_laser = max(worst_laser, float(np.abs(L - L_ref).max()),
                          float(np.abs(L[:3, 3] - o_b[0]).max()),
                          float(np.abs(L[:3, 2] - z_b[0]).max()))
    # position in m and rotation entries alike
    assert worst_flange < 1e-9, worst_flange
    assert worst_laser < 1e-9, worst_laser
    return u


def test_nominal_urdf_flange_and_laser_match_planecal(tmp_path, capsys):
    out = tmp_path / "mc70.urdf"
    assert main(["urdf", "--out", str(out), "--no-meshes"]) == 0
    scene = load_scene("thesis_final")
    u = _check_kinematics(out, scene.robot, nominal_params(scene))
    assert u.base_link == "base"
    assert {"base", "flange", "laser"} <= set(u.link_map)
    for i, name in enumerate(u.actuated_joint_names):
        j = u.joint_map[name]
        assert j.type == "revolute"
        assert (j.limit.lower, j.limit.upper) == tuple(scene.robot.limits[i])  # exact


def test_calibrated_urdf_matches_planecal(tmp_path, capsys):
    out = tmp_path / "cal.urdf"
    assert main(["urdf", "--params", TABLE10, "--out", str(out), "--no-meshes"]) == 0
    params = load_params(TABLE10)
    robot = load_scene("thesis_final").robot
    _check_kinematics(out, robot, params, seed=1)
    # the offsets change the model: the nominal URDF is millimetres away from it
    nominal = tmp_path / "nom.urdf"
    assert main(["urdf", "--out", str(nominal), "--no-meshes"]) == 0
    u = yourdfpy.URDF.load(str(nominal), build_scene_graph=True, load_meshes=False)
    q = _random_q(robot, np.random.default_rng(2), 1)[0]
    u.update_cfg(q)
    gap = np.linalg.norm(u.get_transform("flange", "base")[:3, 3]
                         - fk(robot.kinematics.with_offsets(params.joint_offsets), q)[:3, 3])
    assert gap > 1e-4


def test_all_six_offsets_fold_into_the_origins(tmp_path):
    # delta1 and delta6 (fixed in a plane calibration, but a parameter file may hold them)
    robot = load_scene("thesis_final").robot
    rng = np.random.default_rng(3)
    params = CellParams(rng.uniform(-0.01, 0.01, 6), [0.03, -0.07, 0.18], 1.2, -1.0,
                        [[0.0, -1.0, 3.6]])
    path = tmp_path / "p.urdf"
    path.write_text(urdf_text(robot, params))
    _check_kinematics(path, robot, params, n=100, seed=4)


def test_meshes_sit_where_geometry_puts_them(tmp_path, capsys):
    out = tmp_path / "mc70.urdf"
    assert main(["urdf", "--params", TABLE10, "--out", str(out)]) == 0
    scene = load_scene("thesis_final")
    params = load_params(TABLE10)
    u = yourdfpy.URDF.load(str(out), build_scene_graph=True, load_meshes=True)
    q = _random_q(scene.robot, np.random.default_rng(5), 1)[0]
    u.update_cfg(q)
    frames = link_frames(scene.robot.kinematics.with_offsets(params.joint_offsets), q)
    checked = 0
    for kind in ("visual", "collision"):
        expected = {m.name: m for m in robot_link_meshes(scene.robot, kind)
                    + tool_meshes(scene, kind, sensor=params)}
        for link in u.link_map.values():
            for el in getattr(link, kind + "s"):
                m = expected.pop(el.name[: -len(kind) - 1])
                mesh = trimesh.load(out.parent / el.geometry.mesh.filename, force="mesh")
                origin = np.eye(4) if el.origin is None else el.origin
                T = u.get_transform(link.name, "base") @ origin
                got = mesh.vertices @ T[:3, :3].T + T[:3, 3]
                F = frames[m.body] @ m.T_body_mesh
                want = m.mesh.vertices @ F[:3, :3].T + F[:3, 3]
                # an STL holds triangles, not the vertex list (the loader merges and
                # reorders): compare the point sets both ways; float32 coordinates: ~1e-7 m
                gap = max(cKDTree(want).query(got)[0].max(), cKDTree(got).query(want)[0].max())
                assert gap < 2e-6, (el.name, gap)
                checked += 1
        assert not expected, f"{kind} meshes missing from the URDF: {sorted(expected)}"
    assert checked >= 16


def test_urdf_refuses_to_overwrite_its_input(tmp_path, capsys):
    p = tmp_path / "p.json"
    p.write_text(open(TABLE10).read())
    assert main(["urdf", "--params", str(p), "--out", str(p)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--params" in err and len(err.splitlines()) == 1
    assert p.read_text() == open(TABLE10).read()


def test_urdf_bad_params_is_one_line(tmp_path, capsys):
    p = tmp_path / "bad.json"
    p.write_text('{"joint_offsets_rad": [1, 2]}')
    assert main(["urdf", "--params", str(p), "--out", str(tmp_path / "x.urdf")]) == 2
    err = capsys.readouterr().err.strip()
    assert str(p) in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x.urdf").exists()
