"""The run loop on a fake cell (ideal servo + analytic distance model): samples written and
flushed, the step limit kept, enable dropping mid-path stops the run with a valid file,
--resume continues to N without duplicates, rejections counted, home/calibration moves."""
import json

import numpy as np
import pytest
from full_disk import FullDisk
from test_sampling_fakes import Clear, DropAfter, FakeCell, NullChecker

from planecal.model.encoder import joints_to_counts
from planecal.links.base import AlwaysEnabled
from planecal.io.samples import read_samples
from planecal.sampling import (Driver, EnableDropped, FollowingMonitor, NullObserver,
                               PathBlocked,
                               PoseSettings, RunSettings, SamplingRun, load_sidecar,
                               move_home, move_to_calibration, sidecar_path)
from planecal.sampling.runfiles import count_samples
from planecal.model.scene import load_scene


@pytest.fixture(scope="module")
def scene():
    return load_scene("thesis_final")


def settings(n, seed=1, **pose):
    # a narrow roll range keeps the fake runs short; the loop does not care
    return RunSettings(scene="thesis_final", samples=n, seed=seed,
                       pose=PoseSettings(roll_deg=pose.pop("roll_deg", 30.0), **pose))


class Recorder(NullObserver):
    def __init__(self, out=None):
        self.out = out
        self.samples, self.rejects, self.paths = [], [], []
        self.ticks = 0
        self.lines_on_disk = []
        self.laser_ticks = 0

    def on_ticks(self, first_tick, deltas, reference, current, laser_mm):
        self.ticks = first_tick + len(deltas) - 1
        self.laser_ticks += int(np.isfinite(laser_mm).sum())

    def on_sample(self, index, qe, d_mm, plate):
        self.samples.append((index, qe.copy(), d_mm, plate))
        if self.out is not None:
            self.lines_on_disk.append(count_samples(self.out))

    def on_reject(self, q_target, reason):
        self.rejects.append(reason)

    def on_path(self, kind, q_start, q_goal, rows):
        self.paths.append((kind, self.ticks, len(rows)))


def run(scene, out, n, cell=None, enable=None, checker=None, observer=None, resume=False,
        st=None):
    cell = cell or FakeCell(scene)
    drv = Driver(cell, cell, enable or AlwaysEnabled(), scene.robot, observer)
    st = st or settings(n)
    r = SamplingRun(drv, scene, st, out, checker or NullChecker(), resume=resume)
    return r.run(), cell, drv


def test_samples_written_flushed_and_step_limit_kept(scene, tmp_path):
    out = tmp_path / "RUN.tsv"
    obs = Recorder(out)
    stats, cell, drv = run(scene, out, 8, observer=obs)
    assert stats.status == "complete" and stats.samples == 8
    # each sample was on disk (flushed) when on_sample fired
    assert obs.lines_on_disk == list(range(1, 9))
    s = read_samples(out)
    assert len(s) == 8 and s.n_zero == 0
    for (i, qe, d, plate), q_file, d_file in zip(obs.samples, s.qe, s.d_mm):
        assert np.array_equal(qe, q_file)
        assert d_file == pytest.approx(d, abs=1e-4)
        # the reading belongs to the counts recorded with it (ideal servo, no noise)
        assert d == pytest.approx(cell.true_mm(qe), abs=1e-9)
        assert 65 <= d <= 95
    # never more than 51 counts per joint per tick on the wire; the tracked max agrees
    assert cell.max_jump <= 51
    assert stats.max_step_counts == cell.max_jump
    # robot time is ticks x 10 ms; each sample waited exactly 100 laser reads (no noise)
    assert stats.ticks == len(cell.sent) and stats.robot_time_s == pytest.approx(stats.ticks * 0.01)
    assert obs.laser_ticks == 8 * 100
    side = load_sidecar(out)
    assert side["samples"] == 8 and side["status"] == "complete" and side["seed"] == 1
    assert side["settings"]["pose"]["cone_deg"] == 30.0
    assert side["rejected"] == {"collision": 0, "laser": 0, "unreachable": stats.rejected["unreachable"]}
    assert side["ticks"] == stats.ticks and side["wall_time_s"] > 0
    # each path ends with 5 identical dwell deltas before the laser is read
    sent = np.array(cell.sent)
    for kind, t0, n in obs.paths:
        assert np.all(sent[t0 + n - 5:t0 + n] == sent[t0 + n - 1])


def _probe_path_ticks(scene, tmp_path, n, seed=1):
    obs = Recorder()
    run(scene, tmp_path / "probe.tsv", n, observer=obs, st=settings(n, seed))
    return obs.paths


def test_enable_dropped_mid_path_sends_nothing_more_and_leaves_a_valid_file(scene, tmp_path):
    paths = _probe_path_ticks(scene, tmp_path, 5)
    kind, t0, n = paths[3]  # the 4th path: 3 samples are taken by then
    assert n > 40
    drop = t0 + n // 2  # mid-path
    out = tmp_path / "RUN.tsv"
    stats, cell, _ = run(scene, out, 5, enable=DropAfter(drop))
    assert len(cell.sent) == drop  # not one exchange after the drop
    assert stats.status == "stopped" and "dead-man" in stats.stop_reason
    # the last delta sent is mid-path (not at the target): the robot stopped on the way
    assert not np.array_equal(cell.sent[-1], cell.sent[-2])
    s = read_samples(out)
    assert len(s) == 3
    side = load_sidecar(out)
    assert side["samples"] == 3 and side["status"] == "stopped"


def test_resume_continues_to_n_without_duplicates(scene, tmp_path):
    paths = _probe_path_ticks(scene, tmp_path, 6)
    out = tmp_path / "RUN.tsv"
    _, t0, n = paths[2]
    stats1, cell1, _ = run(scene, out, 6, enable=DropAfter(t0 + n // 3))
    assert stats1.samples == 2 and stats1.status == "stopped"
    first = read_samples(out)
    # a run killed while writing leaves a partial line: it is cut off on resume
    with open(out, "a") as f:
        f.write("8388608\t83886")
    assert count_samples(out) == 2
    side = load_sidecar(out)
    st = RunSettings.from_sidecar(side)
    assert st.samples == 6 and st.seed == 1 and st.pose.roll_deg == 30.0
    # the robot starts from wherever it stopped (the fresh link's reference is there)
    cell2 = FakeCell(scene, start_counts=cell1.cur)
    stats2, cell2, _ = run(scene, out, 6, cell=cell2, resume=True, st=st)
    assert stats2.status == "complete" and stats2.samples == 6 and stats2.sessions == 2
    s = read_samples(out)
    assert len(s) == 6
    assert np.array_equal(s.qe[:2], first.qe) and np.array_equal(s.d_mm[:2], first.d_mm)
    assert len({tuple(r) for r in s.qe}) == 6
    assert out.read_text().count("q1\t") == 1  # one header
    assert stats2.ticks == stats1.ticks + len(cell2.sent)
    side = load_sidecar(out)
    assert side["samples"] == 6 and side["sessions"] == 2 and side["status"] == "complete"
    # the rng continued from the sidecar state: the new poses are not the first run's again
    for qe, d in zip(s.qe[2:], s.d_mm[2:]):
        assert d == pytest.approx(cell2.true_mm(qe), abs=1e-4)


def test_resume_of_a_complete_run_takes_no_sample(scene, tmp_path):
    out = tmp_path / "RUN.tsv"
    run(scene, out, 2)
    st = RunSettings.from_sidecar(load_sidecar(out))
    stats, cell, _ = run(scene, out, 2, resume=True, st=st)
    assert stats.samples == 2 and stats.status == "complete" and len(read_samples(out)) == 2
    assert len(cell.sent) == 1  # just the first exchange that learns the reference


class Picky:
    """Rejects every third configuration and every fourth path."""

    def __init__(self):
        self.nc = self.np = 0

    def check_config(self, q):
        self.nc += 1
        return Clear(ok=self.nc % 3 != 0, pair=("link6", "plate") if self.nc % 3 == 0 else None)

    def check_path(self, q0, q1):
        self.np += 1
        return Clear(ok=self.np % 4 != 0)


def test_rejections_are_counted_and_replaced(scene, tmp_path):
    out = tmp_path / "RUN.tsv"
    obs = Recorder()
    # a laser window narrower than the drawn distances: some poses read out of range
    cell = FakeCell(scene, window=(65.0, 80.0))
    checker = Picky()
    # nearest branch: one path check per pose (a wrist change adds detour legs)
    stats, cell, _ = run(scene, out, 10, cell=cell, checker=checker, observer=obs,
                         st=settings(10, ik_choice="nearest"))
    assert stats.samples == 10 and len(read_samples(out)) == 10
    r = stats.rejected
    assert r["collision"] == checker.nc // 3 + checker.np // 4 > 0
    assert r["laser"] > 0 and stats.laser_give_ups["out_of_range"] == r["laser"]
    assert len(obs.rejects) == sum(r.values())
    assert any("link6 - plate" in x for x in obs.rejects)
    assert any(x.startswith("laser: gave up: 400 out-of-range") for x in obs.rejects)
    assert load_sidecar(out)["rejected"] == r


def test_gives_up_when_every_pose_is_rejected(scene, tmp_path):
    class Wall:
        def check_config(self, q):
            return Clear()

        def check_path(self, q0, q1):
            return Clear(ok=False)

    out = tmp_path / "RUN.tsv"
    st = settings(3)
    st.max_attempts = 40
    stats, cell, _ = run(scene, out, 3, checker=Wall(), st=st)
    assert stats.status == "gave_up" and stats.samples == 0
    assert sum(stats.rejected.values()) == 40
    assert count_samples(out) == 0 and out.read_text().startswith("q1\t")
    assert len(cell.sent) == 1


def test_start_configuration_in_collision_stops_at_once(scene, tmp_path):
    class Stuck(NullChecker):
        def check_config(self, q):
            return Clear(ok=False, pair=("forearm", "flange"))

    out = tmp_path / "RUN.tsv"
    stats, cell, _ = run(scene, out, 3, checker=Stuck())
    assert stats.status == "gave_up" and "forearm - flange" in stats.stop_reason
    assert len(cell.sent) == 1 and count_samples(out) == 0
    assert load_sidecar(out)["status"] == "gave_up"


class Hashy:
    """Stateless (like CollisionWorld): rejects about a third of the configurations and of
    the paths, by a hash of the joint angles."""

    def check_config(self, q):
        return Clear(ok=int(abs(np.sum(q)) * 1e6) % 3 != 0)

    def check_path(self, q0, q1):
        return Clear(ok=int(abs(np.sum(q1 - q0)) * 1e6) % 3 != 1)


@pytest.mark.parametrize("two_plates", [False, True])
def test_background_planning_gives_the_same_run(scene, tmp_path, two_plates):
    """Planning the next pose in a forked process while the robot moves changes nothing:
    same samples, same rejections, same random state (also when a laser rejection
    invalidates a round-robin plate guess)."""
    sc = _two_plates(scene, tmp_path) if two_plates else scene
    results = []
    for bg in (False, True):
        out = tmp_path / f"RUN{bg}.tsv"
        cell = FakeCell(sc, window=(65.0, 82.0))  # some laser rejections
        obs = Recorder()
        drv = Driver(cell, cell, AlwaysEnabled(), sc.robot, obs)
        stats = SamplingRun(drv, sc, settings(8), out, Hashy(), background=bg).run()
        assert stats.status == "complete"
        results.append((out.read_text(), stats.rejected, obs.rejects,
                        load_sidecar(out)["rng_state"], len(cell.sent)))
    assert results[0][1]["laser"] > 0 and results[0][1]["collision"] > 0
    assert results[0] == results[1]


class Chain:
    """A pure planner that counts its plans: the target is q_start + 1 on every joint,
    the random state counts up; a budget below 2 rejects the draw (no target)."""
    pure = True

    def __init__(self, round_robin=False):
        self.calls, self.round_robin = [], round_robin

    def index_matters(self):
        return self.round_robin

    def plan(self, q_start, index, rng_state, budget, back=(), aim=None):
        from planecal.sampling.planner import Plan
        self.calls.append(index)
        out = Plan(index, q_start, [], {"n": rng_state["n"] + 1})
        if budget < 2:
            out.rejections.append(("collision", None, "budget"))
            out.reason = "gave up"
            return out
        out.q = np.asarray(q_start, float) + 1.0
        out.qe_goal = np.zeros(6, np.int64)
        return out


def test_the_background_planner_serves_plans_made_ahead_along_the_chain():
    """While the run moves, the planner makes the plans its next requests will ask for
    (``planner._Ahead``): each is served without planning again, and is the plan the
    request gives; a request off the chain (another index, new aiming shifts), or with a
    budget larger than the plan was made with, is planned anew and the chain restarts
    from it."""
    from planecal.sampling.aim import Shifts
    from planecal.sampling.planner import AHEAD, _Ahead, route_back

    def request(plan, index, budget=5, aim=None):  # what collect asks next (collect.collect)
        return (plan.q, index, plan.rng_after, budget, route_back(plan), aim)

    for round_robin in (False, True):
        chain = Chain(round_robin)
        ahead = _Ahead(chain)
        p = ahead.take((np.zeros(6), 0, {"n": 0}, 5, (), None))
        while ahead.wanted():
            ahead.plan_next()
        assert chain.calls == [0, 1, 2, 3, 4] and AHEAD == 4
        for k in range(1, 4):  # served from the plans made ahead
            p = ahead.take(request(p, k))
            assert np.array_equal(p.q, np.full(6, k + 1.0)) and p.rng_after == {"n": k + 1}
        assert len(chain.calls) == 5
        # a laser rejection: the run asks again for index 3 from where plan 3 left it
        p4 = ahead.take(request(p, 3))
        assert len(chain.calls) == (6 if round_robin else 5)
        assert np.array_equal(p4.q, np.full(6, 5.0)) and p4.index == (3 if round_robin else 4)
    # made with a budget below the request's: planned again with the request's budget
    chain = Chain()
    ahead = _Ahead(chain)
    p = ahead.take((np.zeros(6), 0, {"n": 0}, 3, (), None))
    ahead.plan_next()
    assert chain.calls == [0, 1]
    p = ahead.take(request(p, 1, budget=5))
    assert chain.calls == [0, 1, 1] and ahead.next[3] == 5
    # new aiming shifts after a reading (sampling.aim): off the chain, planned anew
    ahead.plan_next()
    shifts = Shifts(-0.01, (-0.01,))
    p = ahead.take(request(p, 2, aim=shifts))
    assert chain.calls == [0, 1, 1, 2, 2] and ahead.next[5] == shifts
    # a plan with no target ends the chain: nothing follows it to plan ahead
    p = ahead.take((np.zeros(6), 0, {"n": 0}, 1, (), None))
    assert p.q is None and not ahead.wanted()


class Targets:
    """A given planner: sample i goes to ``targets[i]`` (counts), straight; it keeps the
    way back (``back``) each request handed it."""
    pure = False

    def __init__(self, robot, targets):
        self.robot, self.targets = robot, targets
        self.backs = []

    def index_matters(self):
        return False

    def plan(self, q_start, index, rng_state, budget, back=(), aim=None):
        from planecal.model.encoder import counts_to_joints
        from planecal.sampling.planner import Plan
        self.backs.append(back)
        out = Plan(index, q_start, [], rng_state)
        out.qe_goal = self.targets[index]
        out.q = counts_to_joints(self.robot, out.qe_goal)
        return out


def _targets(scene, degrees):
    return [joints_to_counts(scene.robot, scene.calibration_q + dq) for dq in np.deg2rad(degrees)]


def test_a_given_planner_supplies_the_targets(scene, tmp_path):
    """A pose list instead of random poses: the run visits exactly those counts."""
    targets = _targets(scene, [[0, 0, 0, 0, 2, 0], [1, -1, 1, 0, 0, 3], [0, 1, 0, 2, -2, 0]])
    out = tmp_path / "RUN.tsv"
    cell = FakeCell(scene)
    stats = SamplingRun(Driver(cell, cell, AlwaysEnabled(), scene.robot), scene, settings(3),
                        out, NullChecker(), planner=Targets(scene.robot, targets)).run()
    assert stats.status == "complete"
    assert np.array_equal(read_samples(out).qe, np.array(targets))


def test_a_resume_takes_the_way_back_only_where_the_robot_still_is(scene, tmp_path):
    """The way the robot came in (``Cursor.back``: where a detour may leave when nothing
    else is clear) travels in the sidecar; a resumed run hands it to its planner when the
    robot stands where it was recorded, and none when the robot was moved since."""
    targets = _targets(scene, [[0, 0, 0, 0, 2, 0], [1, -1, 1, 0, 0, 3], [0, 1, 0, 2, -2, 0],
                               [0, 0, 1, 0, 1, 0]])
    out = tmp_path / "RUN.tsv"
    cell = FakeCell(scene)
    first = Targets(scene.robot, targets)
    SamplingRun(Driver(cell, cell, AlwaysEnabled(), scene.robot), scene, settings(2), out,
                NullChecker(), planner=first).run()
    assert len(first.backs[0]) == 0 and len(first.backs[1]) == 1  # nothing before the first
    rb = load_sidecar(out)["route_back"]
    assert rb["from_counts"] == targets[1].tolist() and rb["counts"] == [targets[0].tolist()]
    for start, expect in ((targets[1], [targets[0]]), (targets[0], [])):
        copy = tmp_path / f"copy{len(expect)}.tsv"
        copy.write_bytes(out.read_bytes())
        sidecar_path(copy).write_text(sidecar_path(out).read_text())
        cell2, again = FakeCell(scene, start_counts=start), Targets(scene.robot, targets)
        SamplingRun(Driver(cell2, cell2, AlwaysEnabled(), scene.robot), scene, settings(3),
                    copy, NullChecker(), planner=again, resume=True).run()
        got = [joints_to_counts(scene.robot, q) for q in again.backs[0]]
        assert [list(c) for c in got] == [list(c) for c in expect]


def test_following_monitor_drops_enable_when_the_robot_stops_following(scene, tmp_path):
    class Brakes(FakeCell):
        """The dead-man switch is released after tick ``at``: the robot stands still."""

        def __init__(self, *a, at=0, **k):
            super().__init__(*a, **k)
            self.at = at

        def exchange(self, delta):
            frozen = self.cur.copy()
            ref, cur = super().exchange(delta)
            if len(self.sent) > self.at:
                self.cur = frozen
            return ref, self.cur.copy()

    paths = _probe_path_ticks(scene, tmp_path, 3)
    _, t0, n = paths[1]
    cell = Brakes(scene, at=t0 + 5)
    mon = FollowingMonitor(cell)  # limit 211 counts: 60 / (1 - exp(-10 ms / 30 ms))
    drv = Driver(mon, cell, mon, scene.robot)
    out = tmp_path / "RUN.tsv"
    stats = SamplingRun(drv, scene, settings(3), out, NullChecker()).run()
    assert stats.status == "stopped" and "dead-man" in stats.stop_reason
    assert stats.samples == 1 and len(read_samples(out)) == 1
    # the robot stands still from the brakes on; the command runs ahead 50 counts a tick
    # (an ideal servo: no lag before): 4 steps go out (gap 200; 200 + 51 > 211), no more
    assert len(cell.sent) - (t0 + 5) == 4
    assert 211 - 51 < mon.last_lag == mon.max_lag <= 4 * 50 and mon.limit_counts == 211


def test_following_monitor_tolerates_a_lagging_but_following_servo(scene, tmp_path):
    class Lagging(FakeCell):
        """Follows the command 3 ticks late (150 counts behind at full speed)."""

        def exchange(self, delta):
            ref, _ = super().exchange(delta)
            k = len(self.sent)
            self.cur = ref + self.sent[max(0, k - 4)]
            return ref, self.cur.copy()

    cell = Lagging(scene)
    mon = FollowingMonitor(cell)
    stats = SamplingRun(Driver(mon, cell, mon, scene.robot), scene, settings(3),
                        tmp_path / "RUN.tsv", NullChecker()).run()
    assert stats.status == "complete" and mon.enabled()


def test_driver_refuses_a_path_with_a_step_above_51(scene):
    cell = FakeCell(scene)
    drv = Driver(cell, cell, AlwaysEnabled(), scene.robot)
    drv.start()
    rows = np.array([[10, 0, 0, 0, 0, 0], [62, 0, 0, 0, 0, 0]], np.int64)
    with pytest.raises(ValueError, match="step of 52 counts"):
        drv.follow(rows)
    assert len(cell.sent) == 1  # only the first handshake tick
    drv.follow(rows[:1])
    assert drv.max_step_counts == 10


def test_driver_hands_whole_moves_to_a_move_link_and_ticks_otherwise(scene):
    # the twin takes a move in one call when the enable signal is known ahead; a link
    # that cannot (or an enable signal that is not) gets it tick by tick: same counts
    twin_mod = pytest.importorskip("planecal.twin")

    class Counting(twin_mod.Twin):
        calls = 0

        def run(self, deltas, read=True):
            self.calls += 1
            return super().run(deltas, read)

    class Plain:  # enabled(), nothing known ahead
        def enabled(self):
            return True

    rows = np.cumsum(np.tile([20, -10, 5, 0, 15, 0], (60, 1)), axis=0).astype(np.int64)
    got = []
    for enable in (AlwaysEnabled(), Plain()):
        twin = Counting(scene, seed=1)
        obs = Recorder()
        drv = Driver(twin, twin, enable, scene.robot, obs)
        drv.start()
        drv.follow(rows)
        got.append((twin.calls, drv.ticks, obs.ticks, drv.current.tolist(), twin.qpos.tolist()))
    assert got[0][0] == 2 and got[1][0] == 61  # start + one move / start + 60 ticks
    assert got[0][1:] == got[1][1:] and got[0][1] == 61


def test_enable_known_ahead_stops_a_handed_over_move_at_the_same_tick(scene):
    twin_mod = pytest.importorskip("planecal.twin")

    class Reserving(DropAfter):  # the same signal, known ahead
        def reserve(self, ticks):
            m = max(0, min(ticks, self.n - self.calls))
            self.calls += m
            return m

    rows = np.cumsum(np.tile([20, -10, 5, 0, 15, 0], (60, 1)), axis=0).astype(np.int64)
    seen = []
    for enable in (DropAfter(25), Reserving(25)):
        twin = twin_mod.Twin(scene, seed=1)
        drv = Driver(twin, twin, enable, scene.robot)
        drv.start()
        with pytest.raises(EnableDropped):
            drv.follow(rows)
        seen.append((twin.ticks, drv.ticks, drv.delta.tolist(), drv.max_step_counts))
    assert seen[0] == seen[1] and seen[0][0] == 25


def test_home_and_calibration_moves(scene, tmp_path):
    cell = FakeCell(scene)
    obs = Recorder()
    drv = Driver(cell, cell, AlwaysEnabled(), scene.robot, obs)
    n = move_home(drv, scene, NullChecker())
    assert np.array_equal(cell.cur, scene.home_counts)
    assert n == len(cell.sent) - 1
    move_to_calibration(drv, scene, NullChecker())
    assert np.array_equal(cell.cur, joints_to_counts(scene.robot, scene.calibration_q))
    assert [p[0] for p in obs.paths] == ["home", "calibration"]
    assert cell.max_jump <= 50 and drv.max_step_counts == cell.max_jump

    class Blocked(NullChecker):
        def check_path(self, q0, q1):
            return Clear(ok=False, pair=("link3", "stand"))

    with pytest.raises(PathBlocked, match="home: path not collision-free .link3 - stand."):
        move_home(drv, scene, Blocked())


def _two_plates(scene, tmp_path):
    raw = json.loads(scene.path.read_text())
    # a second plate beside the first, on a parallel plane 10 mm nearer
    # (the corner on that plane: the scene check allows 5 mm)
    p2 = dict(raw["plates"][0], name="plate2", corner_m=[0.729, 0.403046, 0.379224])
    n1 = np.array(raw["plates"][0]["n_tilde"])
    p2["n_tilde"] = list(n1 / (1 - 0.010 * np.linalg.norm(n1)))
    raw["plates"].append(p2)
    path = tmp_path / "two.json"
    path.write_text(json.dumps(raw))
    return load_scene(path)


def test_multi_plate_run_records_the_plate(scene, tmp_path):
    sc2 = _two_plates(scene, tmp_path)
    out = tmp_path / "RUN.tsv"
    obs = Recorder()
    st = settings(6)
    stats, cell, _ = run(sc2, out, 6, cell=FakeCell(sc2), observer=obs, st=st)
    assert stats.samples == 6
    s = read_samples(out)
    assert list(s.plate) == [0, 1, 0, 1, 0, 1] == [x[3] for x in obs.samples]
    assert load_sidecar(out)["plates"] == 2
    assert sidecar_path(out).name == "RUN.tsv.json"


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/status"),
                    reason="reads process states from /proc")
@pytest.mark.parametrize("plan_s", [0.5, 0.0])
def test_background_planner_ends_when_the_run_is_killed(tmp_path, plan_s):
    # the forked planner must not outlive its run: SIGKILL the run (no cleanup runs)
    # while it plans (0.5 s) or with its plan sent and unread (0 s): the planner sees the
    # pipe close or reset and exits quietly, instead of waiting for requests forever
    import os
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "run.py"
    script.write_text(
        "import sys, time\n"
        "from planecal.sampling.planner import BackgroundPlanner\n"
        "class P:\n"
        f"    def plan(self, *req): time.sleep({plan_s}); return req\n"
        "    def index_matters(self): return False\n"
        "bp = BackgroundPlanner(P())\n"
        "bp.submit(1, 2, 3)\n"
        "print(bp._proc.pid, flush=True)\n"
        "time.sleep(60)\n")
    run = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        child = int(run.stdout.readline())
        time.sleep(0.2)  # (0 s: the plan is back in the pipe by now)
        os.kill(run.pid, signal.SIGKILL)
        run.wait(timeout=10)

        def alive(pid):
            try:
                with open(f"/proc/{pid}/status") as f:
                    return "\nState:\tZ" not in f.read()  # a zombie has exited
            except FileNotFoundError:
                return False
        deadline = time.monotonic() + 20
        while alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        gone = not alive(child)
        if not gone:
            os.kill(child, signal.SIGKILL)
        assert gone, "the planner outlived its run"
        assert "Traceback" not in run.stderr.read()  # the planner held it until it exited
    finally:
        if run.poll() is None:
            run.kill()


def test_a_full_disk_stops_the_run_with_whole_lines_and_a_resumable_record(scene, tmp_path,
                                                                         monkeypatch):
    import planecal.io.samples as samples_mod
    from planecal.sampling.runfiles import RunWriteError

    out = tmp_path / "RUN.tsv"
    disk = FullDisk(left=250)  # the header and a few samples fit, then a line is cut
    disk.install(monkeypatch, samples_mod)  # and the sidecar's temp file
    with pytest.raises(RunWriteError, match="No space left on device.*continue with --resume"):
        run(scene, out, 8)
    monkeypatch.undo()
    text = out.read_text()
    assert text.endswith("\n")  # whole lines only: the cut line was taken back
    n = count_samples(out)
    assert 1 <= n < 8 and len(read_samples(out)) == n
    assert not list(tmp_path.glob("*.tmp"))  # no temp file left behind
    side = load_sidecar(out)
    assert side["samples"] in (n, n + 1)  # the sidecar is written just before each line
    # room again: the resumed run completes without a duplicate pose
    stats, _, _ = run(scene, out, 8, resume=True, st=settings(8))
    s = read_samples(out)
    assert stats.status == "complete" and len(s) == 8
    assert len({tuple(r) for r in s.qe}) == 8
