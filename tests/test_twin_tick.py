"""The twin's tick, written once (``planecal.twin.ticks``): the compiled tick equals the
same source run by the interpreter bit for bit; ``run`` equals ``exchange`` + ``read``
per tick bit for bit; the beams equal MuJoCo's own ``mj_ray`` at the twin's joint state;
and the default twin equals the twin before the tick was rewritten (a golden record)."""
import os

os.environ.setdefault("MUJOCO_GL", "disable")

from dataclasses import replace  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import planecal.twin.core as core  # noqa: E402
from planecal.twin import EncoderJumpError, Twin, TwinOptions  # noqa: E402
from planecal.twin import ticks as T  # noqa: E402
from planecal.twin.beam import BeamCaster  # noqa: E402
from planecal.twin.laser import seen_mask  # noqa: E402

SCENES = ["thesis_final", "appendix_d", "three_plates"]
GOLDEN = os.path.join(os.path.dirname(__file__), "data", "twin_ideal_golden.npz")


def ramp(start, target, step=50):
    rows, d = [], start.copy()
    while not np.array_equal(d, target):
        d = d + np.clip(target - d, -step, step)
        rows.append(d)
    return np.array(rows, np.int64).reshape(-1, 6)


def no_hit_counts(twin):
    """Counts near home where the beam hits nothing (points into empty space)."""
    probe = Twin(twin.scene, truth=twin.truth, options=TwinOptions.exact())
    home, gains = twin.robot.home_counts, twin.robot.gains
    for j5 in (0.0, 1.2, -1.2, 2.4, -2.4):
        for j4 in (0.0, 1.5, -1.5):
            c = home + np.rint(gains * [0, 0, 0, j4, j5, 0]).astype(np.int64)
            probe.set_counts(c)
            if probe.hit().geom == -1:
                return c
    raise AssertionError("no pose without a hit")


def segments(twin, rng, n_poses, spread=2500):
    """A sampler's segments: ramps to random poses around the start and holds, then a
    ramp out to a pose where the beam hits nothing, and back."""
    base = twin.current_counts - twin.reference_counts
    segs, d = [], base
    for _ in range(n_poses):
        target = base + rng.integers(-spread, spread, 6)
        segs += [ramp(d, target), np.repeat(target[None], 30, axis=0)]
        d = target
    away = no_hit_counts(twin) - twin.reference_counts
    segs += [ramp(d, away, 60), np.repeat(away[None], 20, axis=0), ramp(away, base, 60)]
    return segs


class MjRay:
    """The independent peer: MuJoCo's own mj_kinematics + mj_ray from the laser site,
    in the world frame, at a joint state."""

    def __init__(self, twin):
        self.m, self.d = twin.model, mujoco.MjData(twin.model)
        self.site, self.tool = twin.laser_site, twin.tool_body
        self.geomid = np.zeros(1, np.int32)

    def __call__(self, qpos):
        self.d.qpos[:] = qpos
        mujoco.mj_kinematics(self.m, self.d)
        z = self.d.site_xmat[self.site].reshape(3, 3)[:, 2].copy()
        dist = mujoco.mj_ray(self.m, self.d, self.d.site_xpos[self.site], z, seen_mask(), 1,
                             self.tool, self.geomid)
        return dist, int(self.geomid[0]) if dist >= 0 else -1


def state(t):
    return (t._S.copy(), t._F.copy(), t._laser.left, t._rng_eps.bit_generator.state,
            t._rng_u.bit_generator.state, t._laser.rng.bit_generator.state, t._dist, t._geom,
            t._beam_stale)


def same_state(a, b):
    sa, sb = state(a), state(b)
    return all(np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y
               for x, y in zip(sa, sb))


ERRORS = TwinOptions(stiffness_nm_per_rad=(3e6, 2e6), backlash_rad=(2e-4,) * 6)


def with_all_errors(opts):
    """The options with every joint error on (gear harmonics and quantisation too)."""
    gear = tuple(g for j in range(1, 7) for g in ((j, 2e-5, 1.0), (j, 5e-6, 37.0)))
    return replace(opts, quantization=True, gear=gear, payload=(2.0, (0.0, 0.0, 0.1)))


@pytest.mark.parametrize("name,opts", [
    ("thesis_final", TwinOptions()), ("three_plates", TwinOptions(servo="ideal")),
    ("appendix_d", TwinOptions(laser_quantum_mm=0.001, repeatability_mm=0.3)),
    ("thesis_final", ERRORS), ("three_plates", with_all_errors(ERRORS)),
    ("thesis_final", TwinOptions(laser_noise_mm=0.05, check_steps=False))])
def test_compiled_tick_equals_interpreted_bit_for_bit(name, opts):
    # one source, two executions: random segments of random sizes through run (reading
    # or not), exchange/read and set_counts, a trip at the end: identical state throughout
    a = Twin(name, seed=6, options=opts)
    b = Twin(name, seed=6, options=opts, reference_ticks=True)
    assert a._t.compiled and not b._t.compiled
    rng = np.random.default_rng(len(name))
    D = np.vstack(segments(a, rng, 4))
    i = calls = 0
    while i < len(D):
        size = int(rng.choice([1, 2, 3, int(rng.integers(4, 60)), int(rng.integers(60, 200))]))
        rows = D[i:i + size]
        i += len(rows)
        calls += 1
        if calls % 5 == 0:  # one tick through exchange/read on both
            assert np.array_equal(a.exchange(rows[0])[1], b.exchange(rows[0])[1])
            assert a.read() == b.read()
            rows = rows[1:]
        read = calls % 3 != 0
        ra, ca, ma = a.run(rows, read=read)
        rb, cb, mb = b.run(rows, read=read)
        assert np.array_equal(ra, rb) and np.array_equal(ca, cb)
        assert np.array_equal(ma, mb, equal_nan=True) and same_state(a, b)
        if calls % 7 == 0:
            c = a.commanded_counts
            a.set_counts(c)
            b.set_counts(c)
            assert same_state(a, b)
    assert a.ticks == b.ticks == len(D) and np.array_equal(a.qpos, b.qpos)
    assert a.hit() == b.hit()
    if opts.check_steps:
        jump = np.repeat(D[-1:], 6, axis=0)
        jump[4:] += 100
        for t in (a, b):
            with pytest.raises(EncoderJumpError, match="at row 4"):
                t.run(jump)
        assert a.ticks == b.ticks and same_state(a, b)


@pytest.mark.parametrize("name", SCENES)
def test_run_equals_exchange_read_and_mujoco_ray(name):
    # default options (lag servo, noise, repeatability): run() per segment against
    # exchange + read per tick, bit for bit; with the noise off, every reading against
    # MuJoCo's own mj_ray at the twin's joint state
    a, b = Twin(name, seed=5), Twin(name, seed=5)
    segs = segments(a, np.random.default_rng(7), 12)
    for seg in segs:
        ra, ca, ma = a.run(seg)
        cb, mb = [], []
        for d in seg:
            cb.append(b.exchange(d)[1])
            r = b.read()
            mb.append(np.nan if r is None else r)
        assert np.array_equal(ca, np.array(cb)) and np.array_equal(ma, np.array(mb), equal_nan=True)
        assert same_state(a, b) and a.hit() == b.hit()
    exact = Twin(name, seed=5, options=TwinOptions.exact(servo="lag"))
    ray = MjRay(exact)
    hits = misses = 0
    for seg in segs:  # at the end of each segment: the twin's beam against the peer's
        exact.run(seg, read=False)
        dist, geom = ray(exact.qpos)
        h = exact.hit()
        assert h.geom == geom
        if dist >= 0:
            assert abs(h.distance_m - dist) < 1e-12
            hits += 1
        else:
            assert h.distance_m is None
            misses += 1
    assert hits > 5 and misses >= 1
    # tick by tick over one segment: each reading = 1000 x the peer's distance (window)
    t = Twin(name, seed=5, options=TwinOptions.exact(servo="lag"))
    lo, hi = t.scene.laser_range_mm
    checked = 0
    for d in np.vstack(segs[:4]):
        t.exchange(d)
        r = t.read()
        dist, _ = ray(t.qpos)
        want = dist * 1000 if dist >= 0 and lo <= dist * 1000 <= hi else None
        assert (r is None) == (want is None)
        if r is not None:
            assert abs(r - want) < 1e-9
            checked += 1
    assert checked > 50


def test_default_twin_equals_the_twin_before_the_rewrite():
    # tests/data/twin_ideal_golden.npz: the per-tick twin (exchange + read) of 2026-11-21
    # on four scene/option sets: counts equal, readings to 1e-9 mm (the beams are now
    # intersected in the laser's frame: ~1e-12 mm)
    g = np.load(GOLDEN)
    cases = {"thesis_final_": ("thesis_final", {}), "three_plates_": ("three_plates", {}),
             "appendix_d_servo-ideal": ("appendix_d", {"servo": "ideal"}),
             "thesis_final_laser_quantum_mm-0.001_repeatability_mm-0.2":
                 ("thesis_final", {"laser_quantum_mm": 0.001, "repeatability_mm": 0.2})}
    assert sorted(cases) == sorted({k.split("/")[0] for k in g.files})
    for key, (name, opts) in cases.items():
        for by_run in (False, True):
            tw = Twin(name, seed=5, options=TwinOptions(**opts))
            D = g[key + "/deltas"].astype(np.int64)
            at = int(g[key + "/set_at"][0])
            if by_run:
                _, c1, m1 = tw.run(D[:at])
                tw.set_counts(g[key + "/set_counts"])
                _, c2, m2 = tw.run(D[at:])
                cur, mm = np.vstack([c1, c2]), np.concatenate([m1, m2])
            else:
                cur, mm = np.empty_like(D), np.empty(len(D))
                for i, row in enumerate(D):
                    if i == at:
                        tw.set_counts(g[key + "/set_counts"])
                    cur[i] = tw.exchange(row)[1]
                    r = tw.read()
                    mm[i] = np.nan if r is None else r
            want = g[key + "/counts"].astype(np.int64) + tw.reference_counts
            assert np.array_equal(cur, want)
            assert np.array_equal(np.isnan(mm), np.isnan(g[key + "/mm"]))
            assert np.nanmax(np.abs(mm - g[key + "/mm"])) < 1e-9


def test_reads_skipped_leave_the_noise_stream_alone():
    # a move without reading draws no laser noise: the next reading is the one a twin
    # that was never moved... along another path would give, tick for tick
    a, b = Twin("thesis_final", seed=2), Twin("thesis_final", seed=2)
    base = a.current_counts - a.reference_counts
    D = ramp(base, base + [200, -150, 100, 0, 50, 0])
    a.run(D, read=False)
    for d in D:
        b.exchange(d)
    assert a._laser.left == b._laser.left == 0  # no block drawn yet
    hold = np.repeat(D[-1:], 40, axis=0)
    _, _, ma = a.run(hold)
    mb = [b.exchange(d) and b.read() for d in hold]
    assert np.array_equal(ma, np.array([np.nan if x is None else x for x in mb]), equal_nan=True)


@pytest.mark.parametrize("opts", [TwinOptions(), with_all_errors(ERRORS)])
def test_a_move_without_reads_ends_where_one_with_reads_does(opts):
    # a move that reads no laser computes the joint row of its last state only: the state
    # it leaves (counts, servo, rest draws, the joint row in qpos and in MuJoCo's data)
    # and the beam's hit are those of the same move read tick by tick (the readings
    # differ: each reading draws laser noise)
    a, b = Twin("thesis_final", seed=3, options=opts), Twin("thesis_final", seed=3, options=opts)
    rng = np.random.default_rng(3)
    for seg in segments(a, rng, 5):
        a.run(seg, read=False)
        b.run(seg, read=True)
        assert np.array_equal(a.qpos, b.qpos)
        assert np.array_equal(a.data.site_xpos, b.data.site_xpos)
        assert np.array_equal(a._S[:T.DIRTY], b._S[:T.DIRTY]) and np.array_equal(a._F, b._F)
        assert a.hit() == b.hit()
    assert a.ticks == b.ticks


def test_beam_caster_sees_only_the_static_cell():
    for name in SCENES:
        twin = Twin(name, seed=1)
        m, mask = twin.model, seen_mask()
        seen = [g for g in range(m.ngeom) if mask[m.geom_group[g]]]
        assert seen and all(m.geom_bodyid[g] in (0, twin.tool_body) for g in seen)
        beam = BeamCaster(m, twin.laser_site, mask, twin.tool_body)
        assert beam.geoms == [g for g in seen if m.geom_bodyid[g] == 0]
        assert beam.model.ngeom == len(beam.geoms) and beam.model.nq == m.nq


def test_beam_caster_long_runs_in_chunks(monkeypatch):
    import planecal.twin.beam as beam_mod
    twin = Twin("thesis_final", seed=1)
    beam = BeamCaster(twin.model, twin.laser_site, seen_mask(), twin.tool_body)
    rng = np.random.default_rng(2)
    Q = np.array(twin.qpos) + rng.normal(0, 0.02, (50, 6))
    want = [a.copy() for a in beam.cast(Q)]
    monkeypatch.setattr(beam_mod, "MAX_CHUNK", 16)
    got = beam.cast(Q)
    assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1])
    assert (want[0] > 0).any()
    ray = MjRay(twin)
    for q, d, g in zip(Q, *want):
        dist, geom = ray(q)
        assert geom == g and (dist < 0) == (d < 0) and (d < 0 or abs(dist - d) < 1e-12)


def test_run_refills_random_blocks_mid_call():
    # one call of 9,000 ticks with 150 rests: the perturbation and quantisation blocks
    # (64 draws) and the laser-noise block (4,096) run out inside the call; the tick
    # stops, the twin draws the next block and the tick goes on, as one tick at a time
    opts = with_all_errors(TwinOptions(servo="ideal"))
    a, b = Twin("thesis_final", seed=4, options=opts), Twin("thesis_final", seed=4, options=opts)
    base = a.current_counts - a.reference_counts
    step = np.array([0, 0, 0, 0, 20, 0], np.int64)
    D = np.vstack([np.repeat((base + (i % 2) * step)[None], 60, axis=0) for i in range(1, 151)])
    _, ca, ma = a.run(D)
    mb = []
    for d in D:
        b.exchange(d)
        r = b.read()
        mb.append(np.nan if r is None else r)
    assert np.array_equal(ma, np.array(mb), equal_nan=True) and same_state(a, b)
    assert (~np.isnan(ma)).sum() > 4096  # the noise block refilled at least once
    assert a._S[T.EPS_NEXT] == a._S[T.U_NEXT] == 150 % 64 + 1  # 151 rests: 3 blocks


def test_next_block_drawn_only_at_a_rest():
    # the perturbation block used up, then a call that only moves: no rest, no draw, the
    # generator untouched; the next rest draws the next block
    opts = TwinOptions(servo="ideal")
    a = Twin("thesis_final", seed=1, options=opts)
    while a._S[T.EPS_NEXT] < len(a._eps_block):
        a.set_counts(a.current_counts)
    base = a.current_counts - a.reference_counts
    D = base + np.cumsum(np.tile([0, 5, 0, 0, 0, 0], (10, 1)), axis=0)
    before = a._rng_eps.bit_generator.state
    a.run(D)
    assert a._rng_eps.bit_generator.state == before
    a.run(np.repeat(D[-1:], 3, axis=0))
    assert a._rng_eps.bit_generator.state != before and a._S[T.EPS_NEXT] == 1


def test_without_numba_the_twin_warns_and_runs_the_reference(monkeypatch):
    def no_numba():
        raise ImportError("numba is not installed")
    monkeypatch.setattr(core, "_COMPILED", [])
    monkeypatch.setattr(T, "compiled", no_numba)
    with pytest.warns(RuntimeWarning, match="compiled tick is not available"):
        a = Twin("thesis_final", seed=3)
    assert not a._t.compiled
    b = Twin("thesis_final", seed=3, reference_ticks=True)
    D = np.vstack(segments(a, np.random.default_rng(2), 1))
    _, ca, ma = a.run(D)
    _, cb, mb = b.run(D)
    assert np.array_equal(ca, cb) and np.array_equal(ma, mb, equal_nan=True)
