"""``Twin.run``'s tick loop, compiled (numba): the FD11 semantics, the servo, the rest
logic and the laser model, tick by tick, with the same arithmetic in the same order as
``Twin.exchange`` + ``Twin.read``: the same counts, joint states and random streams, bit
for bit. Only the beams are cast outside, all of a call's in one MuJoCo call
(``beam.BeamCaster``, which intersects in the laser's frame: distances equal the per-tick
``mj_ray``'s to ~1e-15 m, readings to ~1e-12 mm; ``Twin._run_ref`` with the same caster
gives the same readings bit for bit).

One ``run`` call is three steps:

1. ``advance``: for each tick, command = reference + delta (stop at an encoder jump),
   the servo (ideal, or the first-order lag rounded to counts), at rest = the command
   holds and the counts are on it (coming to rest draws the next repeatability
   perturbation), and whenever the state changed (the counts moved, a perturbation was
   drawn, or it was stale at entry) the joint state ``qpos = q(counts) + delta_true +
   eps`` of that tick as a row of ``Q``; ``row_of[i]`` is the row tick i reads (-1: the
   state before the call).
2. the beams of the rows of ``Q`` (MuJoCo: kinematics + ``mj_ray`` per row);
3. ``laser``: each tick's reading from its row's distance: + noise, quantum, window.

Random streams: both steps use blocks drawn ahead by the twin (the repeatability
perturbations, ``JointErrors``; the laser noise, ``LaserModel``), in the order the
per-tick path uses them. When a draw finds its block used up, the step returns before
applying that tick; the caller draws the next block (as the per-tick path would, at the
same moment) and calls again from that tick (state is kept in the arrays).

The twin's state travels in two arrays, ``S`` (int64) and ``F`` (float64), laid out by the
indices below; ``Twin._run_batch`` fills them from the twin before a call and reads them
back after it. numba compiles both functions at the first ``run`` of a process (~1.3 s,
then cached next to this file: ~0.2 s to load).
"""
from __future__ import annotations

import numpy as np
from numba import njit

# S: int64 state
CUR = 0          # [0:6]  current counts
CMD = 6          # [6:12] last commanded counts
REF = 12         # [12:18] reference counts
QE0 = 18         # [18:24] nominal qe0 (encoder counts at q = 0)
AT_REST = 24     # 1: the robot was at rest after the last tick
DIRTY = 25       # 1: the state changed since the last beam (recompute at the next tick)
EPS_NEXT = 26    # next unused row of the perturbation block
TRIP = 27        # trip step (counts); < 0: no check
IDEAL = 28       # 1: ideal servo
SIGMA = 29       # 1: repeatability perturbations on
NS = 30
# F: float64 state
Y = 0            # [0:6] servo filter output (counts, float)
GAIN = 6         # servo gain g (y <- g u + (1 - g) y)
KEEP = 7         # 1 - g
EPS = 8          # [8:14] current perturbation (rad)
DELTA = 14       # [14:20] true joint offsets (rad)
M = 20           # [20:56] q = M (counts - qe0), row-major 6 x 6
NF = 56

# why a function returned (``stop[0]``; ``stop[1]`` = the tick it stopped at)
DONE, NEED_EPS, TRIPPED = 0, 1, 2


@njit(cache=True, nogil=True)
def advance(D, i0, S, F, eps_block, cur_out, row_of, Q, k0, stop):
    """Ticks ``i0..`` of ``D`` (n, 6) deltas. Writes the counts ``cur_out[i]``, the
    recomputed joint rows ``Q[k0..]`` and ``row_of[i]``; returns the number of rows of Q
    now used. ``stop[0]``: DONE, NEED_EPS (tick ``stop[1]`` comes to rest and the
    perturbation block is used up: draw the next, call again from that tick; nothing of
    it was applied) or TRIPPED (tick ``stop[1]`` jumps: not run)."""
    n = D.shape[0]
    k = k0
    trip = S[TRIP]
    g = F[GAIN]
    keep = F[KEEP]
    ideal = S[IDEAL] == 1
    sigma = S[SIGMA] == 1
    nblock = eps_block.shape[0]
    cmd = np.empty(6, np.int64)
    cnt = np.empty(6, np.int64)
    y = np.empty(6)
    for i in range(i0, n):
        # the tick computed aside, applied once nothing can stop it
        holding = True
        for j in range(6):
            c = S[REF + j] + D[i, j]
            if trip >= 0 and abs(c - S[CMD + j]) > trip:
                stop[0] = TRIPPED
                stop[1] = i
                return k
            cmd[j] = c
            if c != S[CMD + j]:
                holding = False
        moved = False
        on_cmd = True
        for j in range(6):
            if ideal:
                c = cmd[j]
            else:
                y[j] = g * cmd[j] + keep * F[Y + j]
                c = np.int64(np.rint(y[j]))
            cnt[j] = c
            if c != S[CUR + j]:
                moved = True
            if c != cmd[j]:
                on_cmd = False
        at_rest = holding and on_cmd
        settle = at_rest and S[AT_REST] == 0 and sigma  # comes to rest: new perturbation
        if settle and S[EPS_NEXT] >= nblock:
            stop[0] = NEED_EPS
            stop[1] = i
            return k
        for j in range(6):
            if not ideal:
                F[Y + j] = y[j]
            S[CUR + j] = cnt[j]
            S[CMD + j] = cmd[j]
            cur_out[i, j] = cnt[j]
        if settle:
            e = S[EPS_NEXT]
            for j in range(6):
                F[EPS + j] = eps_block[e, j]
            S[EPS_NEXT] = e + 1
            S[DIRTY] = 1
        if moved:
            S[DIRTY] = 1
        S[AT_REST] = 1 if at_rest else 0
        if S[DIRTY] == 1:
            _joint_row(S, F, sigma, Q, k)
            k += 1
            S[DIRTY] = 0
        row_of[i] = k - 1
    stop[0] = DONE
    stop[1] = n
    return k


@njit(cache=True, nogil=True, inline="always")
def _joint_row(S, F, sigma, Q, k):
    # q_j = sum_k M[j,k] (counts_k - qe0_k) over the non-zero M, in k order (as
    # ``Twin._joint_angles``), then (q + delta) + eps (as ``Twin._update``)
    for j in range(6):
        acc = 0.0
        for c in range(6):
            m = F[M + 6 * j + c]
            if m != 0.0:
                acc += m * np.float64(S[CUR + c] - S[QE0 + c])
        v = acc + F[DELTA + j]
        if sigma:
            v = v + F[EPS + j]
        Q[k, j] = v


@njit(cache=True, nogil=True)
def laser(row_of, dist, prev, i0, block, left, noise, quantum, lo, hi, out, stop):
    """Readings [mm] (NaN: none) of ticks ``i0..``: tick i reads ``dist[row_of[i]]`` [m]
    (``prev`` for -1; < 0: no hit, no noise drawn). Noise: ``block[left - 1]``, then
    ``left - 1`` ... (``noise`` False: none). Returns the new ``left``; ``stop[0]`` DONE or
    NEED_EPS (the noise block is used up at tick ``stop[1]``: refill, call again from
    there)."""
    n = row_of.shape[0]
    for i in range(i0, n):
        r = row_of[i]
        d = prev if r < 0 else dist[r]
        if d < 0.0:
            out[i] = np.nan
            continue
        mm = d * 1000.0
        if noise:
            if left == 0:
                stop[0] = NEED_EPS
                stop[1] = i
                return left
            mm += block[left - 1]
            left -= 1
        if quantum > 0.0:
            mm = np.rint(mm / quantum) * quantum
        out[i] = np.nan if (mm < lo or mm > hi) else mm
    stop[0] = DONE
    stop[1] = n
    return left
