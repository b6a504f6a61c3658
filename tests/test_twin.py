import os

os.environ.setdefault("MUJOCO_GL", "disable")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from planecal.model.planes import parallel_rows, point_normal_from_n_tilde
from planecal.model.measurement import predict  # noqa: E402
from planecal.model.encoder import counts_to_joints, joints_to_counts  # noqa: E402
from planecal.base.errors import InputError  # noqa: E402
from planecal.io.params import save_params  # noqa: E402
from planecal.model.kinematics import fk, link_frames
from planecal.model.robot import load_robot  # noqa: E402
from planecal.model.scene import load_scene, nominal_params  # noqa: E402
from planecal.twin import EncoderJumpError, Tolerances, Twin, TwinOptions, draw_truth  # noqa: E402
from twin_aim import aim_joints, beam_frame, random_aims  # noqa: E402
from planecal.twin.mjcf import plate_geom_names, robot_xml, robot_xml_path  # noqa: E402

ROBOT = load_robot()
HOME = np.array([[0, 0, 1, 1.315], [0, -1, 0, 0], [1, 0, 0, 1.65], [0, 0, 0, 1.0]])
SCENES = ["appendix_d", "thesis_final", "three_plates"]


@pytest.fixture(scope="module")
def twins():
    return {name: Twin(name, seed=11, options=TwinOptions.exact()) for name in SCENES}


# ----- (1) laser reading = analytic model with the true parameters -----

def test_reading_equals_model_with_truth(twins):
    rng = np.random.default_rng(5)
    n_total, worst = 0, 0.0
    for name, n in (("three_plates", 600), ("thesis_final", 200), ("appendix_d", 200)):
        twin = twins[name]
        truth = twin.truth
        aims = random_aims(twin.scene, truth, n, rng)
        assert len(aims) == n
        qe = np.array([c for c, _ in aims])
        plate = np.array([k for _, k in aims])
        model_mm = predict(ROBOT, qe, truth, plate) * 1000
        for c, k, m in zip(qe, plate, model_mm):
            twin.set_counts(c)
            mm = twin.read()
            assert mm is not None and twin.hit().plate == k
            worst = max(worst, abs(mm - m))
        n_total += n
    assert n_total == 1000
    assert worst < 1e-6  # mm


def test_truth_differs_from_nominal(twins):
    # the twin really uses the truth: the nominal model misses by far more than 1e-6 mm
    twin = twins["thesis_final"]
    twin.set_counts(joints_to_counts(ROBOT, twin.scene.calibration_q))
    nominal = predict(ROBOT, twin.current_counts[None], nominal_params(twin.scene))[0] * 1000
    assert abs(twin.read() - nominal) > 0.1


# ----- (2) MJCF kinematics = numpy DH -----

def test_committed_mjcf_is_builder_output():
    path = robot_xml_path(ROBOT)
    assert path.read_text() == robot_xml(ROBOT), "run scripts/build_mjcf.py"


def test_mjcf_flange_equals_fk():
    m = mujoco.MjModel.from_xml_path(str(robot_xml_path(ROBOT)))
    d = mujoco.MjData(m)
    flange = m.site("flange").id
    frames = [m.site(f"frame{i}").id for i in range(1, 7)]
    rng = np.random.default_rng(0)
    Q = rng.uniform(ROBOT.limits[:, 0], ROBOT.limits[:, 1], (500, 6))
    F = link_frames(ROBOT.kinematics, Q)
    worst = 0.0
    for q, Fq in zip(Q, F):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = d.site_xmat[flange].reshape(3, 3), d.site_xpos[flange]
        worst = max(worst, np.abs(T - Fq[6]).max())
        for i, s in enumerate(frames):
            worst = max(worst, np.abs(d.site_xpos[s] - Fq[i + 1, :3, 3]).max())
    assert worst < 1e-12
    # home pose (MODEL-NOTES)
    d.qpos[:] = 0
    mujoco.mj_kinematics(m, d)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = d.site_xmat[flange].reshape(3, 3), d.site_xpos[flange]
    assert np.abs(T - HOME).max() < 1e-12
    # joint ranges are the limits
    assert np.allclose(m.jnt_range, ROBOT.limits, atol=0, rtol=0)


def test_twin_flange_includes_true_offsets(twins):
    twin = twins["thesis_final"]
    rng = np.random.default_rng(1)
    for _ in range(50):
        c = joints_to_counts(ROBOT, rng.uniform(-1, 1, 6))
        twin.set_counts(c)
        q = counts_to_joints(ROBOT, c)
        assert np.abs(twin.qpos - (q + twin.truth.joint_offsets)).max() < 1e-14
        assert np.abs(twin.flange_pose() - fk(ROBOT.kinematics.with_offsets(twin.truth.joint_offsets), q)).max() < 1e-12


def test_visual_geoms_never_collide(twins):
    m = twins["thesis_final"].model
    vis = m.geom_group == 1
    assert vis.any() and not m.geom_contype[vis].any() and not m.geom_conaffinity[vis].any()
    assert (m.geom_contype[m.geom_group == 3] == 1).all()


# ----- (3) scenes load; plates where the scene (or the truth) says -----

@pytest.mark.parametrize("name", SCENES)
def test_plates_where_the_scene_says(name, twins):
    scene = load_scene(name)
    twin = twins[name]
    truth = twin.truth
    m, d = twin.model, twin.data
    for k, (plate, gname) in enumerate(zip(scene.plates, plate_geom_names(scene))):
        g = m.geom(gname).id
        F = plate.frame(truth.planes[k])
        centre = F[:3, :3] @ [plate.size[0] / 2, plate.size[1] / 2, -plate.thickness / 2] + F[:3, 3]
        assert np.abs(d.geom_xpos[g] - centre).max() < 1e-12
        assert np.abs(d.geom_xmat[g].reshape(3, 3) - F[:3, :3]).max() < 1e-12
        assert np.allclose(m.geom_size[g], [plate.size[0] / 2, plate.size[1] / 2,
                                            plate.thickness / 2], rtol=0, atol=1e-15)
        # the face's corners are on the true plane
        corners = F[:3, 3] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]]) * plate.size @ F[:3, :2].T
        assert np.abs(corners @ truth.planes[k] - 1).max() < 1e-12
    # nominal model: the same with the nominal planes
    nominal = Twin(name, truth="nominal", options=TwinOptions.exact())
    for plate, gname in zip(scene.plates, plate_geom_names(scene)):
        F = plate.frame()
        g = nominal.model.geom(gname).id
        assert np.abs(nominal.data.geom_xmat[g].reshape(3, 3) - F[:3, :3]).max() < 1e-12


@pytest.mark.parametrize("name", SCENES)
def test_calibration_position_reaches_a_plate(name):
    twin = Twin(name, truth="nominal", options=TwinOptions.exact())
    mm = twin.read()
    assert mm is not None and 75 < mm < 85


def test_three_plates_reachable_in_cone():
    # corners and centre of every plate, beam along the normal and on the 30 deg cone,
    # 70 and 90 mm: some roll of the sensor gives an IK solution within the limits
    scene = load_scene("three_plates")
    p = nominal_params(scene)
    normals = []
    for plate in scene.plates:
        F = plate.frame()
        normals.append(F[:3, 2])
        for u, v in [(0.03, 0.03), (0.32, 0.03), (0.03, 0.22), (0.32, 0.22), (0.175, 0.125)]:
            target = F[:3, 3] + F[:3, :2] @ (u, v)
            dirs = [-F[:3, 2]] + [np.cos(np.pi / 6) * -F[:3, 2] + np.sin(np.pi / 6) * (
                np.cos(a) * F[:3, 0] + np.sin(a) * F[:3, 1]) for a in (0, np.pi / 2, np.pi, 1.5 * np.pi)]
            for beam in dirs:
                for dist in (0.070, 0.090):
                    ok = any(aim_joints(ROBOT, p, beam_frame(target, beam, dist, r), np.zeros(6))
                             is not None for r in np.linspace(-np.pi, np.pi, 12, endpoint=False))
                    assert ok, (plate.name, u, v, beam, dist)
    # three different orientations: pairwise more than 30 deg apart
    for i in range(3):
        for j in range(i + 1, 3):
            assert np.degrees(np.arccos(normals[i] @ normals[j])) > 30


# ----- (4) encoder counts and servo -----

def _ramp(twin, target_delta, step=50, start=None):
    """Step generator: deltas from ``start`` towards target_delta by at most ``step``
    per tick; yields (delta, reference, current)."""
    cur = np.zeros(6, np.int64) if start is None else start
    while not np.array_equal(cur, target_delta):
        cur = cur + np.clip(target_delta - cur, -step, step)
        ref, now = twin.exchange(cur)
        yield cur, ref, now


def test_ideal_servo_reaches_command_exactly():
    twin = Twin("thesis_final", seed=2, options=TwinOptions.exact())
    ref0 = twin.reference_counts
    target = np.array([400, -300, 250, 500, -120, 77], np.int64)
    k = 0
    for delta, ref, cur in _ramp(twin, target):
        k += 1
        assert ref.dtype == np.int64 and cur.dtype == np.int64
        assert np.array_equal(ref, ref0)
        assert np.array_equal(cur, ref0 + delta)  # ideal: at the command each tick
    assert np.array_equal(twin.current_counts, ref0 + target)
    assert twin.ticks == k == 10 and twin.robot_time_s == pytest.approx(0.1)


def test_lag_servo_settles_exactly():
    twin = Twin("thesis_final", seed=2, options=TwinOptions.exact(servo="lag", tau_s=0.03))
    ref0 = twin.reference_counts
    target = np.array([400, -300, 250, 500, -120, 77], np.int64)
    for _, _, cur in _ramp(twin, target):
        pass
    assert not np.array_equal(cur, ref0 + target)  # still lagging at the last step
    lag_ticks = 0
    while not np.array_equal(cur, ref0 + target):
        _, cur = twin.exchange(target)
        lag_ticks += 1
        assert lag_ticks < 30
    assert 3 <= lag_ticks < 30  # ~ a few time constants of 3 ticks
    for _ in range(5):  # and stays there
        _, c = twin.exchange(target)
        assert np.array_equal(c, ref0 + target)


def test_encoder_jump_trips():
    twin = Twin("thesis_final", seed=2, options=TwinOptions.exact())
    twin.exchange(np.array([60, 0, 0, 0, 0, 0]))  # 60 is allowed
    with pytest.raises(EncoderJumpError):
        twin.exchange(np.array([121, 0, 0, 0, 0, 0]))
    with pytest.raises(EncoderJumpError):  # the robot braked: no more ticks
        twin.exchange(np.array([60, 0, 0, 0, 0, 0]))


def test_bad_options_are_input_errors():
    for kw in ({"servo": "fast"}, {"tau_s": 0.0}, {"laser_noise_mm": -1.0},
               {"repeatability_mm": float("nan")}):
        with pytest.raises(InputError):
            TwinOptions(**kw)


def test_bad_delta_is_input_error():
    twin = Twin("thesis_final", seed=2, options=TwinOptions.exact())
    with pytest.raises(InputError):
        twin.exchange(np.zeros(5))
    with pytest.raises(InputError):
        twin.exchange(np.full(6, 0.5))


def test_reading_while_moving_follows_counts():
    twin = Twin("thesis_final", seed=4, options=TwinOptions.exact(servo="lag"))
    truth = twin.truth
    (c, _), = random_aims(twin.scene, truth, 1, np.random.default_rng(3), distance_mm=(80, 80))
    twin.set_counts(c)
    start = c - twin.reference_counts
    seen = 0
    for _, _, cur in _ramp(twin, start + [60, -60, 60, 120, -80, 40], step=5, start=start):
        mm = twin.read()
        model = predict(ROBOT, cur[None], truth)[0] * 1000
        if 65 <= model <= 95:
            assert mm == pytest.approx(model, abs=1e-6)
            seen += 1
        else:
            assert mm is None
    assert seen >= 20


# ----- (5) laser window and noise -----

@pytest.mark.parametrize("dist_mm,inside", [(60, False), (64.9, False), (65.5, True),
                                            (80, True), (94.5, True), (95.5, False), (120, False)])
def test_laser_window(dist_mm, inside):
    twin = Twin("thesis_final", seed=3, options=TwinOptions.exact())
    truth = twin.truth
    plate = twin.scene.plates[0]
    F = plate.frame(truth.planes[0])
    target = plate.center(truth.planes[0])
    q = aim_joints(ROBOT, truth, beam_frame(target, -F[:3, 2], dist_mm / 1000, 0.3),
                   twin.scene.calibration_q)
    twin.set_counts(joints_to_counts(ROBOT, q))
    hit = twin.hit()
    assert hit.plate == 0 and hit.distance_m * 1000 == pytest.approx(dist_mm, abs=0.1)
    mm = twin.read()
    assert (mm is not None) == inside
    if inside:
        assert mm == pytest.approx(hit.distance_m * 1000, abs=1e-9)


def test_no_hit_is_none():
    twin = Twin("thesis_final", seed=3, options=TwinOptions.exact(), start_counts=ROBOT.home_counts)
    # at home the beam points up and sideways into empty space
    assert twin.hit().geom == -1 and twin.read() is None


def test_laser_noise_and_repeatability():
    twin = Twin("thesis_final", seed=3, options=TwinOptions(servo="ideal"))
    r = np.array([twin.read() for _ in range(2000)])
    assert 0.0008 < r.std() < 0.0012  # 1 um
    # repeatability: a new joint perturbation per settle, flange 3-sigma ~ 0.07 mm
    base = twin.current_counts - twin.reference_counts
    pos = []
    for k in range(200):
        bump = np.array([5, 0, 0, 0, 0, 0]) * (1 if k % 2 == 0 else 0)
        twin.exchange(base + bump)
        twin.exchange(base + bump)  # at rest: settle
        if k % 2:
            pos.append(twin.flange_pose()[:3, 3])
    spread = np.linalg.norm(np.array(pos) - np.mean(pos, 0), axis=1)
    assert 0.01e-3 < np.sqrt(np.mean(spread ** 2)) < 0.07e-3


# ----- truth -----

def test_truth_bounds_and_seed():
    scene = load_scene("three_plates")
    nom = nominal_params(scene)
    for seed in range(20):
        t = draw_truth(scene, seed)
        assert t.joint_offsets[0] == 0 and t.joint_offsets[5] == 0
        assert np.abs(t.joint_offsets).max() <= 3e-3
        assert np.linalg.norm(t.sensor_origin - nom.sensor_origin) <= 0.010
        assert abs(t.phi_y - nom.phi_y) <= 0.035 and abs(t.phi_z - nom.phi_z) <= 0.035
        stepped = {ref.plates[1] for ref in scene.references}
        for k, plate in enumerate(scene.plates):
            _, n0 = point_normal_from_n_tilde(plate.n_tilde)
            _, n1 = point_normal_from_n_tilde(t.planes[k])
            if k in stepped:  # the block's top: its base's draw, moved as one body
                continue
            assert np.arccos(min(1.0, abs(n0 @ n1))) <= 0.05 + 1e-12
            # the plate centre moved by <= 10 mm off its nominal plane
            assert abs(t.planes[k] @ plate.center() - 1) / np.linalg.norm(t.planes[k]) <= 0.0101
        for ref in scene.references:  # the stepped block: parallel, 200 mm +- its 5 um
            a, b = ref.plates
            g, _, _ = parallel_rows(t.planes[a], t.planes[b], ref.separation_m)
            assert np.linalg.norm(g[:3]) < 6 * ref.parallel_std_rad and abs(g[3]) < 6 * ref.std_m
    assert np.array_equal(draw_truth(scene, 3).to_vector(), draw_truth(scene, 3).to_vector())
    t = draw_truth(scene, 3, Tolerances(offsets_all=True))
    assert t.joint_offsets[0] != 0 and t.joint_offsets[5] != 0


def test_truth_file(tmp_path):
    scene = load_scene("thesis_final")
    t = draw_truth(scene, 8)
    save_params(tmp_path / "truth.json", t)
    twin = Twin(scene, truth=tmp_path / "truth.json", options=TwinOptions.exact())
    assert np.allclose(twin.truth.to_vector(), t.to_vector(), rtol=0, atol=1e-15)
    two = t.copy()
    two.planes = np.vstack([t.planes, t.planes])
    save_params(tmp_path / "bad.json", two)
    with pytest.raises(InputError):
        Twin(scene, truth=tmp_path / "bad.json")


def test_mjcf_command_writes_the_twin_cell(tmp_path, capsys):
    from planecal.cli import main
    out = tmp_path / "scene.xml"
    assert main(["mjcf", "--scene", "three_plates", "--out", str(out), "--truth-seed", "4"]) == 0
    m = mujoco.MjModel.from_xml_path(str(out))
    twin = Twin("three_plates", seed=4, options=TwinOptions.exact())
    for name in plate_geom_names(twin.scene):
        assert np.abs(m.geom_pos[m.geom(name).id] - twin.model.geom_pos[twin.model.geom(name).id]).max() < 1e-15
    # its own file is replaced, another file only with --force, a bad scene is one line
    assert main(["mjcf", "--scene", "three_plates", "--out", str(out)]) == 0
    mine = tmp_path / "mine.xml"
    mine.write_text("<mujoco/>")
    capsys.readouterr()
    assert main(["mjcf", "--out", str(mine)]) == 2
    assert "use --force" in capsys.readouterr().err and mine.read_text() == "<mujoco/>"
    assert main(["mjcf", "--out", str(mine), "--force"]) == 0
    assert main(["mjcf", "--scene", "no_such_scene", "--out", str(out)]) == 2



# ----- batch API -----

def test_run_equals_exchange_and_read_loop():
    # default options: lag servo, laser noise, repeatability: same counts, same readings
    a, b = Twin("thesis_final", seed=6), Twin("thesis_final", seed=6)
    base = a.current_counts - a.reference_counts
    out = base + np.cumsum(np.tile([[30, -30, 30, 40, -20, 10]], (40, 1)), axis=0)
    D = np.vstack([out, np.repeat(out[-1:], 120, axis=0), out[::-1], np.repeat(base[None], 60, axis=0)])
    ref, cur, mm = a.run(D[:100])
    ref2, cur_b, mm_b = a.run(D[100:])
    cur, mm = np.vstack([cur, cur_b]), np.concatenate([mm, mm_b])
    loop_cur, loop_mm = [], []
    for d in D:
        r, c = b.exchange(d)
        loop_cur.append(c)
        x = b.read()
        loop_mm.append(np.nan if x is None else x)
    assert np.array_equal(ref, b.reference_counts) and np.array_equal(cur, np.array(loop_cur))
    assert np.array_equal(np.isnan(mm), np.isnan(loop_mm))
    assert np.nanmax(np.abs(mm - np.array(loop_mm))) < 1e-9
    assert a.ticks == b.ticks == len(D) and a.read() == pytest.approx(b.read(), abs=1e-9)


def test_run_trips_at_the_jump():
    twin = Twin("thesis_final", seed=6, options=TwinOptions.exact())
    D = np.zeros((10, 6), np.int64)
    D[5:, 0] = 61
    with pytest.raises(EncoderJumpError):
        twin.run(D)
    assert twin.ticks == 5


# ----- non-geometric errors (off by default) -----

def test_compliance_sags_under_gravity_and_backlash_trails():
    stiff = Twin("thesis_final", seed=6, options=TwinOptions.exact(stiffness_nm_per_rad=(2e6, 2e6)))
    rigid = Twin("thesis_final", seed=6, options=TwinOptions.exact())
    dz = stiff.flange_pose()[2, 3] - rigid.flange_pose()[2, 3]
    assert -2e-3 < dz < -1e-5  # the arm sags by a fraction of a mm
    dq = stiff.qpos - rigid.qpos
    assert dq[0] == 0 and dq[3:].tolist() == [0, 0, 0] and abs(dq[1]) > 0
    lash = Twin("thesis_final", seed=6, options=TwinOptions.exact(backlash_rad=(1e-4,) * 6))
    base = lash.current_counts - lash.reference_counts
    lash.exchange(base + [10, 0, 0, 0, 0, 0])
    up = lash.qpos[0]
    lash.exchange(base + [20, 0, 0, 0, 0, 0])
    lash.exchange(base + [10, 0, 0, 0, 0, 0])
    assert lash.qpos[0] - up == pytest.approx(1e-4, rel=1e-6)  # same counts, other side of the gap


def test_view_scene_file():
    from planecal.twin.mjcf import view_scene_path, view_scene_xml
    path = view_scene_path(ROBOT)
    assert path.read_text() == view_scene_xml(ROBOT), "run scripts/build_mjcf.py"
    m = mujoco.MjModel.from_xml_path(str(path))  # includes mc70.xml
    assert m.njnt == 6 and m.geom("floor").id >= 0
