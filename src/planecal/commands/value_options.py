"""argparse types every command shares for the values it hands to the system and to numpy:
random seeds and network ports, checked when the command line is read (before any file,
socket or random stream is made), so a bad one is argparse's one line, exit 2::

    p.add_argument("--seed", type=seed, ...)
    p.add_argument("--rt-port", type=port, ...)
    p.add_argument("--reply-port", type=port_or_zero, ...)   # where 0 has a meaning
    p.add_argument("--truth-seeds", type=seed_list, ...)     # "0,1,2"

Counts (samples, runs, repeats, candidates, iterations, ...) take ``count(hi, lo)``: a
whole number in a stated range, so no option can ask for a run that never ends (the
bounds are in the README)::

    p.add_argument("--samples", type=count(MAX_SAMPLES), ...)
    p.add_argument("--jobs", type=jobs, ...)                  # 1 .. 4 x this machine's cores

A seed is a whole number 0 .. 2**63 - 1 (numpy's generators take any non-negative integer;
the bound keeps it a 64-bit integer in every file that records it). A port is 1 .. 65535
(0 only where the option gives 0 a meaning: any free port, the sender's own port).
"""
from __future__ import annotations

import argparse

from planecal.base.limits import (JOBS_PER_CORE, MAX_CANDIDATES, MAX_ITERATIONS,
                                  MAX_RUNS, MAX_SAMPLES, MAX_TRIES, SEED_MAX)

PORT_MAX = 65535
__all__ = ["JOBS_PER_CORE", "MAX_CANDIDATES", "MAX_ITERATIONS", "MAX_RUNS", "MAX_SAMPLES",
           "MAX_TRIES", "SEED_MAX", "bounded", "count", "host", "jobs", "max_jobs", "port", "port_or_zero",
           "seed", "seed_list"]


def _shown(text: str) -> str:
    text = str(text).strip()
    return text if len(text) <= 40 else text[:37] + "..."


def _whole(text: str, what: str) -> int:
    try:
        return int(str(text).strip(), 10)
    except ValueError:  # not a number, a fraction, 5000 digits
        raise argparse.ArgumentTypeError(f"{_shown(text)!r} is not {what}") from None


def seed(text: str) -> int:
    """argparse type: a random seed, 0 .. 2**63 - 1."""
    what = "a seed (a whole number from 0 to 2**63 - 1)"
    v = _whole(text, what)
    if not 0 <= v <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"{_shown(text)} is not {what}")
    return v


def seed_list(text: str) -> list[int]:
    """argparse type: distinct seeds, comma-separated (``0,1,2,3,4``)."""
    parts = [p for p in str(text).split(",") if p.strip()]
    if not parts:
        raise argparse.ArgumentTypeError(f"{text!r} holds no seeds (e.g. 0,1,2)")
    seeds = [seed(p) for p in parts]
    if len(set(seeds)) != len(seeds):
        twice = next(s for s in seeds if seeds.count(s) > 1)
        raise argparse.ArgumentTypeError(f"the seed {twice} is given twice")
    return seeds


def host(text: str) -> str:
    """argparse type: a host name or address; never empty (which a socket takes as every
    interface: give 0.0.0.0 for that)."""
    t = str(text).strip()
    if not t or any(c.isspace() or ord(c) < 32 for c in t) or len(t) > 253:
        raise argparse.ArgumentTypeError(f"{_shown(text)!r} is not a host name or address "
                                         "(0.0.0.0 binds every interface)")
    return t


def count(hi: int, lo: int = 1):
    """argparse type: a whole number ``lo`` .. ``hi`` (a count with a stated bound)."""
    def whole_count(text: str) -> int:
        what = f"a count ({lo} .. {hi:,})".replace(",", "_")
        v = _whole(text, what)
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{_shown(text)} is not {what}")
        return v
    return whole_count


def bounded(lo: float, hi: float, unit: str):
    """argparse type: a finite number in [lo, hi] (``nan``, ``inf``, 1e308 refused)."""
    def number(text: str) -> float:
        try:
            v = float(str(text).strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"{_shown(text)!r} is not a number") from None
        if not lo <= v <= hi:  # NaN fails this too
            raise argparse.ArgumentTypeError(f"{_shown(text)} is not a number in [{lo:g}, "
                                             f"{hi:g}] {unit}")
        return v
    return number


MINUTES = bounded(0.01, 100_000.0, "min")  # --robot-minutes: a budget of robot time


def max_jobs() -> int:
    import os
    return JOBS_PER_CORE * (os.cpu_count() or 1)


def jobs(text: str) -> int:
    """argparse type: worker processes, 1 .. 4 x this machine's cores."""
    return count(max_jobs())(text)


def _port(text: str, low: int) -> int:
    what = f"a port ({low} .. {PORT_MAX})"
    v = _whole(text, what)
    if not low <= v <= PORT_MAX:
        raise argparse.ArgumentTypeError(f"{_shown(text)} is not {what}")
    return v


def port(text: str) -> int:
    """argparse type: a UDP or TCP port, 1 .. 65535."""
    return _port(text, 1)


def port_or_zero(text: str) -> int:
    """argparse type: a port, or 0 where the option gives it a meaning (its help says)."""
    return _port(text, 0)
