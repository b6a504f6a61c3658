"""Issue 22, the approach direction, recorded: each sample's per-joint sign of its last
joint-side motion (``sampling.approach``), followed by the driver from the measured counts,
written to the sample file by the sampling run and carried by the studies' in-memory runs.
The independent peer is the twin's own backlash state (``twin.ticks``: ``S[DIR]``, set by
the compiled tick), read when each sample is recorded."""
import numpy as np
import pytest

import planecal.twin.ticks as T
from planecal.io.samples import read_samples
from planecal.links.base import AlwaysEnabled
from planecal.model.robot import load_robot
from planecal.model.scene import load_scene
from planecal.sampling.approach import ApproachTracker
from planecal.sampling.driver import Driver
from planecal.sampling.observer import NullObserver
from planecal.sampling.run import RunSettings, SamplingRun

collision = pytest.importorskip("planecal.safety.collision")


@pytest.fixture(scope="module")
def cell():
    scene = load_scene("thesis_final")
    return scene, collision.CollisionWorld(scene, clearance_m=0.01)


class TwinSides(NullObserver):
    """The twin's backlash state when each sample is recorded, and the legs driven into
    each sample (``via`` legs: a detour; two ``sample`` legs: a laser read gave up between)."""

    def __init__(self, twin):
        self.twin, self.sides, self.legs, self._legs = twin, [], [], []

    def on_path(self, kind, q_start, q_goal, rows):
        self._legs.append(kind)

    def on_sample(self, index, qe, d_mm, plate):
        self.sides.append(self.twin._S[T.DIR:T.DIR + 6].copy())
        self.legs.append(self._legs)
        self._legs = []


def inferred_from_consecutive_samples(robot, start, qe):
    """What one would guess without the record: the sign of M (qe_i - qe_(i-1)) per joint,
    the last guess where a joint did not move."""
    M = robot.coupling / robot.gains[None, :]
    side, prev, out = np.zeros(6, int), np.asarray(start), []
    for c in qe:
        dq = M @ (c - prev).astype(float)
        side = np.where(dq != 0, np.sign(dq), side).astype(int)
        out.append(side)
        prev = c
    return np.array(out)


def test_recorded_direction_is_the_twins_backlash_state_detours_included(cell, tmp_path):
    from planecal.twin.world import WorldRef, make_twin

    scene, world = cell
    twin = make_twin(scene, WorldRef("realistic", 3), 3)  # backlash, lag servo, gravity
    assert twin._S[T.FLAGS] & T.BACKLASH
    start = twin.current_counts
    seen = TwinSides(twin)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot, seen)
    out = tmp_path / "run.tsv"
    rs = RunSettings.for_scene(scene, samples=4, seed=3)
    assert SamplingRun(drv, scene, rs, out, world).run().status == "complete"
    s = read_samples(out)  # through the file: the header names dir1..dir6
    assert s.direction.dtype == np.int8 and s.direction.shape == (4, 6)
    np.testing.assert_array_equal(s.direction, np.array(seen.sides))
    assert np.all(s.direction != 0)  # every joint moved on the way to the first sample
    # some samples' last leg is a detour's: guessed from consecutive samples, J1..J4 (no
    # wrist coupling in their rows) would be wrong there, and right wherever the robot
    # came straight from the last sample
    guess = inferred_from_consecutive_samples(scene.robot, start, s.qe)
    detour = ["via" in legs for legs in seen.legs]
    straight = [legs == ["sample"] for legs in seen.legs]
    assert any(detour) and any(straight) and all(a != b for a, b in zip(detour, straight))
    wrong = guess[:, :4] != s.direction[:, :4]
    assert any(wrong[i].any() for i in range(4) if detour[i])
    assert not any(wrong[i].any() for i in range(4) if straight[i])


def test_the_in_memory_run_records_what_the_sample_file_records(cell):
    """A study's run in a path-dependent world (driven, ``MemoryRecorder``) and the full
    sampling run (the sample file) on the same seeds: the same directions."""
    from planecal.studies.rehearsal import RehearsalSettings, rehearse_samples, twin_samples

    scene, _ = cell
    st = RehearsalSettings(samples=4, errors="realistic")
    world, opts = st.world(0)
    qe_f, _, _, dir_f, _ = rehearse_samples(scene, world, st, 5, opts)
    qe_m, _, _, dir_m, _ = twin_samples(scene, world, st, 5, opts)
    np.testing.assert_array_equal(qe_f, qe_m)
    assert dir_m.dtype == np.int8 and np.all(dir_m != 0)
    np.testing.assert_array_equal(dir_f, dir_m)


def test_joint_side_through_the_gains_and_the_wrist_coupling():
    """The definition on hand-made moves of the MC70 (g3, g5 < 0; q5 and q6 take J4's motor
    through C54 = -0.0111, C64 = +0.0171, and q6 J5's through C65 = -0.0169)."""
    robot = load_robot("mc70")
    t = ApproachTracker.for_robot(robot)
    c = np.full(6, 8_388_608, np.int64)
    t.follow(c[None])
    np.testing.assert_array_equal(t.side, np.zeros(6))  # nothing moved yet: unknown
    t.follow([c + [0, 0, 0, 10, 0, 0], c + [0, 0, 0, 20, 0, 0]])  # J4's motor only, +
    # J4 + (g4 > 0); on the joint side J5 turns by C54 dx4 < 0 and J6 by C64 dx4 > 0
    np.testing.assert_array_equal(t.side, [0, 0, 0, 1, -1, 1])
    t.follow([c + [0, 0, 5, 20, 0, 0]])  # J3's counts up: g3 < 0, its joint turns -
    np.testing.assert_array_equal(t.side, [0, 0, -1, 1, -1, 1])
    t.follow([c + [0, 0, 5, 20, 3, 0]])  # J5's counts up: q5 - (g5 < 0), q6 + (C65 < 0)
    np.testing.assert_array_equal(t.side, [0, 0, -1, 1, -1, 1])
    # J5's motor down by 1000 while J6's goes down by 10: q6 = x6/g6 - 0.0169 x5/g5 moves
    # by -10/24536 - 0.0169 * 1000 / 37428 = -4.1e-4 - 4.5e-4 < 0; and q5 goes +
    t.follow([c + [0, 0, 5, 20, -997, -10]])
    np.testing.assert_array_equal(t.side, [0, 0, -1, 1, 1, -1])
    # J6's motor up by 5 while J5's goes down by 1000 more: q6 moves by
    # 5/24536 - 0.0169 * (-1000) / (-37428) = 2.0e-4 - 4.5e-4 < 0: still -
    t.follow([c + [0, 0, 5, 20, -1997, -5]])
    np.testing.assert_array_equal(t.side, [0, 0, -1, 1, 1, -1])
    # a move that goes + then comes back: the last motion decides
    t.follow([c + [30, 0, 5, 20, -1997, -5], c + [25, 0, 5, 20, -1997, -5]])
    np.testing.assert_array_equal(t.side, [-1, 0, -1, 1, 1, -1])


class Overshoot:
    """A link whose servo overshoots: each joint passes its command by 3 counts on the
    tick its command stops changing, then settles back on it (the measured counts'
    last motion is against the commanded one's)."""

    def __init__(self, start):
        self.ref = np.asarray(start, np.int64)
        self.last_cmd = self.ref.copy()

    def exchange(self, delta):
        cmd = self.ref + np.asarray(delta, np.int64)
        moved = cmd - self.last_cmd
        self.last_cmd = cmd
        return self.ref.copy(), cmd + 3 * np.sign(moved) * (np.abs(moved) < 25)

    def close(self):
        pass


def test_the_direction_follows_the_measured_counts_not_the_commanded():
    robot = load_robot("mc70")
    start = np.full(6, 8_388_608, np.int64)
    drv = Driver(Overshoot(start), None, AlwaysEnabled(), robot)
    drv.start()
    np.testing.assert_array_equal(drv.direction, np.zeros(6))
    # J1 commanded up by 50, 40 and 10 counts, then held: the small last step overshoots
    rows = np.array([[50, 0, 0, 0, 0, 0], [90, 0, 0, 0, 0, 0], [100, 0, 0, 0, 0, 0],
                     [100, 0, 0, 0, 0, 0]])
    drv.follow(rows)
    # measured J1: +50, +90, +103 (overshoot), +100: its last motion is down
    assert drv.current[0] == start[0] + 100
    np.testing.assert_array_equal(drv.direction, [-1, 0, 0, 0, 0, 0])
