"""Laser read (seed 7.1.3): 100-reading buffer, spread < 0.005 mm, 400 out-of-range in a
row, bounded wait for a noisy sensor; one reading per tick."""
import itertools

import numpy as np
import pytest

from planecal.sampling.laserread import LaserSettings, read_stable


class Source:
    """``take(n)``: the next n readings of ``values`` (None: out of range) as the loop
    gets them, n ticks at a time; ``calls`` counts the readings taken (= ticks)."""

    def __init__(self, values):
        self.it = iter(values)
        self.calls = 0
        self.blocks = []

    def __call__(self, n):
        self.calls += n
        self.blocks.append(n)
        return np.array([np.nan if v is None else v for v in itertools.islice(self.it, n)])


def test_quiet_sensor_sample_after_exactly_100_reads_and_value_is_the_mean():
    rng = np.random.default_rng(0)
    vals = 80.0 + rng.uniform(-0.002, 0.002, 500)
    src = Source(vals)
    r = read_stable(src)
    assert r.ok and r.reason == "stable"
    assert r.reads == 100 == src.calls
    assert r.value_mm == pytest.approx(vals[:100].mean(), abs=1e-12)
    assert r.spread_mm < 0.005


def test_settling_sensor_waits_until_the_buffer_agrees():
    # the reading settles exponentially from 80.5 to 80.0 (time constant 20 ticks)
    k = np.arange(2000)
    vals = 80.0 + 0.5 * np.exp(-k / 20.0)
    src = Source(vals)
    r = read_stable(src)
    assert r.ok
    # first buffer whose spread is < 5 um: 0.5 e^{-(k-99)/20} (1 - e^{-99/20}) < 0.005
    first = next(i for i in range(99, 2000) if vals[i - 99] - vals[i] < 0.005)
    assert r.reads == first + 1
    assert r.value_mm == pytest.approx(vals[first - 99:first + 1].mean(), abs=1e-12)


def test_spread_is_strictly_below_the_limit():
    vals = itertools.cycle([80.0, 80.00501])
    r = read_stable(Source(vals), LaserSettings(max_reads=300))
    assert not r.ok and r.reason == "not_stable" and r.reads == 300


def test_400_out_of_range_in_a_row_gives_up():
    src = Source(itertools.chain([80.0] * 50, itertools.repeat(None)))
    r = read_stable(src)
    assert not r.ok and r.reason == "out_of_range"
    assert r.reads == 450 == src.calls and r.out_of_range == 400
    assert "400 out-of-range reads in a row" in r.describe()


def test_zero_reading_counts_as_out_of_range():
    r = read_stable(Source(itertools.repeat(0.0)))
    assert r.reason == "out_of_range" and r.reads == 400


def test_out_of_range_streak_is_broken_by_a_good_reading_and_not_stored():
    # 399 misses, one good, 399 misses, ... never 400 in a row: the buffer fills with the
    # good readings only and the sample is taken from them
    pattern = [None] * 399 + [80.001]
    src = Source(itertools.cycle(pattern))
    r = read_stable(src, LaserSettings(buffer_len=3, max_reads=5000))
    assert r.ok and r.value_mm == pytest.approx(80.001)
    assert r.reads == 1200 and r.out_of_range == 1197


def test_noisy_sensor_gives_up_after_the_bound():
    rng = np.random.default_rng(1)
    src = Source(80.0 + rng.normal(0, 0.01, 10_000))
    r = read_stable(src, LaserSettings(max_reads=1000))
    assert not r.ok and r.reason == "not_stable"
    assert src.calls == 1000
    assert r.spread_mm > 0.005
    assert "not stable within 1000 reads" in r.describe()


def test_stop_raised_by_the_tick_propagates():
    class Stop(Exception):
        pass

    def take(n):
        raise Stop()

    with pytest.raises(Stop):
        read_stable(take)


def test_blocks_take_exactly_the_readings_of_one_at_a_time():
    # the block sizes are lower bounds of what can be decided: over many sensors, the
    # readings (ticks) taken and the sample equal a reader that takes one at a time
    rng = np.random.default_rng(5)

    def one_at_a_time(vals, st):
        src = Source(vals)
        return read_stable(lambda n: np.concatenate([src(1) for _ in range(n)]), st), src

    for k in range(60):
        st = LaserSettings(buffer_len=int(rng.integers(2, 40)),
                           max_out_of_range=int(rng.integers(3, 60)), max_reads=600)
        base = 80 + rng.normal(0, rng.choice([0.0005, 0.002, 0.004]), 2000)
        settle = 0.05 * np.exp(-np.arange(2000) / rng.uniform(1, 30))
        vals = [None if rng.uniform() < rng.choice([0.0, 0.1, 0.6]) else v
                for v in base + settle]
        b, src_b = one_at_a_time(vals, st)
        src_a = Source(vals)
        a = read_stable(src_a, st)
        assert (a.value_mm, a.reason, a.reads, a.spread_mm, a.out_of_range) == \
            (b.value_mm, b.reason, b.reads, b.spread_mm, b.out_of_range)
        assert src_a.calls == src_b.calls == a.reads
        assert len(src_a.blocks) <= len(src_b.blocks)
