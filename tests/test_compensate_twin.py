"""Compensation validated on the twin (issue 13's done-when): a level-1 calibration of 150
twin samples on the thesis cell; 30 targets in the calibrated region the calibration never
saw and ISO 9283's P1..P5, each visited 10 times from the nominal and the compensated counts;
AP in the robot's frame (studies.compensation). The figures over truths 0-4 and both
scenes: scripts/study_compensate.py, tabulated in docs/COMPENSATE.md."""
import numpy as np
import pytest

from planecal.safety.collision import CollisionWorld
from planecal.estimation.calibrate import calibrate
from planecal.estimation.compensate import CalibratedModel
from planecal.model.cell_params import CellParams
from planecal.model.scene import load_scene, nominal_params
from planecal.studies.compensation import compensation_study
from planecal.studies.rehearsal import RehearsalSettings, twin_samples
from planecal.studies.validation import robot_frame

SCENE = "thesis_final"


@pytest.fixture(scope="module")
def cell():
    scene = load_scene(SCENE)
    return scene, CollisionWorld(scene)


def _calibrated(scene, errors, truth_seed=0):
    st = RehearsalSettings(scene=SCENE, samples=150, errors=errors, truth_seed=truth_seed)
    world, opts = st.world(0)
    qe, d, plate, _, _ = twin_samples(scene, world, st, 100 + truth_seed, opts)
    fit = calibrate(scene.robot, qe, d, nominal_params(scene), plate).result
    return world, opts, qe, fit


def OffsetsModel(robot, delta):
    """The calibrated model of a level-1 result (robot.json's chain with joint offsets)."""
    return CalibratedModel(robot, CellParams(joint_offsets=delta))


def test_ideal_world_compensation_is_exact_up_to_noise(cell):
    scene, checker = cell
    world, opts, qe, fit = _calibrated(scene, "ideal")
    assert np.allclose(robot_frame(scene.robot, world), np.eye(4))  # delta1 = 0, no base error
    r = compensation_study(scene, world, opts, OffsetsModel(scene.robot, fit.params.joint_offsets),
                           qe, n_targets=30, cycles=10, seed=0, checker=checker)
    assert r["converged"] == 35
    # measured: nominal 4.98 mm median; compensated 0.016 (max 0.042); ISO P1..P5 0.038
    # max (the cube at the samples' medoid, validate's rule; 0.020 at their mean before)
    assert r["validation_nominal_median_mm"] > 3.0
    assert r["validation_compensated_median_mm"] < 0.03
    assert r["validation_compensated_max_mm"] < 0.06
    assert r["iso_compensated_max_mm"] < 0.05
    assert r["ratio_median"] > 100
    # with the truth's own offsets only the noise is left: repeatability (0.07 mm 3-sigma,
    # 10 visits averaged) and the counts' rounding (<= 0.03 mm)
    t = compensation_study(scene, world, opts, OffsetsModel(scene.robot,
                                                            world.params.joint_offsets),
                           qe, n_targets=30, cycles=10, seed=0, checker=checker)
    assert t["validation_compensated_max_mm"] < 0.035
    assert t["validation_compensated_median_mm"] < 0.015
    assert t["rounded_residual_max_mm"] < 0.03


def test_realistic_world_compensation_lands_within_the_iso_ap(cell):
    scene, checker = cell
    world, opts, qe, fit = _calibrated(scene, "realistic")
    r = compensation_study(scene, world, opts, OffsetsModel(scene.robot, fit.params.joint_offsets),
                           qe, n_targets=30, cycles=10, seed=0, checker=checker)
    assert r["converged"] == 35
    # measured (truth 0): nominal 4.48 mm median, compensated 0.60 (max 1.19); ISO P1..P5
    # compensated 1.11 median, 1.135 max. Level 1 leaves the link geometry's share.
    assert r["validation_compensated_median_mm"] < r["validation_nominal_median_mm"] / 5
    assert 0.3 < r["validation_compensated_median_mm"] < 0.9
    # the unseen targets land at the calibration's own ISO AP's order (docs/COMPENSATE.md:
    # median 0.55 against an ISO max of 0.35 mm here; with the cube at the samples' medoid,
    # validate's rule, its poses sit nearer the samples than the region's 30 targets)
    assert r["validation_compensated_median_mm"] <= 2.0 * r["iso_compensated_max_mm"]
    # in the cell frame the robot's placement and J1's zero (no plane sees them) stay
    assert r["validation_compensated_cell_median_mm"] > 2.0
