"""Level 2's whole kinematic model (model.measurement at level full): it is today's model at zero corrections,
its analytic Jacobian is the distance's derivative, its compliance is the twin's, and its
parameter files round-trip."""
import numpy as np
import pytest

from conftest import INITIAL, SEED_QE, TABLE10
from planecal.estimation.calibrate import layout_for
from planecal.model.cell_params import CellParams
from planecal.model.measurement import predict, predict_with_jacobian
from planecal.model.encoder import counts_to_joints
from planecal.model.gravity import gravity_world, joint_torques
from planecal.model.kinematics import Kinematics, fk as kin_fk
from planecal.model.layout import level1_layout, level2_layout
from planecal.model.measurement import flange_pose, kinematics_of
from planecal.io.params import load_params, save_params
from planecal.model.kinematics import fk


def corrected(params: CellParams, rng, compliance=True) -> CellParams:
    p = params.copy()
    p.geometry = rng.normal(0.0, 1e-3, (6, 4))
    p.base = rng.normal(0.0, 1e-3, 6)
    if compliance:
        p.compliance = rng.normal(0.0, 3e-7, 6)
    return p


@pytest.mark.parametrize("params", [TABLE10, INITIAL], ids=["table10", "initial"])
def test_zero_corrections_reproduce_todays_model_on_the_seeds_real_samples(robot, params):
    L2 = level2_layout(1, compliance=True)
    d1, J1 = predict_with_jacobian(robot, SEED_QE, params)  # level 1's own code path
    d2, J2 = predict_with_jacobian(robot, SEED_QE, params, layout=L2)  # the whole model's
    assert np.abs(d2 - d1).max() < 1e-12
    n1 = len(level1_layout(1))
    assert L2.names[:n1] == level1_layout(1).names
    np.testing.assert_allclose(J2[:, :n1], J1, rtol=0, atol=1e-12 * np.abs(J1).max())
    q = counts_to_joints(robot, SEED_QE)
    assert np.abs(flange_pose(robot, q, params) - fk(robot.kinematics.with_offsets(params.joint_offsets), q)).max() < 1e-12
    # and the distances are the seed's Table 10 check values (test_cell's)
    if params is TABLE10:
        np.testing.assert_allclose(d2 * 1e3, [89.776, 85.318, 68.221, 68.017, 71.580], atol=0.01)


def test_level2_model_is_the_kinematics_chain_with_corrections(robot):
    # an independent path: kinematics.Kinematics built by hand, its 4x4 product (fk)
    p = corrected(TABLE10, np.random.default_rng(3), compliance=False)
    q = counts_to_joints(robot, SEED_QE)
    kin = kinematics_of(robot, p)
    assert isinstance(kin, Kinematics)
    np.testing.assert_allclose(kin.alpha[1:], robot.alpha[:-1] + p.geometry[1:, 0])
    np.testing.assert_allclose(kin.d, robot.d + p.geometry[:, 3])
    ref = kin_fk(kin, q)
    assert np.abs(flange_pose(robot, q, p) - ref).max() < 1e-14
    # a correction moves the prediction (the distances differ by mm, not 0)
    assert np.abs(predict(robot, SEED_QE, p) - predict(robot, SEED_QE, TABLE10)).max() > 1e-4


@pytest.mark.parametrize("n_planes", [1, 3])
def test_analytic_jacobian_against_central_differences(robot, n_planes):
    rng = np.random.default_rng(n_planes)
    base = CellParams(TABLE10.joint_offsets, TABLE10.sensor_origin, TABLE10.phi_y,
                      TABLE10.phi_z, [TABLE10.planes[0]] * n_planes)
    p = corrected(base, rng)
    L = level2_layout(n_planes, compliance=True)
    plate = np.arange(len(SEED_QE)) % n_planes
    d, J = predict_with_jacobian(robot, SEED_QE, p, plate, L)
    x = p.to_vector(L)
    for k, name in enumerate(L.names):
        h = 1e-9 if name.startswith("c") and L.param(name).unit.startswith("rad/") else 1e-6
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (predict(robot, SEED_QE, CellParams.from_vector(xp, L), plate)
              - predict(robot, SEED_QE, CellParams.from_vector(xm, L), plate)) / (2 * h)
        scale = max(np.abs(fd).max(), np.abs(J[:, k]).max())
        if scale == 0.0:
            continue  # a plane no sample is on
        # central differences of step h: error ~ h^2 d''' ~ 1e-12 relative, rounding 1e-10
        assert np.abs(fd - J[:, k]).max() <= 1e-6 * scale, name


def test_compliance_columns_are_offset_columns_times_the_gravity_torque(robot):
    p = corrected(TABLE10, np.random.default_rng(7))
    L = level2_layout(1, compliance=True)
    _, J = predict_with_jacobian(robot, SEED_QE, p, layout=L)
    tau = joint_torques(robot, counts_to_joints(robot, SEED_QE))
    np.testing.assert_allclose(J[:, L.slice("compliance")], J[:, L.slice("joint_offsets")] * tau,
                               rtol=1e-12)
    # J2 and J3 carry the arm: hundreds of N m (the profile's source says 985-1831 and
    # 433-523 N m over the sampled region); J1's axis is vertical: no torque
    assert np.all(np.abs(tau[:, 1]) > 500) and np.all(np.abs(tau[:, 2]) > 200)
    assert np.abs(tau[:, 0]).max() < 1e-9


def test_gravity_torque_is_the_twins(robot):
    """The same torque as the twin's MuJoCo model gives its ticks (twin.errors.gravity_model
    read from the compiled MJCF), and as MuJoCo's own inverse dynamics at rest."""
    import mujoco

    from planecal.twin.errors import gravity_model
    from planecal.twin.mjcf import link_body_name, robot_spec
    model = robot_spec(robot).compile()
    links = [model.body(link_body_name(i + 1)).id for i in range(6)]
    W_twin = (np.zeros((6, 1, 3)),) + gravity_model(model, links, links[-1])
    W = gravity_world(robot)
    q = counts_to_joints(robot, SEED_QE)
    from planecal.twin.ticks import gravity_torque
    data = mujoco.MjData(model)
    for qi, t in zip(q, joint_torques(robot, q)):
        ref = np.empty(6)
        gravity_torque(qi, W_twin, ref)
        np.testing.assert_allclose(t, ref, rtol=1e-9, atol=1e-7)  # MuJoCo: 1e-9 kg minimum
        data.qpos[:] = qi
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        # qfrc_bias at rest is the torque holding the arm against gravity: -tau
        np.testing.assert_allclose(t, -data.qfrc_bias, rtol=1e-6, atol=1e-6)
    assert W[3].tolist() == [2, 3, 4, 5]


def test_level2_parameter_file_round_trips(tmp_path, robot):
    p = corrected(TABLE10, np.random.default_rng(11))
    f = tmp_path / "p.json"
    save_params(f, p)
    back = load_params(f)
    for name in ("geometry", "base", "compliance", "joint_offsets", "planes"):
        np.testing.assert_array_equal(getattr(back, name), getattr(p, name))
    assert np.abs(predict(robot, SEED_QE, back) - predict(robot, SEED_QE, p)).max() == 0.0
    # a level-1 file has no kinematics key
    save_params(f, TABLE10)
    assert "kinematics" not in f.read_text()


def test_layout_for_the_mc70_frees_beta_only_between_the_parallel_axes(robot):
    L = layout_for(robot, 2, "full")
    free = L.names_of(L.default_free)
    assert [n for n in free if n.startswith("beta")] == ["beta3"]
    # delta1 and delta6 fixed as in level 1 (a plane never tells them from the plates' turn
    # and the sensor's roll); the base frame a candidate
    assert "delta1" not in free and "delta6" not in free and "base_rz" in free
    assert layout_for(robot, 2, "offsets") is level1_layout(2)
    assert layout_for(robot, 1, "offsets", compliance=True).names_of(
        layout_for(robot, 1, "offsets", compliance=True).default_free)[-2:] == ["c2", "c3"]
