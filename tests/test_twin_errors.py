"""The realistic twin's error sources, each switched on alone and checked against its own
formula or an independent peer: gravity compliance against MuJoCo's own inverse dynamics,
the gear error's amplitude and period, backlash by the direction of approach, encoder
quantisation within half a count, the true geometry against the analytic model; and the
ideal profile against the first twin."""
import os

os.environ.setdefault("MUJOCO_GL", "disable")

from dataclasses import replace  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from planecal.model.measurement import beam_direction, plane_distance  # noqa: E402
from planecal.model.encoder import counts_to_joints  # noqa: E402
from planecal.model.kinematics import fk as kin_fk  # noqa: E402
from planecal.model.scene import load_scene  # noqa: E402
from planecal.twin import Twin, TwinOptions  # noqa: E402
from planecal.twin import ticks as T  # noqa: E402
from planecal.twin.profile import draw_world, load_profile  # noqa: E402
from planecal.twin.truth import Truth, draw_truth  # noqa: E402

SCENE = load_scene("thesis_final")
ROBOT = SCENE.robot
EXACT = TwinOptions.exact()


def nominal_q(twin):
    return counts_to_joints(ROBOT, twin.current_counts) + twin.truth.joint_offsets


def gravity_torque_mujoco(twin, qpos):
    """The torque gravity puts on each joint, from MuJoCo's own inverse dynamics on the
    twin's model (its inertials): -qfrc_bias at zero velocity, gravity on."""
    m = twin.model
    g = m.opt.gravity.copy()
    m.opt.gravity[:] = (0.0, 0.0, -9.81)
    try:
        d = mujoco.MjData(m)
        d.qpos[:] = qpos
        mujoco.mj_forward(m, d)
        return -d.qfrc_bias.copy()
    finally:
        m.opt.gravity[:] = g


def test_compliance_deflects_each_joint_by_torque_over_stiffness():
    # the realistic world's geometry (a tilted base, moved links) and a payload: the
    # deflection of J2 and J3 is the gravity torque at the deflected pose / stiffness,
    # with the torque from MuJoCo's inverse dynamics of the same model
    world, _ = draw_world(SCENE, 3, load_profile("realistic", ROBOT))
    k = (None, 4e6, 2.5e6, None, None, None)
    opts = replace(EXACT, stiffness_nm_per_rad=k, payload=(2.0, (0.01, -0.02, 0.09)))
    stiff = Twin(SCENE, truth=world, options=opts)
    rigid = Twin(SCENE, truth=world, options=replace(opts, stiffness_nm_per_rad=None))
    rng = np.random.default_rng(1)
    base = stiff.current_counts
    for _ in range(20):
        c = base + np.rint(rng.normal(0, 0.3, 6) * ROBOT.gains).astype(np.int64)
        stiff.set_counts(c)
        rigid.set_counts(c)
        dq = stiff.qpos - rigid.qpos
        tau = gravity_torque_mujoco(stiff, stiff.qpos)
        assert abs(dq[1]) > 1e-5 and dq[[0, 3, 4, 5]].tolist() == [0, 0, 0, 0]
        np.testing.assert_allclose(dq[1:3], tau[1:3] / np.array([4e6, 2.5e6]), rtol=1e-8)


def test_the_ticks_gravity_model_is_mujocos():
    # the tick's own recursion (numba) against MuJoCo's inverse dynamics, at random poses
    # of a true geometry, with the payload
    world, _ = draw_world(SCENE, 5, load_profile("realistic", ROBOT))
    twin = Twin(SCENE, truth=world, options=replace(EXACT, payload=(1.5, (0.0, 0.0, 0.08))))
    tau = np.empty(6)
    rng = np.random.default_rng(2)
    for q in rng.uniform(-2.5, 2.5, (30, 6)):
        T.gravity_torque(q, twin._W, tau)
        want = gravity_torque_mujoco(twin, q)
        np.testing.assert_allclose(tau, want, rtol=1e-10, atol=1e-9 * np.abs(want).max())


def test_gear_error_has_its_amplitude_and_period():
    # joint 2 only: q2's error = A sin(n q2 + phi), the phase the truth's
    A, n, phi = 4e-5, 3.0, 0.7
    opts = replace(EXACT, gear=((2, A, n),))
    twin = Twin(SCENE, truth=Truth(draw_truth(SCENE, 0), gear_phases=(phi,)), options=opts)
    base = twin.current_counts
    q2, err = [], []
    for k in range(0, 400):
        c = base.copy()
        c[1] += int(k * ROBOT.gains[1] * 2 * np.pi / n / 400)  # one period of the error
        twin.set_counts(c)
        q = nominal_q(twin)
        q2.append(q[1] - twin.truth.joint_offsets[1])
        err.append(twin.qpos[1] - q[1])
    q2, err = np.array(q2), np.array(err)
    np.testing.assert_allclose(err, A * np.sin(n * q2 + phi), atol=1e-15)
    assert err.max() == pytest.approx(A, rel=1e-3) and err.min() == pytest.approx(-A, rel=1e-3)
    assert np.abs(twin.qpos[[0, 2, 3, 4, 5]] - nominal_q(twin)[[0, 2, 3, 4, 5]]).max() < 1e-15


def test_backlash_follows_the_joint_side_direction_through_the_coupling():
    b = np.array([1e-4, 2e-4, 3e-4, 4e-4, 5e-4, 6e-4])
    twin = Twin(SCENE, options=replace(EXACT, backlash_rad=tuple(b)))
    d0 = twin.current_counts - twin.reference_counts
    # motor 4 alone moves q4 and, through the coupling, q5 and q6
    for sign in (1, -1):
        rows = d0 + np.outer(np.arange(1, 11), [0, 0, 0, 20 * sign, 0, 0])
        twin.run(rows, read=False)
        err = twin.qpos - nominal_q(twin)
        # q4, q5, q6 moved: each trails by half its backlash against its own direction
        dq = np.sign(ROBOT.coupling[3:, 3] / ROBOT.gains[3]) * sign
        np.testing.assert_allclose(err[3:], -0.5 * b[3:] * dq, atol=1e-15)
        d0 = rows[-1]
    assert np.abs(err[:3]).max() < 1e-15  # joints that never moved: no side taken yet


def test_quantisation_puts_each_motor_within_half_a_count():
    twin = Twin(SCENE, options=replace(EXACT, quantization=True))
    c = twin.current_counts
    x = []
    for _ in range(400):  # a new rest each time
        twin.set_counts(c)
        dq = twin.qpos - nominal_q(twin)
        x.append(np.linalg.solve(ROBOT.coupling, dq) * ROBOT.gains)  # counts, motor side
    x = np.array(x)
    assert np.all(np.abs(x) <= 0.5 + 1e-9)
    assert np.all(np.abs(x.mean(0)) < 0.05) and np.allclose(x.var(0), 1 / 12, rtol=0.2)


def test_true_geometry_is_in_mujoco_and_the_reading_is_the_analytic_model():
    # a realistic world: MuJoCo's flange = the analytic true geometry at the twin's joint
    # state; the laser reading = the distance of the true sensor beam to the true plane
    world, _ = draw_world(SCENE, 2, load_profile("realistic", ROBOT))
    twin = Twin(SCENE, truth=world, options=EXACT)
    assert world.kinematics is twin.true_kinematics
    rng = np.random.default_rng(4)
    base = twin.current_counts
    checked = 0
    p = world.params
    for _ in range(200):
        twin.set_counts(base + np.rint(rng.normal(0, 0.02, 6) * ROBOT.gains).astype(np.int64))
        F = kin_fk(world.kinematics, twin.qpos)
        np.testing.assert_allclose(twin.flange_pose(), F, atol=1e-12)
        o = F[:3, :3] @ p.sensor_origin + F[:3, 3]
        z = F[:3, :3] @ beam_direction(p.phi_y, p.phi_z)
        d = float(plane_distance(p.planes[0], o, z)) * 1e3
        h = twin.hit()
        if h.plate == 0:
            assert h.distance_m * 1e3 == pytest.approx(d, abs=1e-9)
            r = twin.read()
            assert (r is None) == (not 65 <= d <= 95) and (r is None or abs(r - d) < 1e-9)
            checked += 1
    assert checked > 100


def test_ideal_profile_is_the_first_twin():
    prof = load_profile("ideal", ROBOT)
    for seed in (0, 3):
        world, opts = draw_world(SCENE, seed, prof)
        a, b = Twin(SCENE, truth=world, seed=seed, options=opts), Twin(SCENE, seed=seed)
        assert np.array_equal(a.truth.to_vector(), b.truth.to_vector())
        assert a.options == b.options
        D = (a.current_counts - a.reference_counts) + np.cumsum(
            np.tile([10, -10, 5, 20, -5, 0], (300, 1)), axis=0)
        D = np.vstack([D, np.repeat(D[-1:], 200, axis=0)])
        ra, rb = a.run(D), b.run(D)
        assert all(np.array_equal(x, y, equal_nan=True) for x, y in zip(ra, rb))
        assert np.array_equal(a.qpos, b.qpos)


def test_realistic_profile_draws_every_joint_offset_and_the_geometry():
    prof = load_profile("realistic", ROBOT)
    world, opts = draw_world(SCENE, 1, prof)
    assert np.all(world.params.joint_offsets != 0)  # delta1 and delta6 too
    nom = Twin(SCENE, options=EXACT).true_kinematics
    assert nom is None
    kin = world.kinematics
    assert np.any(kin.a != 0) and np.any(kin.alpha != np.asarray(kin.alpha).round(12))
    assert kin.beta[2] != 0 and np.all(kin.beta[[0, 1, 3, 4, 5]] == 0)  # J2-J3 parallel only
    assert opts.quantization and opts.gear and opts.stiffness_nm_per_rad is not None
    again, _ = draw_world(SCENE, 1, prof)
    assert np.array_equal(again.kinematics.a, kin.a) and again.gear_phases == world.gear_phases


def test_a_joint_held_by_gravity_rests_on_one_flank_whichever_way_it_came():
    # J2 carries its links: with a preload below its gravity torque the backlash side is
    # gravity's, not the direction of motion; J1 (no preload) follows the motion
    b = (2e-4, 3e-4, 0.0, 0.0, 0.0, 0.0)
    opts = replace(EXACT, backlash_rad=b, backlash_preload_nm=(None, 200.0, None, None, None, None))
    twin = Twin(SCENE, options=opts)
    d0 = twin.current_counts - twin.reference_counts
    for sign in (1, -1, 1):
        rows = d0 + np.outer(np.arange(1, 8), [15 * sign, 15 * sign, 0, 0, 0, 0])
        twin.run(rows, read=False)
        d0 = rows[-1]
        err = twin.qpos - nominal_q(twin)
        tau = gravity_torque_mujoco(twin, nominal_q(twin))
        assert abs(tau[1]) > 200
        assert err[1] == pytest.approx(0.5 * b[1] * np.sign(tau[1]), abs=1e-15)
        assert err[0] == pytest.approx(-0.5 * b[0] * np.sign(ROBOT.gains[0]) * sign, abs=1e-15)


def test_laser_linearity_error_is_its_two_harmonics_over_the_window():
    a, p1, p2 = 0.03, 1.1, -0.4
    world = Truth(draw_truth(SCENE, 0), laser_phases=(p1, p2))
    lin = Twin(SCENE, truth=world, options=replace(EXACT, laser_linearity_mm=a,
                                                   check_steps=False))
    flat = Twin(SCENE, truth=world, options=replace(EXACT, check_steps=False))
    d0 = lin.current_counts - lin.reference_counts
    # a ramp along the beam's direction walks the distance through the window
    rows = d0 + np.outer(np.arange(-300, 300), [0, 6, -9, 0, 3, 0])
    got, want = lin.run(rows, read=True)[2], flat.run(rows, read=True)[2]
    ok = np.isfinite(got) & np.isfinite(want)
    assert ok.sum() > 100
    x = 2 * np.pi * (want[ok] - 65.0) / 30.0
    model = 0.7 * a * np.sin(x + p1) + 0.3 * a * np.sin(2 * x + p2)
    np.testing.assert_allclose(got[ok] - want[ok], model, atol=1e-12)
    assert np.ptp(want[ok]) > 10 and np.abs(got[ok] - want[ok]).max() <= a


def test_thermal_growth_scales_the_links_over_robot_time():
    # expansion 1.2e-5/K, a 3 K rise, 600 s time constant: after t seconds of moving the
    # links' translations are (1 + g(t)) of the start's, g = k rise (1 - exp(-t/tau)), in
    # MuJoCo and so in the readings; off, nothing grows
    world, _ = draw_world(SCENE, 2, load_profile("realistic", ROBOT))
    opts = replace(EXACT, thermal=(1.2e-5, 3.0, 600.0))
    warm, cold = Twin(SCENE, truth=world, options=opts), Twin(SCENE, truth=world, options=EXACT)
    d0 = warm.current_counts - warm.reference_counts
    hold = np.repeat(d0[None], 30_000, axis=0)  # 300 s at rest
    warm.run(hold, read=False)
    cold.run(hold, read=False)
    warm.run(hold[:1])  # the next call applies the heat of now
    g = 1.2e-5 * 3.0 * (1 - np.exp(-300.01 / 600.0))
    assert warm.growth() == pytest.approx(g, rel=1e-3) and cold.growth() == 0.0
    kin = world.kinematics
    grown = replace(kin, a=kin.a * (1 + warm._growth), d=kin.d * (1 + warm._growth))
    np.testing.assert_allclose(warm.flange_pose(), kin_fk(grown, warm.qpos), atol=1e-12)
    shift = np.linalg.norm(warm.flange_pose()[:3, 3] - cold.flange_pose()[:3, 3])
    assert 0.8 * g * 1.5 < shift < g * 3.0  # ~g times the arm's reach (1.5-2.5 m)
