"""sampling.tour: robot time of a run (against the step generator and the twin's own tick
count) and the visiting order of a pose list (against brute force)."""
import itertools

import numpy as np
import pytest

from planecal.model.encoder import counts_to_joints
from planecal.sampling import tour as T
from planecal.sampling.steps import step_path


def _random_pairs(rng, n):
    for _ in range(n):
        a = rng.integers(8_000_000, 8_600_000, 6)
        span = int(rng.choice([0, 1, 49, 50, 51, 1000, 300_000]))
        b = a + rng.integers(-span, span + 1, 6)
        yield a, b


def test_move_ticks_is_the_step_generators_row_count():
    rng = np.random.default_rng(3)
    for a, b in _random_pairs(rng, 400):
        nominal = int(rng.choice([1, 7, 50]))
        dwell = int(rng.integers(0, 7))
        assert T.move_ticks(a, b, nominal, dwell) == len(step_path(a, b, nominal, dwell))
        assert T.move_ticks(a, b, nominal, dwell) == T.move_ticks(b, a, nominal, dwell)
    a = np.full(6, 8_000_000)
    assert T.move_ticks(a, a, 50) == 5  # no move: the dwell only
    assert T.move_ticks(a, a + [0, 0, 0, 0, 0, 101], 50) == 3 + 5  # the joint with most counts


def test_robot_ticks_sums_the_legs():
    start = np.full(6, 8_000_000)
    a = start + [5000, 0, 0, 0, 0, 0]  # 100 ticks
    b = a + [0, -2550, 10, 0, 0, 0]  # 51 ticks
    via = a + [0, 0, 0, 0, 0, 500]  # 10 ticks there, then 51 to b
    assert T.robot_ticks([a, b], start, read_ticks=100, nominal=50) == \
        100 + 5 + 100 + 51 + 5 + 100
    assert T.robot_ticks([a, b], start, read_ticks=100, vias=[[], [via]], nominal=50) == \
        100 + 5 + 100 + 10 + 51 + 5 + 100
    # on a robot: its step and its tick (the MC70's 50 counts and 10 ms, the UR5's 129
    # counts and 8 ms: 39 + 20 ticks of travel)
    from planecal.model.robot import load_robot
    mc70, ur5 = load_robot("mc70"), load_robot("ur5")
    assert (mc70.step_counts, ur5.step_counts) == (50, 129)
    assert T.robot_time_s([a, b], start, mc70, read_ticks=0) == pytest.approx(1.61)
    assert T.robot_time_s([a, b], start, ur5, read_ticks=0) == pytest.approx((59 + 10) * 0.008)


_CELLS: dict = {}


def _cell(name: str):
    from planecal.safety.collision import CollisionWorld
    from planecal.model.scene import load_scene
    if name not in _CELLS:
        scene = load_scene(name)
        _CELLS[name] = scene, CollisionWorld(scene, clearance_m=0.01)
    return _CELLS[name]


@pytest.fixture(scope="module")
def cell():
    return _cell("thesis_final")


@pytest.mark.parametrize("scene_name, planned", [("thesis_final", False),
                                                 ("thesis_final", True), ("ur5_table", False)])
def test_robot_ticks_match_the_twins_own_clock(tmp_path, scene_name, planned):
    """A rehearsal on the exact twin (no noise: each laser read takes exactly the 100
    readings of its buffer) ticks exactly as ``visit`` + ``robot_ticks`` predict at the
    robot's own step (the MC70's 50 counts a tick, the UR5's 129) and tick: the random
    planner with its detours, and a pose list in the order ListPlanner takes it. On the
    UR5, at the MC70's 50 counts the run's travel (its Clock) was 2.6x the ticks driven."""
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.driver import Driver
    from planecal.sampling.planner import ListPlanner, Planner
    from planecal.sampling.run import RunSettings, SamplingRun
    from planecal.studies.planning import plan
    from planecal.twin import Twin, TwinOptions

    scene, world = _cell(scene_name)
    step, tick_s = scene.robot.step_counts, scene.robot.tick_s
    twin = Twin(scene, truth="nominal", seed=0, options=TwinOptions.exact())
    start = twin.current_counts.copy()
    q0 = counts_to_joints(scene.robot, start)
    if planned:
        res = plan(scene, 14, 80, 3, None, world, ordered=False)  # the design's order
        counts, plates = np.array(res["counts"]), np.array(res["plates"])
        # in the tour's order ListPlanner visits all 14, one of the moves by a detour
        # (unavoidable)
        tr = T.order(counts, start, world, scene, nominal=step)
        assert tr.detours == 1 and tr.excluded == 0
        counts, plates = counts[tr.order], plates[tr.order]
        rs = RunSettings(scene=str(scene.path), samples=len(counts), seed=0)
        make = lambda: ListPlanner(scene, counts, plates, world)  # noqa: E731
    else:
        rs = RunSettings.for_scene(scene, samples=25, seed=7)
        make = lambda: Planner(scene, rs.pose, world)  # noqa: E731
    visits = T.visit(make(), q0, rs.samples, seed=rs.seed)
    drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
    stats = SamplingRun(drv, scene, rs, str(tmp_path / "run.tsv"), world,
                        planner=make()).run()
    assert stats.status == "complete"
    assert stats.rejected["laser"] == 0
    # +1: the driver's first exchange (a zero delta) is the run's
    assert stats.ticks == 1 + T.robot_ticks(visits, start, read_ticks=100, nominal=step)
    # the run's own account (tour.Clock in SamplingRun): travel + dwell + reads
    assert stats.read_ticks == 100 * rs.samples
    assert stats.ticks == 1 + stats.travel_ticks + rs.dwell_ticks * rs.samples + stats.read_ticks
    per = stats.per_sample()
    assert per["travel_per_sample_s"] == round(stats.travel_ticks * tick_s / rs.samples, 3)
    assert per["robot_time_per_sample_s"] == round(stats.ticks * tick_s / rs.samples, 3)
    if scene_name == "thesis_final":  # the check covered detour legs (the UR5 took none)
        assert any(v.via for v in visits)


def _brute(C):
    n = len(C) - 1
    return min(T.path_cost(C, [0, *p]) for p in itertools.permutations(range(1, n + 1)))


def test_order_is_optimal_on_small_instances():
    rng = np.random.default_rng(11)
    for n in range(1, 8):
        for _ in range(6):
            nodes = rng.integers(8_000_000, 8_400_000, (n + 1, 6))
            tr = T.order(nodes[1:], nodes[0], nominal=50)
            C = T.tick_matrix(nodes, 50).astype(float)
            assert sorted(tr.order) == list(range(n))
            assert tr.travel_ticks == T.path_cost(C, [0, *(i + 1 for i in tr.order)])
            assert tr.travel_ticks == _brute(C)


def test_heuristic_close_to_optimal_and_never_worse_than_the_input():
    """The local search alone (exact solver off) on 30 instances of 9 poses: never worse
    than the input order, within 3 % of the optimum (Held-Karp, itself checked above),
    optimal on most."""
    rng = np.random.default_rng(5)
    gaps = []
    for _ in range(30):
        nodes = rng.integers(8_000_000, 8_400_000, (10, 6))
        C = T.tick_matrix(nodes, 50).astype(float)
        best = T.path_cost(C, [0, *T.held_karp(C)])
        h = T.order(nodes[1:], nodes[0], exact_max=0, nominal=50)
        assert h.travel_ticks <= T.path_cost(C, range(10))
        gaps.append(h.travel_ticks / best - 1)
    assert max(gaps) < 0.03
    assert sum(g == 0 for g in gaps) >= 20


def test_order_keeps_a_good_input_order():
    rng = np.random.default_rng(2)
    nodes = rng.integers(8_000_000, 8_400_000, (40, 6))
    first = T.order(nodes[1:], nodes[0], nominal=50)
    again = T.order(nodes[1:][first.order], nodes[0], nominal=50)
    assert again.travel_ticks <= first.travel_ticks


def test_checked_order_is_driven_as_planned_and_saves_robot_time(cell):
    """On a D-optimal plan: every move of the checked tour is clear, so ListPlanner visits
    the list exactly in that order, and it costs less than half the robot time of the
    design's own order or a random one."""
    from planecal.model.encoder import joints_to_counts
    from planecal.sampling.planner import ListPlanner
    from planecal.studies.planning import plan

    scene, world = cell
    res = plan(scene, 30, 200, 1, None, world, ordered=False)  # the design's order
    counts, plates = np.array(res["counts"]), np.array(res["plates"])
    q0 = scene.calibration_q
    start = joints_to_counts(scene.robot, q0)

    def ticks(idx):
        v = T.visit(ListPlanner(scene, counts[idx], plates[idx], world), q0, len(idx))
        seq = [int(np.flatnonzero(np.all(counts[idx] == x.goal, axis=1))[0]) for x in v]
        return T.robot_ticks(v, start, nominal=50), seq, v

    tr = T.order(counts, start, world, scene, nominal=50)
    assert tr.detours == 0 and tr.excluded == 0 and tr.paths_checked > 0
    t_tour, seq, v = ticks(np.array(tr.order))
    assert seq == list(range(len(counts)))  # visited exactly in the tour's order
    assert not any(x.via for x in v)
    assert t_tour == tr.travel_ticks + len(counts) * (5 + T.READ_TICKS)
    t_plan, _, _ = ticks(np.arange(len(counts)))
    t_rand, _, _ = ticks(np.random.default_rng(0).permutation(len(counts)))
    # the design's order is the D-optimal selection's, as arbitrary as a random one
    assert t_tour < 0.5 * min(t_plan, t_rand), (t_tour, t_plan, t_rand)
    # plan orders its poses the same way and reports both robot times (ticks x 10 ms)
    ordered = plan(scene, 30, 200, 1, None, world)
    assert np.array_equal(np.array(ordered["counts"]), counts[tr.order])
    rt = ordered["robot_time_s"]
    assert rt["planned"] == pytest.approx(t_tour * 0.01)
    assert rt["planned_unordered"] == pytest.approx(t_plan * 0.01)
    assert rt == {**res["robot_time_s"], "planned": rt["planned"]}


def test_order_errors():
    with pytest.raises(ValueError, match="blocked must be"):
        T.order(np.zeros((2, 6)), np.zeros(6), blocked="nope", nominal=50)
    with pytest.raises(ValueError, match="needs the scene"):
        T.order(np.zeros((2, 6)), np.zeros(6), checker=object(), nominal=50)


def test_clock_counts_the_driven_ticks_and_estimates_them_at_rest(cell, tmp_path):
    """The noisy twin (laser noise, repeatability, the servo's lag: reads of 100 to
    several hundred ticks). Driving the ticks (``DriveAcquirer``) under a ``Clock``: its
    count is exactly the driver's. Setting the twin at rest instead (``RestAcquirer``, the
    Monte Carlo's twin mode), same seed, same plans: the reads differ a little (no settling
    after a move), here by 111 of 43486 ticks; within 1 %."""
    from planecal.links.base import AlwaysEnabled
    from planecal.sampling.collect import (Cursor, DriveAcquirer, MemoryRecorder,
                                           RestAcquirer, Tally, collect)
    from planecal.sampling.driver import Driver
    from planecal.sampling.planner import Planner
    from planecal.sampling.run import RunSettings
    from planecal.twin import Twin
    from planecal.twin.truth import draw_truth

    scene, world = cell
    truth = draw_truth(scene, 0)
    rs = RunSettings.for_scene(scene, samples=30, seed=1000)

    def run(make_acquirer):
        twin = Twin(scene, truth=truth, seed=rs.seed)
        start = twin.current_counts.copy()
        clock = T.Clock(make_acquirer(twin), start, rs.nominal_step_counts)
        tally = Tally()
        collect(Planner(scene, rs.pose, world), clock, MemoryRecorder(), rs.samples,
                Cursor(counts_to_joints(scene.robot, start),
                       np.random.default_rng(rs.seed).bit_generator.state), tally,
                rs.max_attempts)
        assert tally.status == "complete"
        return clock, tally, twin

    drv = None

    def drive(twin):
        nonlocal drv
        drv = Driver(twin, twin, AlwaysEnabled(), scene.robot)
        drv.start()  # one tick: the first exchange
        return DriveAcquirer(drv, rs.laser, rs.nominal_step_counts, rs.dwell_ticks)

    driven, t_drive, twin = run(drive)
    assert driven.ticks + 1 == drv.ticks == twin.ticks
    assert driven.read_ticks > 100 * rs.samples  # the reads are not all the minimum
    rest, t_rest, _ = run(lambda tw: RestAcquirer(tw, rs.laser))
    assert t_rest.rejected == t_drive.rejected
    assert abs(rest.ticks - driven.ticks) < 0.01 * driven.ticks
