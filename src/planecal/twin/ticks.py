"""The twin's tick, written once: the FD11 semantics, the servo, the rest logic, every
error source on the joints, and the laser model, one tick after the other.

Each function below is plain Python that numba compiles (``COMPILED``); the same source
run by the interpreter is the reference (``REFERENCE``: ``register_jitable`` keeps the
helpers plain Python when called from Python). The tests hold the two to each other bit
for bit. The beams are cast outside, by MuJoCo (``beam.BeamCaster``), for the joint rows
this module computes.

One tick (``advance``), for the row ``D[i]`` of deltas:

1. command = reference + delta; a change of more than the trip step on a joint stops
   before the tick (``TRIPPED``: the FD11 brakes);
2. the servo: ``ideal`` (counts = command) or a first-order lag whose output is rounded
   to counts (``y <- g u + (1 - g) y``, counts = rint(y));
3. at rest = the command holds and the counts are on it; the first tick at rest is a
   *settle*: it draws the next repeatability perturbation ``eps`` (N(0, s^2) per joint)
   and, with quantisation on, the next sub-count position ``u`` of each motor
   (U(-1/2, 1/2) counts); a draw that finds its block used up stops before the tick
   (``NEED_BLOCK``, ``stop[2]`` says which block) so the caller can draw the next block
   and call again from that tick;
4. when the counts moved, the backlash direction of each joint follows the sign of its
   joint-side motion (unchanged for joints that did not move);
5. whenever the state changed (counts moved, a settle, or stale at entry), the joint row
   ``qpos`` of that tick (``joint_row``, below) goes into ``Q``; ``row_of[i]`` is the row
   tick i shows (-1: the state before the call). A call that reads no laser (a move)
   computes the row of the state it ends in only: the row is a function of the state
   (rest draws, counts, backlash sides), so it is the one the last tick's would be.

The joint row, in this order (rad; ``joint_row``):

    x  = counts - qe0 (+ u)                  motor side, counts from the zero reference
    q  = M x                                 M = C diag(1/g): gains and wrist coupling
    q += sum_h A_h sin(f_h q + phi_h)        gear transmission error (per joint)
    q -= b / 2 * direction                   backlash: the output trails its motor; a
                                             joint held by gravity (|tau| >= its preload
                                             torque) rests on the flank tau pushes it to
    q += delta_true                          the true joint zero offsets
    q += eps                                 repeatability perturbation of this rest
    q += c * tau_gravity(q)                  gravity compliance (c = 1/k per joint), the
                                             torque at the deflected pose (3 passes)

``laser`` then turns each reading tick's true distance into a reading: mm = 1000 d +
linearity error (``a1 sin(2 pi x + p1) + a2 sin(4 pi x + p2)``, x the place of the
distance in the 65-95 mm window) + noise (N(0, sigma^2) from a block drawn ahead),
optional quantum, and the window (NaN outside, and for no hit, d < 0).

State travels in two arrays, ``S`` (int64) and ``F`` (float64), laid out by the indices
below, and the world (``W``): gear harmonics and the gravity model (body poses, masses).
numba compiles at the first use in a process (cached on disk in planecal's cache folder,
``planecal.base.paths.numba_cache``).
"""
from __future__ import annotations

import numpy as np

from planecal.base.paths import numba_cache
from planecal.model.gravity_kernel import gravity_torque  # the one formula (also the calibration's)

try:
    from numba import njit
    from numba.extending import register_jitable
except ImportError:  # pragma: no cover - numba is a dependency; the reference still runs
    njit = None

    def register_jitable(f):
        return f

# S: int64 state
CUR = 0          # [0:6]   current counts
CMD = 6          # [6:12]  last commanded counts
REF = 12         # [12:18] reference counts
QE0 = 18         # [18:24] nominal qe0 (encoder counts at q = 0)
DIR = 24         # [24:30] backlash direction of each joint (-1, 0, +1)
AT_REST = 30     # 1: at rest after the last tick
DIRTY = 31       # 1: the joint row is stale (recompute at the next tick)
EPS_NEXT = 32    # next unused row of the perturbation block
U_NEXT = 33      # next unused row of the quantisation block
TRIP = 34        # trip step (counts); < 0: no check
IDEAL = 35       # 1: ideal servo
FLAGS = 36       # error sources on (bits below)
NS = 37
# F: float64 state
Y = 0            # [0:6]   servo filter output (counts, float)
GAIN = 6         # servo gain g
KEEP = 7         # 1 - g
EPS = 8          # [8:14]  current repeatability perturbation (rad)
U = 14           # [14:20] current sub-count motor positions (counts)
DELTA = 20       # [20:26] true joint offsets (rad)
M = 26           # [26:62] q = M (counts - qe0), row-major 6 x 6
BACK = 62        # [62:68] backlash per joint (rad, full width)
COMP = 68        # [68:74] compliance per joint (rad / N m)
QNOW = 74        # [74:80] the joint row of the current state
PRELOAD = 80     # [80:86] backlash: a gravity torque at least this (N m, > 0) holds the
                 # joint on one flank (0: by the direction of motion only)
NF = 86

# FLAGS bits
REPEAT, QUANT, GEAR, BACKLASH, COMPLY, PRELOADED = 1, 2, 4, 8, 16, 32

# why a function returned (``stop[0]``; ``stop[1]`` = the tick it stopped at; for
# NEED_BLOCK ``stop[2]`` = the block: 0 perturbations, 1 quantisation, 2 laser noise)
DONE, NEED_BLOCK, TRIPPED = 0, 1, 2
BLOCK_EPS, BLOCK_U, BLOCK_NOISE = 0, 1, 2


@register_jitable
def joint_row(S, F, W, out):
    """The joint row (qpos, rad) of the current state into ``out`` (module docstring);
    also kept in ``F[QNOW:]``."""
    flags = S[FLAGS]
    G = W[0]
    x = np.empty(6)
    for c in range(6):
        x[c] = np.float64(S[CUR + c] - S[QE0 + c])
        if flags & QUANT:
            x[c] = x[c] + F[U + c]
    q = np.empty(6)
    for j in range(6):
        # q_j = sum_c M[j,c] x_c over the non-zero M, in c order
        acc = 0.0
        for c in range(6):
            m = F[M + 6 * j + c]
            if m != 0.0:
                acc += m * x[c]
        q[j] = acc
    if flags & GEAR:
        for j in range(6):
            e = 0.0
            for h in range(G.shape[1]):
                if G[j, h, 0] != 0.0:
                    e += G[j, h, 0] * np.sin(G[j, h, 1] * q[j] + G[j, h, 2])
            q[j] = q[j] + e
    tau = np.zeros(6)
    if flags & BACKLASH and flags & PRELOADED:  # the flank gravity holds a joint on
        gravity_torque(q, W, tau)
    for j in range(6):
        v = q[j]
        if flags & BACKLASH:
            side = np.float64(S[DIR + j])
            pre = F[PRELOAD + j]
            if pre > 0.0 and abs(tau[j]) >= pre:
                side = -1.0 if tau[j] > 0.0 else 1.0  # trails against: rests towards tau
            v = v - 0.5 * F[BACK + j] * side
        v = v + F[DELTA + j]
        if flags & REPEAT:
            v = v + F[EPS + j]
        q[j] = v
    if flags & COMPLY:
        theta = q.copy()
        for _ in range(3):  # the torque at the deflected pose: each pass gains c dtau/dq
            # (~1e-3 for an arm like the MC70's), 3 passes leave ~1e-10 of the deflection
            gravity_torque(theta, W, tau)
            for j in range(6):
                theta[j] = q[j] + F[COMP + j] * tau[j]
        q = theta
    for j in range(6):
        out[j] = q[j]
        F[QNOW + j] = q[j]


@register_jitable
def settle(S, F, eps_block, u_block):
    """Draw this rest's perturbation and sub-count positions (from the blocks drawn
    ahead); returns -1, or the block (BLOCK_EPS, BLOCK_U) that is used up, with nothing
    drawn."""
    flags = S[FLAGS]
    if flags & REPEAT and S[EPS_NEXT] >= eps_block.shape[0]:
        return BLOCK_EPS
    if flags & QUANT and S[U_NEXT] >= u_block.shape[0]:
        return BLOCK_U
    if flags & REPEAT:
        e = S[EPS_NEXT]
        for j in range(6):
            F[EPS + j] = eps_block[e, j]
        S[EPS_NEXT] = e + 1
    if flags & QUANT:
        e = S[U_NEXT]
        for j in range(6):
            F[U + j] = u_block[e, j]
        S[U_NEXT] = e + 1
    S[DIRTY] = 1
    return -1


def advance(D, i0, S, F, W, eps_block, u_block, cur_out, row_of, Q, k0, stop, every_row):
    """Ticks ``i0..`` of ``D`` (n, 6) deltas (module docstring). Writes the counts
    ``cur_out[i]``, the recomputed joint rows ``Q[k0..]`` and ``row_of[i]``; returns the
    number of rows of Q now used; ``stop`` says why it returned (DONE, NEED_BLOCK,
    TRIPPED) and at which tick. ``every_row`` False (ticks that read no laser: a move):
    only the row of the state it returns in (DONE, TRIPPED) is computed, once, into
    ``Q[k0]``, and ``row_of`` is not written; the joint row is a function of the state
    alone, so that row and ``F[QNOW:]`` are the ones every tick's would have ended with."""
    n = D.shape[0]
    k = k0
    trip = S[TRIP]
    g = F[GAIN]
    keep = F[KEEP]
    ideal = S[IDEAL] == 1
    flags = S[FLAGS]
    draws = (flags & REPEAT) or (flags & QUANT)
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
                return k if every_row else flush_row(S, F, W, Q, k)
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
        if at_rest and S[AT_REST] == 0 and draws:  # comes to rest: this rest's draws
            need = settle(S, F, eps_block, u_block)
            if need >= 0:
                stop[0] = NEED_BLOCK
                stop[1] = i
                stop[2] = need
                return k
        if moved and flags & BACKLASH:
            follow_sides(S, F, cnt)
        for j in range(6):
            if not ideal:
                F[Y + j] = y[j]
            S[CUR + j] = cnt[j]
            S[CMD + j] = cmd[j]
            cur_out[i, j] = cnt[j]
        if moved:
            S[DIRTY] = 1
        S[AT_REST] = 1 if at_rest else 0
        if every_row:
            if S[DIRTY] == 1:
                joint_row(S, F, W, Q[k])
                k += 1
                S[DIRTY] = 0
            row_of[i] = k - 1
    stop[0] = DONE
    stop[1] = n
    return k if every_row else flush_row(S, F, W, Q, k)


@register_jitable
def follow_sides(S, F, cnt):
    """Each joint's backlash side follows the sign of its joint-side motion from the
    current counts to ``cnt`` (unchanged where it does not move)."""
    for j in range(6):
        dq = 0.0
        for c in range(6):
            m = F[M + 6 * j + c]
            if m != 0.0:
                dq += m * np.float64(cnt[c] - S[CUR + c])
        if dq > 0.0:
            S[DIR + j] = 1
        elif dq < 0.0:
            S[DIR + j] = -1


@register_jitable
def flush_row(S, F, W, Q, k):
    """The joint row of the current state into ``Q[k]`` where it is stale; returns the
    number of rows of Q then used."""
    if S[DIRTY] == 1:
        joint_row(S, F, W, Q[k])
        S[DIRTY] = 0
        return k + 1
    return k


def laser(row_of, dist, prev, i0, block, left, noise, quantum, lo, hi, lin, out, stop):
    """Readings [mm] (NaN: none) of ticks ``i0..``: tick i reads ``dist[row_of[i]]`` [m]
    (``prev`` for -1; < 0: no hit, no noise drawn). Linearity error ``lin`` = (a1, p1,
    a2, p2) (module docstring; zeros: none). Noise: ``block[left - 1]``, then ``left - 1``
    ... (``noise`` False: none). Returns the new ``left``; ``stop[0]`` DONE or NEED_BLOCK
    (the noise block is used up at tick ``stop[1]``: refill, call again)."""
    n = row_of.shape[0]
    linear = lin[0] != 0.0 or lin[2] != 0.0
    span = hi - lo
    for i in range(i0, n):
        r = row_of[i]
        d = prev if r < 0 else dist[r]
        if d < 0.0:
            out[i] = np.nan
            continue
        mm = d * 1000.0
        if linear:
            x = 2.0 * np.pi * (mm - lo) / span
            mm = mm + lin[0] * np.sin(x + lin[1]) + lin[2] * np.sin(2.0 * x + lin[3])
        if noise:
            if left == 0:
                stop[0] = NEED_BLOCK
                stop[1] = i
                stop[2] = BLOCK_NOISE
                return left
            mm += block[left - 1]
            left -= 1
        if quantum > 0.0:
            mm = np.rint(mm / quantum) * quantum
        out[i] = np.nan if (mm < lo or mm > hi) else mm
    stop[0] = DONE
    stop[1] = n
    return left


def refresh(S, F, W, out):
    """The joint row of the current state (after a jump, at construction)."""
    joint_row(S, F, W, out)
    S[DIRTY] = 0


class Ticks:
    """One implementation of the tick, run compiled or by the interpreter."""

    def __init__(self, advance, laser, settle, refresh, compiled: bool):
        self.advance, self.laser, self.settle, self.refresh = advance, laser, settle, refresh
        self.compiled = compiled


REFERENCE = Ticks(advance, laser, settle, refresh, compiled=False)


def compiled() -> Ticks:
    """The compiled tick (numba, cached in ``cache_dir()/numba``; ~1-2 s to compile the
    first time, ~0.3 s to load from the cache)."""
    if njit is None:
        raise ImportError("numba is not installed")
    numba_cache()
    jit = njit(cache=True, nogil=True)
    return Ticks(jit(advance), jit(laser), jit(settle), jit(refresh), compiled=True)
