"""Robot time of a sampling run, and the visiting order of a pose list that minimises it.

Robot time is what a calibration costs the cell: ticks x ``robot.tick_s`` (the MC70's
10 ms). Per sample the robot

* moves: the step generator (``steps``) cuts a move from counts a to counts b into
  ``steps.n_steps(a, b, nominal)`` ticks -- the joint that needs the most counts sets it,
  at the robot's step ``nominal`` (``Robot.step_counts``: the MC70's 50 counts, the UR5's
  129) -- then holds the goal for ``DWELL_TICKS`` (5);
  a detour's legs to its via-points have no dwell (``collect.DriveAcquirer``);
* reads the laser: ``read_stable`` takes one reading a tick until its buffer of
  ``buffer_len`` (100) readings is stable, so at least 100 ticks. On the twin with the
  default noise (1 um a reading) the median read takes 101 ticks but the mean is ~150: the
  spread of 100 readings often exceeds the 5 um limit and the buffer must turn over
  (150 samples, seed 1000: 90th percentile 248, max 448). ``READ_TICKS`` (the median,
  102) is for estimates; ``Clock`` counts the real reads of a collection.

``order`` finds the visiting order of a set of poses that minimises the travel ticks (the
dwell and read ticks are the same for every order): an open path from the start
configuration over the cost matrix of move ticks (symmetric: ``n_steps(a, b, s) ==
n_steps(b, a, s)``). Exact (Held-Karp dynamic programming) up to ``exact_max`` poses;
beyond, nearest neighbour and the input order, each improved by 2-opt (reverse a stretch)
and Or-opt (move a stretch of 1-3 poses elsewhere, either way round) until neither helps;
the better of the two. Hand-kept rather than a library: 150 poses take well under a second
in numpy, the result is deterministic (no wall-clock time limit, unlike the metaheuristics
of OR-Tools or fast-tsp), it can never be worse than the input order, and the exact solver
checks it on small instances.

With a collision checker the straight path of each move in the tour is checked (lazily:
only the moves a candidate tour uses, in both directions, then the tour is solved again
until every move in it is checked). A blocked move costs its detour (``detour.Detour``:
back out along the beam, move, approach) or is excluded when there is none. With
``blocked="avoid"`` (the default) a tour with fewer blocked moves always wins, whatever its
ticks: ``planner.ListPlanner`` serves the list in order only while each next pose is
reachable on a straight path (otherwise it takes a later pose that is, and comes back), so
a tour of clear moves is the one the run actually drives. ``blocked="detour"`` weighs a
detour by its ticks alone.

``visit`` is the ground truth for a planner: the moves (via-points, goal) the sampling
run's collect core takes with it if every laser read succeeds, from which ``robot_ticks``
gives the robot time.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from planecal.base.progress import report
from planecal.sampling.steps import DWELL_TICKS, n_steps

READ_TICKS = 102  # median ticks of one laser read on the twin (100 at least: the buffer)
READ_TICKS_MEAN = 150  # mean ticks of one stable read on the twin (what a budget of robot
# time spends: the buffer turns over when 100 readings of 1 um spread beyond 5 um; 40 reads
# of one three_plates pose took 152 ticks each, a 150-sample run 141 a stable read)
EXACT_MAX = 12  # poses up to which ``order`` solves exactly (Held-Karp: n^2 2^n)
BLOCKED_MODES = ("avoid", "detour")


# ----- robot time -------------------------------------------------------------------------------

def move_ticks(counts_a, counts_b, nominal: int, dwell: int = DWELL_TICKS) -> int:
    """Ticks of one move from counts a to counts b as the step generator makes it at
    ``nominal`` counts a tick (the robot's step, ``Robot.step_counts``), with
    ``dwell`` ticks holding the goal (``len(steps.step_path(a, b, nominal, dwell))``)."""
    return n_steps(counts_a, counts_b, nominal) + int(dwell)


@dataclass
class Visit:
    """One sample's move: the counts of its via-points (a detour's; none for a straight
    move), then its goal."""
    goal: np.ndarray
    via: list = field(default_factory=list)
    plate: int = 0


def _as_visits(sequence, vias) -> list[Visit]:
    if len(sequence) and isinstance(sequence[0], Visit):
        return list(sequence)
    seq = np.asarray(sequence, np.int64).reshape(-1, 6)
    vias = vias if vias is not None else [[]] * len(seq)
    if len(vias) != len(seq):
        raise ValueError(f"{len(vias)} via lists for {len(seq)} targets")
    return [Visit(c, [np.asarray(v, np.int64) for v in vs]) for c, vs in zip(seq, vias)]


def robot_ticks(sequence, start, read_ticks: float = READ_TICKS, vias=None, *,
                nominal: int, dwell: int = DWELL_TICKS) -> float:
    """Ticks of visiting ``sequence`` (encoder-count targets (n, 6), or ``Visit``s) from
    counts ``start`` at the robot's step ``nominal`` (``Robot.step_counts``): every leg's
    ``n_steps``, the dwell and ``read_ticks`` at each
    target (not at a via-point). ``vias``: per target, the via-point counts before it."""
    cur = np.asarray(start, np.int64)
    total = 0.0
    for v in _as_visits(sequence, vias):
        for c in v.via:
            total += move_ticks(cur, c, nominal, 0)
            cur = np.asarray(c, np.int64)
        total += move_ticks(cur, v.goal, nominal, dwell) + read_ticks
        cur = np.asarray(v.goal, np.int64)
    return total


def robot_time_s(sequence, start, robot, read_ticks: float = READ_TICKS, vias=None,
                 dwell: int = DWELL_TICKS) -> float:
    """Robot time [s] of ``robot_ticks`` on ``robot`` (``model.robot.Robot``): its step
    (``step_counts``) and its tick (``tick_s``)."""
    return robot_ticks(sequence, start, read_ticks, vias, nominal=robot.step_counts,
                       dwell=dwell) * float(robot.tick_s)


# ----- counting a collection's ticks -----------------------------------------------------------

class Clock:
    """An acquirer (``collect.Acquirer``) that counts the robot's ticks of a collection
    while ``inner`` acquires: each plan's legs from the last commanded counts (via-points
    without dwell, the goal with ``dwell``) and the laser read's own ticks
    (``LaserResult.reads``; a read that gives up counts too: the robot went there). With
    ``RestAcquirer`` (studies) this is the robot time ``DriveAcquirer`` spends on the same
    plans, without simulating the ticks. ``nominal``: the step the acquirer drives at
    (the run's ``nominal_step_counts``, the robot's step). ``ticks`` is the running
    total, ``travel_ticks`` the part spent moving (the legs without their dwell),
    ``read_ticks`` the laser's."""

    def __init__(self, inner, start_counts, nominal: int, dwell: int = DWELL_TICKS):
        self.inner, self.nominal, self.dwell = inner, nominal, dwell
        self.idle = inner.idle
        self.counts = np.asarray(start_counts, np.int64).copy()
        self.ticks = 0
        self.travel_ticks = 0
        self.read_ticks = 0
        self.moves = 0

    def ticks_for(self, plan, reads: int) -> int:
        """The ticks ``plan`` would take from where the robot is: its legs, the dwell and
        ``reads`` laser reads (``collect.Budget``: whether the next pose fits)."""
        counts, ticks = self.counts, self.dwell + reads
        for c in [c for _, c in plan.via] + [plan.qe_goal]:
            ticks += move_ticks(counts, c, self.nominal, 0)
            counts = np.asarray(c, np.int64)
        return ticks

    def acquire(self, plan):
        got = self.inner.acquire(plan)
        for _, c in plan.via:
            self._travel(move_ticks(self.counts, c, self.nominal, 0))
            self.counts = np.asarray(c, np.int64)
        self._travel(move_ticks(self.counts, plan.qe_goal, self.nominal, 0))
        self.ticks += self.dwell
        self.counts = np.asarray(plan.qe_goal, np.int64).copy()
        self.ticks += got.laser.reads
        self.read_ticks += got.laser.reads
        self.moves += 1
        return got

    def _travel(self, ticks: int) -> None:
        self.ticks += ticks
        self.travel_ticks += ticks


# ----- what a planner makes the run do ----------------------------------------------------------

class _Moves:
    """A collect-core recorder keeping each sample's move (``collect.Recorder``), and
    saying how many of ``samples`` are planned (``base.progress.report``)."""

    def __init__(self, samples: int):
        self.visits: list[Visit] = []
        self.samples = samples

    def sample(self, index, counts, d_mm, plan, direction) -> None:
        self.visits.append(Visit(np.asarray(plan.qe_goal, np.int64).copy(),
                                 [np.asarray(c, np.int64).copy() for _, c in plan.via],
                                 int(plan.plate)))
        report(len(self.visits), self.samples, "poses planned")

    def reject(self, kind, q, reason) -> None:
        report(len(self.visits), self.samples, "poses planned")


def visit(planner, start_q: np.ndarray, samples: int, seed: int = 0,
          max_attempts: int = 500, short: bool = False):
    """The moves the sampling run makes with ``planner`` (a ``Planner`` drawing with
    ``seed``, or a ``ListPlanner``) from joint angles ``start_q`` if every laser read
    succeeds (``collect`` with ``PlansOnly``). RuntimeError when the planner gives up;
    with ``short`` the moves up to there and why it gave up (None: it did not)."""
    from planecal.sampling.collect import Cursor, PlansOnly, Tally, collect
    rec, tally = _Moves(samples), Tally()
    collect(planner, PlansOnly(), rec, samples,
            Cursor(np.asarray(start_q, float), np.random.default_rng(seed).bit_generator.state),
            tally, max_attempts)
    # a pose list that ends short (poses it cannot reach dropped) is complete, not whole
    why = None if tally.status == "complete" and tally.samples >= samples else tally.reason
    if short:
        return rec.visits, why
    if why is not None:
        raise RuntimeError(f"the planner gave up after {tally.samples} samples: {why}")
    return rec.visits


def visit_list(scene, counts, plates, checker, start_q: np.ndarray, approach=None):
    """What the sampling run does with a pose list (its ``ListPlanner``, each pose
    approached from its side of ``approach``) from joint angles ``start_q`` if every
    laser read succeeds: (the moves, the indices of the poses it takes in the order it
    takes them, why it stops short of the list or None). The list without the poses it
    left out, ``counts[np.sort(taken)]``, is then visited whole by the same moves: each
    pose the run took was the first of those left that it could reach (straight, else by
    a detour), and still is without the others."""
    from planecal.sampling.planner import ListPlanner
    lp = ListPlanner(scene, counts, plates, checker, approach=approach)
    visits, why = visit(lp, start_q, len(lp.counts), short=True)
    return visits, np.array(lp.taken, int), why


# ----- the order --------------------------------------------------------------------------------

@dataclass
class Tour:
    """``order``: indices into the poses, in visiting order; ``travel_ticks``: the moves'
    ticks without dwell (detours by their legs); ``detours``: moves of the tour whose
    straight path is blocked (each with a detour); ``excluded``: blocked moves without a
    detour the tour could not avoid; ``paths_checked``: straight paths checked."""
    order: list[int]
    travel_ticks: int
    detours: int = 0
    excluded: int = 0
    paths_checked: int = 0


def tick_matrix(nodes: np.ndarray, nominal: int) -> np.ndarray:
    """Straight-move ticks between every pair of count rows at ``nominal`` counts a tick
    (symmetric, int64)."""
    m = len(nodes)
    D = np.zeros((m, m), np.int64)
    for i in range(m):
        for j in range(i + 1, m):
            D[i, j] = D[j, i] = n_steps(nodes[i], nodes[j], nominal)
    return D


def path_cost(C: np.ndarray, path: Sequence[int]) -> float:
    """Cost of the open path ``path`` (node indices) over matrix C."""
    p = np.asarray(path)
    return float(C[p[:-1], p[1:]].sum()) if len(p) > 1 else 0.0


def held_karp(C: np.ndarray) -> list[int]:
    """The cheapest open path from node 0 through every other node of C (exact, dynamic
    programming over subsets: O(n^2 2^n)); returns the nodes after 0, in order."""
    n = len(C) - 1
    if n <= 1:
        return list(range(1, n + 1))
    full = 1 << n
    dp = np.full((full, n), np.inf)
    parent = np.full((full, n), -1, np.int64)
    Cn = C[1:, 1:]
    for j in range(n):
        dp[1 << j, j] = C[0, j + 1]
    for mask in range(1, full):
        if mask & (mask - 1) == 0:
            continue
        for j in range(n):
            bit = 1 << j
            if not mask & bit:
                continue
            prev = dp[mask ^ bit] + Cn[:, j]
            i = int(np.argmin(prev))
            dp[mask, j], parent[mask, j] = prev[i], i
    mask, j = full - 1, int(np.argmin(dp[full - 1]))
    out = []
    while j >= 0:
        out.append(j + 1)
        mask, j = mask ^ (1 << j), int(parent[mask, j])
    return out[::-1]


def nearest_neighbour(C: np.ndarray) -> list[int]:
    """Greedy open path from node 0: always the cheapest unvisited node next (ties: the
    lowest index)."""
    n = len(C)
    left = np.ones(n, bool)
    left[0] = False
    cur, out = 0, []
    for _ in range(n - 1):
        c = np.where(left, C[cur], np.inf)
        cur = int(np.argmin(c))
        left[cur] = False
        out.append(cur)
    return out


def _two_opt(Cx: np.ndarray, p: np.ndarray) -> bool:
    """One pass of 2-opt on the path p (fixed ends p[0], p[-1]): for each i the best
    reversal p[i..j]; True if it improved."""
    improved = False
    m = len(p)
    for i in range(1, m - 2):
        js = np.arange(i + 1, m - 1)
        a, b = p[i - 1], p[i]
        c, d = p[js], p[js + 1]
        delta = Cx[a, c] + Cx[b, d] - Cx[a, b] - Cx[c, d]
        k = int(np.argmin(delta))
        if delta[k] < -1e-9:
            j = js[k]
            p[i:j + 1] = p[i:j + 1][::-1].copy()
            improved = True
    return improved


def _or_opt(Cx: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, bool]:
    """One pass of Or-opt on p (fixed ends): move a stretch of 1-3 nodes, forward or
    reversed, to its best place elsewhere; (path, improved)."""
    improved = False
    for L in (1, 2, 3):
        i = 1
        while i + L <= len(p) - 1:
            seg = p[i:i + L]
            prev, nxt = p[i - 1], p[i + L]
            gain = Cx[prev, seg[0]] + Cx[seg[-1], nxt] - Cx[prev, nxt]
            rest = np.concatenate([p[:i], p[i + L:]])
            u, w = rest[:-1], rest[1:]  # insert between u[k] and w[k]
            fwd = Cx[u, seg[0]] + Cx[seg[-1], w] - Cx[u, w]
            rev = Cx[u, seg[-1]] + Cx[seg[0], w] - Cx[u, w]
            best = np.minimum(fwd, rev)
            k = int(np.argmin(best))
            if best[k] - gain < -1e-9:
                s = seg if fwd[k] <= rev[k] else seg[::-1]
                p = np.concatenate([rest[:k + 1], s, rest[k + 1:]])
                improved = True
            else:
                i += 1
    return p, improved


def local_search(C: np.ndarray, start_order: Sequence[int]) -> list[int]:
    """2-opt and Or-opt from ``start_order`` (the nodes after 0) until neither improves."""
    n = len(C)
    Cx = np.zeros((n + 1, n + 1))  # a free end node: the open path as a fixed-end path
    Cx[:n, :n] = C
    p = np.array([0, *start_order, n], np.int64)
    while True:
        a = _two_opt(Cx, p)
        p, b = _or_opt(Cx, p)
        if not (a or b):
            return [int(x) for x in p[1:-1]]


def solve_path(C: np.ndarray, initial: Sequence[int] | None = None,
               exact_max: int = EXACT_MAX) -> list[int]:
    """The cheapest open path from node 0 found over C (module docstring): exact up to
    ``exact_max`` nodes after 0; else the best of local search from nearest neighbour and
    from ``initial`` (default 1..n). Never costlier than ``initial``."""
    n = len(C) - 1
    initial = list(range(1, n + 1)) if initial is None else [int(x) for x in initial]
    if n <= exact_max:
        return held_karp(C)
    cands = [local_search(C, nearest_neighbour(C)), local_search(C, initial)]
    costs = [path_cost(C, [0, *c]) for c in cands]
    return cands[int(np.argmin(costs))]


def order(counts, start, checker=None, scene=None, blocked: str = "avoid",
          exact_max: int = EXACT_MAX, *, nominal: int) -> Tour:
    """The visiting order of the poses ``counts`` (n, 6) from counts ``start`` that
    minimises robot time at the robot's step ``nominal`` (``Robot.step_counts``; module
    docstring). With a ``checker`` (``CollisionWorld``) the
    moves are collision-checked; ``scene`` (for counts -> joint angles and the detour) is
    then required. Never worse than the input order (by the same costs)."""
    if blocked not in BLOCKED_MODES:
        raise ValueError(f"blocked must be one of {BLOCKED_MODES}, got {blocked!r}")
    counts = np.asarray(counts, np.int64).reshape(-1, 6)
    n = len(counts)
    nodes = np.concatenate([np.asarray(start, np.int64).reshape(1, 6), counts])
    D = tick_matrix(nodes, nominal).astype(float)
    identity = list(range(1, n + 1))
    if checker is None:
        path = solve_path(D, identity, exact_max)
        return Tour([i - 1 for i in path], int(path_cost(D, [0, *path])))
    if scene is None:
        raise ValueError("order: a collision checker needs the scene")
    edges = _EdgeChecker(scene, checker, nodes, D, blocked, nominal)
    rounds = 0
    while True:
        rounds += 1
        report(rounds, None, f"order: {edges.paths // 2} moves checked, search round")
        C = edges.matrix()
        path = solve_path(C, identity, exact_max)
        if path_cost(C, [0, *identity]) < path_cost(C, [0, *path]):
            path = identity  # only possible while some of identity's moves are unchecked
        todo = edges.unchecked([0, *path]) | edges.unchecked([0, *identity])
        if not todo:
            break
        edges.check(todo)
    tour = [0, *path]
    legs = [edges.status[_key(a, b)] for a, b in zip(tour[:-1], tour[1:])]
    travel = sum(s if s > 0 else D[a, b] for (a, b), s in zip(zip(tour[:-1], tour[1:]), legs))
    return Tour([i - 1 for i in path], int(travel),
                detours=sum(1 for s in legs if s > 0), excluded=sum(1 for s in legs if s < 0),
                paths_checked=edges.paths)


def _key(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


class _EdgeChecker:
    """Checked moves between nodes: ``status[(i, j)]`` 0 clear, > 0 blocked with a
    detour of that many travel ticks, -1 blocked without a detour."""

    def __init__(self, scene, checker, nodes, D, blocked, nominal):
        from planecal.model.encoder import counts_to_joints
        from planecal.sampling.planner import ListPlanner
        self.checker, self.D, self.blocked, self.nominal = checker, D, blocked, nominal
        self.nodes = nodes
        self.q = counts_to_joints(scene.robot, nodes)
        # the run's own detour (ListPlanner builds it the same way for the pose list)
        self.detour = ListPlanner(scene, nodes[1:], np.zeros(len(nodes) - 1, int),
                                  checker).detour
        self.status: dict = {}
        self.paths = 0
        # lexicographic costs: fewer excluded moves, then (avoid) fewer detours, then ticks
        self.penalty = float(D.max() * len(D) + 1)
        self.excluded = self.penalty * (len(D) + 2)

    def unchecked(self, path) -> set:
        return {_key(a, b) for a, b in zip(path[:-1], path[1:])} - self.status.keys()

    def check(self, todo) -> None:
        for a, b in sorted(todo):
            report(self.paths // 2, None, "order: moves checked")  # each 10-20 ms
            qa, qb = self.q[a], self.q[b]
            self.paths += 2
            if self.checker.check_path(qa, qb).ok and self.checker.check_path(qb, qa).ok:
                self.status[(a, b)] = 0
                continue
            via = self.detour.find(qa, qb)
            if not via:
                self.status[(a, b)] = -1
                continue
            pts = [self.nodes[a], *(c for _, c in via), self.nodes[b]]
            self.status[(a, b)] = max(1, sum(n_steps(x, y, self.nominal)
                                             for x, y in zip(pts[:-1], pts[1:])))

    def matrix(self) -> np.ndarray:
        C = self.D.copy()
        for (a, b), s in self.status.items():
            if s < 0:
                x = self.excluded
            elif s > 0:
                x = s + (self.penalty if self.blocked == "avoid" else 0.0)
            else:
                continue
            C[a, b] = C[b, a] = x
        return C
