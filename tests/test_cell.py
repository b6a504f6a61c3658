import numpy as np

from conftest import INITIAL, SEED_DM, SEED_QE, TABLE10
from planecal.model.cell_params import CellParams
from planecal.model.measurement import beam_direction, predict, predict_with_jacobian, sensor_rotation
from planecal.model.planes import n_tilde_from_point_normal, point_normal_from_n_tilde, transform_n_tilde
from planecal.model.layout import level1_layout


def test_seed_samples_with_table10(robot):
    d = predict(robot, SEED_QE, TABLE10) * 1e3
    np.testing.assert_allclose(d, [89.776, 85.318, 68.221, 68.017, 71.580], atol=0.01)
    # the readings are mm away, as the seed's own resampling spread (8.4)
    assert 0.01 < np.abs(d - SEED_DM).max() < 3.0


def test_seed_samples_with_initial_parameters(robot):
    d = predict(robot, SEED_QE, INITIAL) * 1e3
    np.testing.assert_allclose(d, [106.677, 104.277, 78.472, 83.416, 82.364], atol=0.01)


def test_beam_direction_is_seed_value():
    # seed 6.4.2 prints (0.4733, -0.8198, 0.3222) for phi = (1.2427, -1.0472)
    np.testing.assert_allclose(beam_direction(1.2427, -1.0472), [0.4733, -0.8198, 0.3222], atol=1e-4)
    R = sensor_rotation(1.2427, -1.0472)
    np.testing.assert_allclose(R[:, 2], beam_direction(1.2427, -1.0472), atol=1e-15)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)


def test_thesis_plane_from_point_and_normal():
    # seed 6.4.2: a = [0.35 0 0], b = [0 0.2406 0.068], corner (0.729, 0.737, 0.484)
    n = np.cross([0.35, 0, 0], [0, 0.2406, 0.068])
    nt = n_tilde_from_point_normal([0.729, 0.737, 0.484], n)
    np.testing.assert_allclose(nt, [0, -1.02511, 3.62708], atol=2e-3)  # seed rounds its normal


def test_n_tilde_frame_change_round_trip():
    rng = np.random.default_rng(0)
    nt = np.array([0.3, -1.2, 3.5])
    from scipy.spatial.transform import Rotation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    T[:3, 3] = rng.normal(size=3)
    nb = transform_n_tilde(T, nt)
    p, _ = point_normal_from_n_tilde(nt)
    pts = p + np.cross(nt, rng.normal(size=(5, 3)))  # points on the plane in frame P
    pb = pts @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(pb @ nb, 1.0, atol=1e-12)
    Tinv = np.linalg.inv(T)
    np.testing.assert_allclose(transform_n_tilde(Tinv, nb), nt, atol=1e-12)


def test_jacobian_against_central_differences(robot):
    rng = np.random.default_rng(5)
    for trial in range(8):
        k = 1 + trial % 3
        x = np.concatenate([rng.uniform(-5e-3, 5e-3, 6), [0.03, -0.07, 0.18],
                            [rng.uniform(0.9, 1.5), rng.uniform(-1.2, -0.9)],
                            np.tile([0.0, -1.0, 3.6], k) + rng.uniform(-0.3, 0.3, 3 * k)])
        layout = level1_layout(k)
        params = CellParams.from_vector(x, layout)
        qe = SEED_QE + rng.integers(-3000, 3000, (5, 6))
        pidx = rng.integers(0, k, 5)
        d, J = predict_with_jacobian(robot, qe, params, pidx)
        Jn = np.zeros_like(J)
        for j in range(len(x)):
            h = 1e-6 * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            Jn[:, j] = (predict(robot, qe, CellParams.from_vector(xp, layout), pidx)
                        - predict(robot, qe, CellParams.from_vector(xm, layout), pidx)) / (2 * h)
        np.testing.assert_allclose(J, Jn, rtol=1e-6, atol=1e-9 * np.abs(J).max())
        # samples on plane k have zero derivative for the other planes' n~
        for i, pk in enumerate(pidx):
            others = [c for m in range(k) if m != pk for c in layout.columns("plane")[m]]
            assert np.all(J[i, others] == 0)
