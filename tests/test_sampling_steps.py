"""Step generator (seed 7.1.2): integer, synchronized, <= 51 counts a tick at the MC70's
step (50), exact landing."""
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planecal.sampling.steps import MAX_STEP, max_step, n_steps, step_path

LIMIT = (1 << 24) - 1
STEP = 50  # the MC70's (Robot.step_counts: one below robot.json's max_step_counts 51)
counts = st.lists(st.integers(0, LIMIT), min_size=6, max_size=6).map(
    lambda v: np.array(v, np.int64))
near = st.lists(st.integers(-400, 400), min_size=6, max_size=6).map(
    lambda v: np.array(v, np.int64))


def check_path(start, goal, dwell=0):
    rows = step_path(start, goal, STEP, dwell=dwell)
    n = n_steps(start, goal, STEP)
    dq = goal - start
    assert rows.dtype == np.int64
    assert rows.shape == (n + dwell, 6)
    assert n == -(-int(np.max(np.abs(dq))) // 50)
    if n == 0:
        assert np.all(rows == goal)
        return
    full = np.concatenate([start[None], rows])
    steps = np.diff(full, axis=0)
    # never more than 51 counts a joint a tick (in fact never more than 50)
    assert np.max(np.abs(steps)) <= MAX_STEP
    assert max_step(start, rows) <= 50
    # the path lands exactly: the steps sum to the move
    assert np.array_equal(steps.sum(axis=0), dq)
    assert np.array_equal(rows[n - 1], goal)
    # synchronized: every joint tracks dq * k / n within half a count, so all arrive on tick n
    k = np.arange(1, n + 1)[:, None]
    assert np.max(np.abs(rows[:n] - start - dq * k / n)) <= 0.5 + 1e-9
    moving = dq != 0
    # the joint that moves most is still moving on the last step; none overshoots its goal
    if n > 1:
        worst = int(np.argmax(np.abs(dq)))
        assert rows[n - 2, worst] != goal[worst]
    lo, hi = np.minimum(start, goal), np.maximum(start, goal)
    assert np.all((rows >= lo) & (rows <= hi))
    # monotone per joint
    assert np.all(steps[:n][:, moving] * np.sign(dq[moving]) >= 0)
    # dwell: the goal repeated
    assert np.all(rows[n:] == goal)


@settings(max_examples=80, deadline=None)  # paths of up to 335 000 ticks: keep it brisk
@given(counts, counts)
def test_any_start_goal_in_24_bit_range(start, goal):
    check_path(start, goal)


@settings(max_examples=400, deadline=None)
@given(counts, near)
def test_short_moves_with_dwell(start, off):
    goal = np.clip(start + off, 0, LIMIT)
    check_path(start, goal, dwell=5)


def test_seed_example():
    """Seed 7.1.2: +300 on q1-q3, -300 on q4-q5 from home gives six rows of 50."""
    home = np.full(6, 8388608, np.int64)
    goal = home + np.array([300, 300, 300, -300, -300, 0])
    rows = step_path(np.zeros(6, np.int64), goal - home, STEP)
    expect = np.array([[50, 50, 50, -50, -50, 0]]) * np.arange(1, 7)[:, None]
    assert np.array_equal(rows, expect)


def test_no_motion_only_dwell():
    s = np.array([5, 6, 7, 8, 9, 10], np.int64)
    rows = step_path(s, s, STEP, dwell=5)
    assert rows.shape == (5, 6) and np.all(rows == s)
    assert step_path(s, s, STEP).shape == (0, 6)


def test_full_range_move():
    start = np.zeros(6, np.int64)
    goal = np.full(6, LIMIT, np.int64) * np.array([1, -1, 1, 0, 1, -1])
    rows = step_path(start, goal, STEP)
    assert len(rows) == -(-LIMIT // 50)
    assert max_step(start, rows) == 50
    assert np.array_equal(rows[-1], goal)
