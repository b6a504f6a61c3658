"""Twin.run's batch path (``beam.BeamCaster``: all moving ticks' beams in one MuJoCo call)
equals the per-tick MuJoCo path (one mj_kinematics + mj_ray per moving tick)."""
import os

os.environ.setdefault("MUJOCO_GL", "disable")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from planecal.twin import EncoderJumpError, Twin, TwinOptions  # noqa: E402
from planecal.twin.beam import BeamCaster  # noqa: E402

SCENES = ["thesis_final", "appendix_d", "three_plates"]
pytest.importorskip("mujoco.batch")


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


def segments(twin, rng, n_poses):
    """A sampler's segments: ramps to random poses around the start and holds, then a
    ramp out to a pose where the beam hits nothing, and back."""
    base = twin.current_counts - twin.reference_counts
    segs, d = [], base
    for _ in range(n_poses):
        target = base + rng.integers(-2500, 2500, 6)
        segs += [ramp(d, target), np.repeat(target[None], 30, axis=0)]
        d = target
    away = no_hit_counts(twin) - twin.reference_counts
    segs += [ramp(d, away, 60), np.repeat(away[None], 20, axis=0), ramp(away, base, 60)]
    return segs


@pytest.mark.parametrize("name", SCENES)
def test_batch_path_equals_per_tick_mujoco(name):
    a, b = Twin(name, seed=5), Twin(name, seed=5)  # default options: lag, noise, repeatability
    b.batch_rays = False
    segs = segments(a, np.random.default_rng(7), 25)
    moving = hits = misses = 0
    geoms = set()
    for seg in segs:
        ra, ca, ma = a.run(seg)
        rb, cb, mb = b.run(seg)
        assert np.array_equal(ra, rb) and np.array_equal(ca, cb)
        assert np.array_equal(np.isnan(ma), np.isnan(mb))
        if not np.all(np.isnan(ma)):
            assert np.nanmax(np.abs(ma - mb)) < 1e-9
        moving += int(np.any(np.diff(np.vstack([ca[:1], ca]), axis=0) != 0, axis=1).sum())
        ha, hb = a.hit(), b.hit()
        assert ha.geom == hb.geom and ha.plate == hb.plate
        assert (ha.distance_m is None) == (hb.distance_m is None)
        if ha.distance_m is not None:
            assert abs(ha.distance_m - hb.distance_m) < 1e-12
            hits += 1
        else:
            misses += 1
        geoms.add(ha.geom)
        # MjData follows the batch path lazily: same joints and poses as the loop's
        assert np.abs(a.qpos - b.qpos).max() < 1e-15
        assert np.abs(a.sensor_pose() - b.sensor_pose()).max() < 1e-12
    assert isinstance(a._beam, BeamCaster) and b._beam is None
    assert moving > 2000 and hits > 10 and misses >= 1 and -1 in geoms
    assert a.ticks == b.ticks and a.read() == pytest.approx(b.read(), abs=1e-9)


@pytest.mark.parametrize("opts", [dict(servo="lag"), dict(servo="ideal"),
                                  dict(servo="ideal", laser_noise_mm=0.002,
                                       laser_quantum_mm=0.001, check_steps=False)])
def test_batch_path_exact_twin_out_of_window(opts):
    # noise and repeatability off (or noise with quantisation): a ramp along the beam
    # leaves the 65-95 mm window on both sides
    a = Twin("thesis_final", seed=2, options=TwinOptions.exact(**opts))
    b = Twin("thesis_final", seed=2, options=TwinOptions.exact(**opts))
    b.batch_rays = False
    base = a.current_counts - a.reference_counts
    step = np.array([0, 6, -9, 0, 3, 0], np.int64)
    D = base + np.cumsum(np.vstack([np.tile(step, (300, 1)), np.tile(-step, (600, 1))]), axis=0)
    _, ca, ma = a.run(D)
    _, cb, mb = b.run(D)
    assert np.array_equal(ca, cb) and np.array_equal(np.isnan(ma), np.isnan(mb))
    assert np.isnan(ma).sum() > 50 and (~np.isnan(ma)).sum() > 50
    assert np.nanmax(np.abs(ma - mb)) < 1e-9


def test_beam_caster_sees_only_the_static_cell():
    # the twin's ray sees only world-body geoms (the tool is excluded): the mask keeps
    # no robot link geom, so the caster (which has no robot) casts against the same set
    for name in SCENES:
        twin = Twin(name, seed=1)
        m, mask = twin.model, twin._ray.mask
        seen = [g for g in range(m.ngeom) if mask[m.geom_group[g]]]
        assert seen and all(m.geom_bodyid[g] in (0, twin.tool_body) for g in seen)
        beam = BeamCaster(m, twin.laser_site, mask, twin.tool_body)
        assert beam.geoms == [g for g in seen if m.geom_bodyid[g] == 0]
        assert beam.model.ngeom == len(beam.geoms) and beam.model.nq == m.nq
        # robot geoms moved anywhere: the twin's mj_ray doesn't change
        d = mujoco.MjData(m)
        d.qpos[:] = twin.qpos
        mujoco.mj_kinematics(m, d)
        ray = twin._ray.__class__(m, d, twin.laser_site, twin.tool_body)
        want = ray.cast()
        robot = m.geom_bodyid != 0
        d.geom_xpos[robot] = ray._pnt + 0.05 * ray._mat.reshape(3, 3)[:, 2]
        assert ray.cast() == want


def test_batch_path_falls_back_without_caster(monkeypatch):
    monkeypatch.setattr(BeamCaster, "build", classmethod(lambda cls, *a: None))
    a, b = Twin("thesis_final", seed=3), Twin("thesis_final", seed=3)
    b.batch_rays = False
    D = segments(a, np.random.default_rng(1), 2)
    for seg in D:
        _, ca, ma = a.run(seg)
        _, cb, mb = b.run(seg)
        assert np.array_equal(ca, cb) and np.array_equal(ma, mb, equal_nan=True)
    assert a._beam is False


def test_batch_runs_of_any_size_mixed_with_single_ticks():
    # run calls of 1..40 rows, single exchange/read ticks and a set_counts in between:
    # the state carried across calls (last beam, dirty kinematics, rest, perturbation)
    # keeps the batch twin on the per-tick twin
    a, b = Twin("three_plates", seed=9), Twin("three_plates", seed=9)
    rng = np.random.default_rng(4)
    D = np.vstack(segments(a, rng, 6))
    i = 0
    while i < len(D):
        size = int(rng.integers(1, 41))
        rows = D[i:i + size]
        i += len(rows)
        if size % 7 == 0:  # tick by tick on both
            for d in rows:
                assert np.array_equal(a.exchange(d)[1], b.exchange(d)[1])
                ra, rb = a.read(), b.read()
                assert (ra is None) == (rb is None) and (ra is None or abs(ra - rb) < 1e-9)
            continue
        _, ca, ma = a.run(rows)
        cb, mb = [], []
        for d in rows:
            cb.append(b.exchange(d)[1])
            r = b.read()
            mb.append(np.nan if r is None else r)
        assert np.array_equal(ca, np.array(cb)) and np.array_equal(np.isnan(ma), np.isnan(mb))
        if not np.all(np.isnan(ma)):
            assert np.nanmax(np.abs(ma - np.array(mb))) < 1e-9
        if size == 13:  # jump onto the command, at rest (both)
            c = a.commanded_counts
            a.set_counts(c)
            b.set_counts(c)
    assert a.ticks == b.ticks == len(D) and isinstance(a._beam, BeamCaster)
    assert a.hit().geom == b.hit().geom


def test_beam_caster_long_runs_in_chunks(monkeypatch):
    import planecal.twin.beam as beam_mod
    twin = Twin("thesis_final", seed=1)
    beam = BeamCaster(twin.model, twin.laser_site, twin._ray.mask, twin.tool_body)
    rng = np.random.default_rng(2)
    Q = np.array(twin.qpos) + rng.normal(0, 0.02, (50, 6))
    want = beam.cast(Q)
    monkeypatch.setattr(beam_mod, "MAX_CHUNK", 16)
    got = beam.cast(Q)
    assert np.array_equal(want[0], got[0]) and np.array_equal(want[1], got[1])
    d, g = beam.cast(Q, last_geom_only=True)
    assert np.array_equal(d, want[0]) and g == want[1][-1]
    assert (want[0] > 0).any()


@pytest.mark.parametrize("name,opts", [
    ("thesis_final", {}), ("three_plates", {}), ("appendix_d", {}),
    ("thesis_final", dict(servo="ideal")), ("three_plates", dict(laser_noise_mm=0.0)),
    ("thesis_final", dict(laser_quantum_mm=0.001)), ("three_plates", dict(repeatability_mm=0.0)),
    ("thesis_final", dict(laser_noise_mm=0.05, servo="ideal", repeatability_mm=0.3))])
def test_run_fast_path_equals_reference_bit_for_bit(name, opts):
    # Twin.run's batch path (``_run_batch``: fewer numpy calls, laser window shortcuts,
    # perturbations drawn in blocks) against ``_run_ref`` (the general path with the same
    # caster) over random segments of random sizes: ramps, holds, single ticks, misses,
    # set_counts, exchange/read in between, and a trip at the end; identical results
    a = Twin(name, seed=6, options=TwinOptions(**opts))
    b = Twin(name, seed=6, options=TwinOptions(**opts))
    b.run = b._run_ref
    rng = np.random.default_rng(len(name) + len(opts))
    D = np.vstack(segments(a, rng, 8))
    D = np.vstack([D, np.repeat(D[-1:], 40, axis=0)])  # a long hold at the end
    i = calls = 0
    while i < len(D):
        size = int(rng.choice([1, 2, 3, int(rng.integers(4, 60)), int(rng.integers(60, 200))]))
        rows = D[i:i + size]
        i += len(rows)
        calls += 1
        if calls % 11 == 0:  # one tick through exchange/read on both
            for d in rows[:1]:
                assert np.array_equal(a.exchange(d)[1], b.exchange(d)[1])
                assert a.read() == b.read()
            rows = rows[1:]
        ra, ca, ma = a.run(rows)
        rb, cb, mb = b.run(rows)
        assert np.array_equal(ra, rb) and np.array_equal(ca, cb) and ca.dtype == cb.dtype
        assert ma.dtype == mb.dtype and np.array_equal(ma, mb, equal_nan=True)
        assert a._at_rest == b._at_rest and a._dist == b._dist and a._geom == b._geom
        assert np.array_equal(a._errors.eps, b._errors.eps)
        assert a._errors._next == b._errors._next and a._laser._left == b._laser._left
        assert a._errors.rng.bit_generator.state == b._errors.rng.bit_generator.state
        if calls % 17 == 0:  # jump onto the command, at rest (both)
            c = a.commanded_counts
            a.set_counts(c)
            b.set_counts(c)
    assert a.ticks == b.ticks == len(D) and isinstance(a._beam, BeamCaster)
    assert np.array_equal(a.qpos, b.qpos) and a.hit() == b.hit()
    jump = np.repeat(D[-1:], 6, axis=0)
    jump[4:] += 100
    with pytest.raises(EncoderJumpError) as ea:
        a.run(jump)
    with pytest.raises(EncoderJumpError) as eb:
        b.run(jump)
    assert str(ea.value) == str(eb.value) and a.ticks == b.ticks
    assert a.read() == b.read()


def test_run_fast_path_window_cases():
    # the laser's shortcuts (all readings in the window, all out, per reading) on a
    # ramp that walks the beam through the window and back, split into calls of all sizes
    for noise in (0.001, 0.0, 3.0):
        opts = TwinOptions(laser_noise_mm=noise)
        a, b = Twin("thesis_final", seed=2, options=opts), Twin("thesis_final", seed=2, options=opts)
        b.run = b._run_ref
        base = a.current_counts - a.reference_counts
        step = np.array([0, 6, -9, 0, 3, 0], np.int64)
        D = base + np.cumsum(np.vstack([np.tile(step, (300, 1)), np.zeros((50, 6), np.int64),
                                        np.tile(-step, (600, 1))]), axis=0)
        rng = np.random.default_rng(3)
        i, seen = 0, set()
        while i < len(D):
            rows = D[i:i + int(rng.integers(1, 80))]
            i += len(rows)
            _, ca, ma = a.run(rows)
            _, cb, mb = b.run(rows)
            assert np.array_equal(ca, cb) and np.array_equal(ma, mb, equal_nan=True)
            seen.add((bool(np.isnan(ma).all()), bool(np.isnan(ma).any())))
        assert seen >= {(True, True), (False, False), (False, True)}


def test_run_refills_random_blocks_mid_call():
    # one call of 9,000 ticks with 150 settles: the perturbation block (64 draws) and the
    # laser-noise block (4,096) both run out inside the call; the compiled loop stops,
    # the twin draws the next block and the loop goes on, with the reference's numbers
    a = Twin("thesis_final", seed=4, options=TwinOptions(servo="ideal"))
    b = Twin("thesis_final", seed=4, options=TwinOptions(servo="ideal"))
    b.run = b._run_ref
    base = a.current_counts - a.reference_counts
    step = np.array([0, 0, 0, 0, 20, 0], np.int64)
    D = np.vstack([np.repeat((base + (i % 2) * step)[None], 60, axis=0) for i in range(1, 151)])
    settles, draw = [], b._errors.on_settle
    b._errors.on_settle = lambda: (settles.append(1), draw())
    _, ca, ma = a.run(D)
    _, cb, mb = b.run(D)
    assert np.array_equal(ca, cb) and np.array_equal(ma, mb, equal_nan=True)
    assert np.array_equal(a._errors.eps, b._errors.eps) and a._errors._next == b._errors._next
    assert a._laser._left == b._laser._left
    assert (~np.isnan(ma)).sum() > 4096  # the noise block refilled at least once
    assert len(settles) == 150  # > 2 blocks of perturbations
    assert a._S is not None  # the compiled loop ran (numba is a dependency)


def test_run_without_the_compiled_loop_warns_and_takes_the_reference(monkeypatch):
    import sys

    import planecal.twin.core as core
    monkeypatch.setattr(core, "_TICKS", [])
    import planecal.twin
    monkeypatch.setitem(sys.modules, "planecal.twin.ticks", None)  # as if numba were missing
    monkeypatch.delattr(planecal.twin, "ticks", raising=False)
    a, b = Twin("thesis_final", seed=3), Twin("thesis_final", seed=3)
    b.run = b._run_ref
    D = np.vstack(segments(a, np.random.default_rng(2), 2))
    with pytest.warns(RuntimeWarning, match="compiled tick loop is not available"):
        _, ca, ma = a.run(D)
    _, cb, mb = b.run(D)
    assert np.array_equal(ca, cb) and np.array_equal(ma, mb, equal_nan=True)
    assert a._S is None


def test_run_draws_the_next_perturbation_block_only_at_a_settle():
    # the perturbation block used up, then a call that only moves: no settle, so no new
    # block drawn (the per-tick path draws at the settle that needs it), the generator
    # untouched; the next settle draws it in both
    opts = TwinOptions(servo="ideal")
    a, b = Twin("thesis_final", seed=1, options=opts), Twin("thesis_final", seed=1, options=opts)
    for t in (a, b):
        while t._errors._next < len(t._errors._eps_block):
            t.set_counts(t.current_counts)
    base = a.current_counts - a.reference_counts
    D = base + np.cumsum(np.tile([0, 5, 0, 0, 0, 0], (10, 1)), axis=0)
    state = a._errors.rng.bit_generator.state
    a.run(D)
    for d in D:
        b.exchange(d)
        b.read()
    assert a._errors.rng.bit_generator.state == state == b._errors.rng.bit_generator.state
    assert a._errors._next == b._errors._next == len(a._errors._eps_block)
    hold = np.repeat(D[-1:], 3, axis=0)  # comes to rest: the settle draws a block
    _, _, ma = a.run(hold)
    mb = []
    for d in hold:
        b.exchange(d)
        mb.append(b.read())
    assert a._errors._next == b._errors._next == 1
    assert np.array_equal(a._errors.eps, b._errors.eps)
    assert np.abs(ma - np.array(mb, float)).max() < 1e-9
