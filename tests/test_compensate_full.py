"""compensate with level 2's whole model (``CalibratedModel`` of a full result)."""
import numpy as np


from planecal.model.cell_params import CellParams  # noqa: E402
from planecal.estimation.compensate import CalibratedModel, compensate, load_calibrated  # noqa: E402
from planecal.io.targets import Targets  # noqa: E402
from planecal.model.kinematics import frame_error  # noqa: E402
from planecal.io.params import save_params  # noqa: E402
from planecal.model.kinematics import fk
from planecal.model.robot import load_robot  # noqa: E402
from regions import joint_region  # noqa: E402

ROBOT = load_robot()
DELTA = np.array([0.0, 2e-3, -1.5e-3, 1e-3, -2e-3, 0.0])
Q_CAL = np.radians([28.7, -15.2, -44.5, -66.1, 73.3, -92.5])


def _params(geometry=None, base=None, compliance=None, delta=DELTA):
    return CellParams(delta, [0.0257, -0.0725, 0.1769], 1.2427, -1.0472,
                      [[0.0, -1.02511, 3.62708]], geometry=geometry, base=base,
                      compliance=compliance)


def _targets(n=20, seed=0):
    q = Q_CAL + np.random.default_rng(seed).uniform(-0.3, 0.3, (n, 6))
    T = fk(ROBOT.kinematics, q)
    return q, Targets([f"t{i}" for i in range(n)], T, np.full_like(q, np.nan), ["x"] * n, "x")


def test_full_model_without_corrections_is_the_offsets_model():
    q, t = _targets()
    region = joint_region(q, 0.01)
    a = compensate(CalibratedModel(ROBOT, _params()), t, region)
    b = compensate(CalibratedModel(ROBOT, CellParams(joint_offsets=DELTA)), t, region)
    assert np.abs(a.q_corrected - b.q_corrected).max() < 1e-10
    assert (a.counts_corrected == b.counts_corrected).all()


def test_full_model_with_corrections_is_solved_and_registered():
    rng = np.random.default_rng(1)
    g = rng.normal(0, 1e-4, (6, 4))
    g[:, 2] = 0.0
    g[2, 2] = 1e-4  # beta3: J2 || J3
    base = np.array([1e-3, -2e-3, 0.5e-3, 1e-3, -1e-3, 0.02])
    m = CalibratedModel(ROBOT, _params(g, base, np.array([0, 2e-7, 3e-7, 0, 0, 0])))
    q, t = _targets(seed=2)
    region = joint_region(q, 0.05)
    c = compensate(m, t, region)
    assert c.converged.all() and c.iterations.max() <= 4
    assert c.residual_m.max() < 1e-9 and c.residual_rad.max() < 1e-9
    # the model's flange at the corrected joints is the target in the robot's frame
    F = m.robot_frame()
    assert np.abs(m.flange(c.q_corrected)[:, :3, 3] - (F @ t.pose)[:, :3, 3]).max() < 1e-9
    # the base frame's turn about z (0.02 rad, no plate sees it) is registered away: the
    # J1 correction stays small; in the cell frame J1 turns by it
    assert np.abs(c.correction_rad[:, 0]).max() < 2e-3
    cell = compensate(m, t, region, frame="cell")
    assert np.abs(cell.correction_rad[:, 0]).min() > 0.015
    assert np.allclose(F[:3, :3], frame_error(base)[:3, :3] @ np.eye(3), atol=2e-3)


def test_a_full_result_file_is_read_as_a_full_model(tmp_path):
    p = tmp_path / "full.json"
    g = np.zeros((6, 4))
    g[1, 1] = 2e-4
    save_params(p, _params(g))
    m, doc = load_calibrated(ROBOT, p)
    assert m.level == "full" and "kinematics" in doc
    assert np.array_equal(m.params.geometry, g)
    save_params(tmp_path / "l1.json", _params())
    m1, _ = load_calibrated(ROBOT, tmp_path / "l1.json")
    assert m1.level == "offsets" and not m1.params.geometry.any()
