import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planecal.model.encoder import counts_to_joints, joints_to_counts, offsets_to_qe0

# Seed Table 7: encoder model WITHOUT coupling, each row one joint turned 10 deg on the
# teach pendant (Table 6). Entries in degrees.
TABLE7 = np.array([
    [9.999661127, 0, 0, 0, 0, 0],
    [0, 10.00142912, 0, 0, 0, 0],
    [0, 0, 9.999019289, 0, 0, 0],
    [0, 0, 0, 10.0026304, 0.1117503448, -0.170466859],
    [0, 0, 0, 0, 9.999999604, 0.170466859],
    [0, 0, 0, 0, 0, 9.999170161],
])
# Table 8: the same readings WITH coupling
TABLE8 = np.array([
    [9.999661127, 0, 0, 0, 0, 0],
    [0, 10.00142912, 0, 0, 0, 0],
    [0, 0, 9.999019289, 0, 0, 0],
    [0, 0, 0, 10.0026304, 0.000636422119, 0.00098166495],
    [0, 0, 0, 0, 9.999999604, -0.00097166],
    [0, 0, 0, 0, 0, 9.999170161],
])


def table7_counts(robot):
    return robot.qe0 + robot.gains * np.deg2rad(TABLE7)


def test_table7_readings_are_whole_encoder_counts(robot):
    """Table 7 = counts / gains: the counts it implies are integers where the readings were
    printed in full (a check of the gain table)."""
    c = table7_counts(robot) - robot.qe0
    for i, j, expect in [(0, 0, 7460), (1, 1, 9690), (2, 2, -9363), (3, 4, -73), (3, 5, -73), (4, 5, 73)]:
        assert abs(c[i, j] - expect) < 1e-5


def test_without_coupling_reproduces_table7(robot):
    x = (table7_counts(robot) - robot.qe0) / robot.gains
    np.testing.assert_allclose(np.rad2deg(x), TABLE7, atol=1e-9)


def test_coupling_reproduces_table8(robot):
    q = np.rad2deg(counts_to_joints(robot, table7_counts(robot)))
    np.testing.assert_allclose(np.diag(q), np.diag(TABLE8), atol=1e-9)
    off = ~np.eye(6, dtype=bool)
    # coupled q5, q6 vanish to the order Table 8 shows (MODEL-NOTES: within 0.001 deg)
    assert np.abs(q[off]).max() < 0.001
    # magnitudes agree to 5e-5 deg; Table 8 prints two of the three with the other sign
    for i, j in [(3, 4), (3, 5), (4, 5)]:
        assert abs(abs(q[i, j]) - abs(TABLE8[i, j])) < 5e-5
    # and without coupling they would be the 0.11 / 0.17 deg of Table 7
    assert np.abs(TABLE7[off]).max() > 0.17


def test_zero_reference_is_zero_joints(robot):
    np.testing.assert_array_equal(counts_to_joints(robot, robot.qe0), np.zeros(6))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6))
def test_counts_joints_round_trip(robot, q):
    q = np.array(q)
    qe = joints_to_counts(robot, q, rounded=False)
    np.testing.assert_allclose(counts_to_joints(robot, qe), q, atol=1e-12)
    qi = joints_to_counts(robot, q)
    assert qi.dtype == np.int64
    # rounding to whole counts moves a joint by at most half a count (plus coupling)
    assert np.abs(counts_to_joints(robot, qi) - q).max() < 1.0 / np.abs(robot.gains).min()


def test_offsets_to_qe0_realises_offsets(robot):
    rng = np.random.default_rng(0)
    delta = rng.uniform(-5e-3, 5e-3, 6)
    qe = robot.qe0 + rng.integers(-50000, 50000, (10, 6))
    qe0_new = offsets_to_qe0(robot, delta)
    np.testing.assert_allclose(counts_to_joints(robot, qe, qe0_new),
                               counts_to_joints(robot, qe) + delta, atol=1e-14)
    # a delta4 alone also shifts the encoder offsets of 5 and 6 (C^-1); one number by hand
    d4 = np.zeros(6)
    d4[3] = 1e-3
    shift = robot.qe0 - offsets_to_qe0(robot, d4)
    assert abs(shift[3] - 37.0121) < 1e-9
    assert abs(shift[4] - (-37428.0 * 0.01111111e-3)) < 1e-9
