"""Servo and joint-error models of the twin (all in encoder counts / joint radians).

Servo (``Servo``): the controller's position loop as seen through the encoders.
* ``ideal``: current = commanded at every tick.
* ``lag``: first order with time constant ``tau_s`` (30 ms default), the encoders
  showing the filter output rounded to integer counts, so they settle exactly on the
  command (see ``Servo``).

Joint errors added to the joint angle the encoders imply (``JointErrors``):
* repeatability: each time the robot comes to rest (the first tick at which the counts
  are on the command and the command holds) a new joint perturbation ``eps ~ N(0, s^2 I)``
  is drawn and held until the next rest. ``s = (r / 3) / ||J_v(q = 0)||_F`` makes the
  flange position's 3-sigma spread about ``r`` (robot.json ``repeatability_mm``, JIS
  B 8432 +-0.07 mm for the MC70). Small: for the MC70, s ~ 1.1e-5 rad (~0.5 count).
* compliance (off by default): joints 2 and 3 yield to the gravity torque of a lumped
  mass model, ``dq_j = tau_j / k_j``; ``LUMPED_MASSES`` lists the masses.
* backlash (off by default): joint j's output trails its motor by ``b_j / 2`` against
  the direction of its last motion.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from planecal.robot import Robot, fk_frames, repeatability_sigma

SERVO_MODES = ("ideal", "lag")


def _first_order_filter():
    """(``f(b, a, x, zi) -> (y, zf)`` along axis 0, the C function or None): scipy's C
    filter under ``lfilter`` (~20 us less per call than lfilter's argument handling;
    called as ``raw(b, a, x, 0, zi)``, x float or int64) when it answers exactly like lfilter, else
    lfilter itself and None."""
    def public(b, a, x, zi):
        return lfilter(b, a, x, axis=0, zi=zi)
    try:
        from scipy.signal import _sigtools
        raw = _sigtools._linear_filter

        def fast(b, a, x, zi):
            return raw(b, a, x, 0, zi)
        rng = np.random.default_rng(0)
        b, a = np.array([0.3]), np.array([1.0, -0.7])
        x, zi = rng.normal(0, 100, (50, 6)), rng.normal(0, 10, (1, 6))
        want, got = public(b, a, x, zi), fast(b, a, x, zi)
        xi = np.rint(x).astype(np.int64)  # integer commands: converted inside, exactly
        want_i, got_i = public(b, a, xi.astype(float), zi), raw(b, a, xi, 0, zi)
        if all(np.array_equal(u, v) and v.dtype == np.float64
               for u, v in [*zip(want, got), *zip(want_i, got_i)]):
            return fast, raw
    except Exception:  # noqa: BLE001 - a private function: any change means lfilter
        pass
    return public, None


_filter, _raw_filter = _first_order_filter()
# (DH frame, point in that frame [m], mass [kg]): an MC70-sized arm (~570 kg in all)
LUMPED_MASSES = [
    (2, (-0.45, 0.0, 0.0), 110.0),  # upper arm
    (3, (0.0, 0.0, 0.05), 90.0),  # elbow housing, J4 motor
    (4, (0.0, 0.45, 0.0), 45.0),  # forearm tube
    (5, (0.0, 0.0, 0.05), 20.0),  # wrist and tool
]
GRAVITY = np.array([0.0, 0.0, -9.81])
EPS_BLOCK = 64  # joint perturbations drawn at once (``JointErrors.on_settle``)


class Servo:
    """Integer encoder counts following integer commands.

    ``lag``: a first-order filter ``y <- g u + (1 - g) y`` (g = 1 - exp(-tick/tau)) runs
    in floating point and the encoders show ``current = rint(y)``; once the command
    holds, ``|y - u|`` shrinks geometrically below half a count and the counts sit
    exactly on the command (a 50-count step settles in ~14 ticks with tau = 30 ms).
    ``step`` (one tick, Python floats) and ``run`` (many ticks, scipy.signal.lfilter)
    do the same arithmetic. State: ``current`` (list of ints), ``y`` (list of floats).
    """

    def __init__(self, start_counts, mode: str = "ideal", tau_s: float = 0.03,
                 tick_s: float = 0.01):
        if mode not in SERVO_MODES:
            raise ValueError(f"servo mode must be one of {SERVO_MODES}, got {mode!r}")
        if mode == "lag" and not tau_s > 0:
            raise ValueError(f"servo time constant must be > 0, got {tau_s!r}")
        self.mode = mode
        self.ideal = mode == "ideal"
        self.current = [int(c) for c in start_counts]
        self.y = [float(c) for c in self.current]
        self.gain = 1.0 - float(np.exp(-tick_s / tau_s)) if mode == "lag" else 1.0
        self.keep = 1.0 - self.gain
        self._b, self._a = np.array([self.gain]), np.array([1.0, -self.keep])  # lfilter's
        # the filter state keep * y as a (1, 6) array, None when ``y`` changed elsewhere:
        # ``run`` keeps lfilter's final state (= keep * y[-1], bit for bit) for the next run
        self._zi = None

    def set(self, counts) -> None:
        """Put the servo at rest on ``counts``."""
        self.current = [int(c) for c in counts]
        self.y = [float(c) for c in self.current]
        self._zi = None

    def step(self, commanded: list) -> bool:
        """Advance one tick towards ``commanded`` (list of ints); True when the counts changed."""
        if self.ideal:
            if commanded == self.current:
                return False
            self.current = list(commanded)
            return True
        g, k = self.gain, self.keep
        self.y = y = [g * u + k * v for u, v in zip(commanded, self.y)]
        self._zi = None
        new = [round(v) for v in y]  # Python round: half to even, like np.rint
        if new == self.current:
            return False
        self.current = new
        return True

    def run(self, commanded: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Counts (N, 6) int64 for commands (N, 6), one row per tick (into ``out`` if
        given)."""
        if out is None:
            out = np.empty(commanded.shape, np.int64)
        if self.ideal:
            out[...] = commanded
        else:
            zi = self._zi
            if zi is None:
                zi = np.multiply(self.keep, self.y)[None, :]
            if _raw_filter is not None:  # (it converts the int64 commands to float)
                y, self._zi = _raw_filter(self._b, self._a, commanded, 0, zi)
            else:
                y, self._zi = _filter(self._b, self._a, commanded.astype(float), zi)
            self.y = y[-1].tolist()
            out[...] = np.rint(y, out=y)
        self.current = out[-1].tolist()
        return out


def gravity_torque(robot: Robot, theta_q: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Gravity torque (6,) [N m] about each joint axis for the lumped masses."""
    F = fk_frames(robot, theta_q, delta)
    tau = np.zeros(robot.n_joints)
    for frame, p, m in LUMPED_MASSES:
        c = F[frame, :3, :3] @ np.asarray(p) + F[frame, :3, 3]
        f = m * GRAVITY
        for j in range(frame):  # joints 1..frame move this mass
            z, o = F[j, :3, 2], F[j, :3, 3]
            tau[j] += z @ np.cross(c - o, f)
    return tau


class JointErrors:
    """Non-encoder joint errors; ``extra(q)`` is added to qpos (rad)."""

    def __init__(self, robot: Robot, rng: np.random.Generator, repeatability_m: float = 0.0,
                 stiffness=None, backlash_rad=None):
        self.robot = robot
        self.rng = rng
        self.sigma = repeatability_sigma(robot, repeatability_m) if repeatability_m > 0 else 0.0
        self.stiffness = None if stiffness is None else np.asarray(stiffness, float).reshape(2)
        self.backlash = None if backlash_rad is None else np.asarray(backlash_rad, float).reshape(6)
        self.eps = np.zeros(robot.n_joints)
        self.direction = np.zeros(robot.n_joints)
        self._eps_block = np.zeros((0, robot.n_joints))  # perturbations drawn ahead
        self._next = 0

    @property
    def active(self) -> bool:
        return self.sigma > 0 or self.stiffness is not None or self.backlash is not None

    def on_move(self, step_counts: np.ndarray) -> None:
        if self.backlash is not None:
            s = np.sign(step_counts / self.robot.gains)  # joint-side direction
            self.direction = np.where(s != 0, s, self.direction)

    def on_settle(self) -> None:
        if self.sigma > 0:
            if self._next == len(self._eps_block):
                self.draw_block()
            self.eps = self._eps_block[self._next]
            self._next += 1

    def draw_block(self) -> None:
        """Draw the next EPS_BLOCK perturbations: the same values, in the same order, as
        one rng.normal(0, sigma, n_joints) call per settle (numpy's Generator draws
        element by element), ~5 us less per settle. ``Twin.run`` calls it at the settle
        that needs it, as ``on_settle`` does."""
        self._eps_block = self.rng.normal(0.0, self.sigma, (EPS_BLOCK, self.robot.n_joints))
        self._next = 0

    def extra(self, q: np.ndarray, delta: np.ndarray) -> np.ndarray:
        out = self.eps.copy()
        if self.backlash is not None:
            out -= 0.5 * self.backlash * self.direction
        if self.stiffness is not None:
            tau = gravity_torque(self.robot, q + out, delta)
            out[1:3] += tau[1:3] / self.stiffness
        return out
