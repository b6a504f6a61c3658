"""Pairs of a robot's collision pieces that touch in (nearly) every configuration: what
``planecal robot import`` allows in shapes.json, each with its reason.

A URDF's collision meshes are often coarse hulls: the IRB 4600's link 4 swallows link 6,
so no configuration of the arm is clear of itself and every plate placement of
``scene new`` fails. The checker cannot tell such a pair apart at any angle, so checking
it says nothing about the arm: sampled at ``SAMPLES`` random configurations within the
limits, a pair within the checker's clearance in at least ``ALWAYS`` of them is allowed
(not checked), as ``models/ur5/shapes.json`` allows the UR's nested wrist by hand.
"""
from __future__ import annotations

import numpy as np

from planecal.model.robot import Robot

SAMPLES = 200
ALWAYS = 0.95  # share of the sampled configurations a pair must touch in to be allowed


def always_touching(robot: Robot, samples: int = SAMPLES, seed: int = 0,
                    allowed=()) -> tuple[list[dict], float, float]:
    """(allowed pairs as shapes.json writes them, {pieces, why}; the share of the sampled
    configurations clear of the arm itself before, and after allowing them). ``allowed``:
    pairs shapes.json allows already."""
    from planecal.safety.collision import CollisionWorld
    world = CollisionWorld(None, robot=robot, tools=[], static=[], allowed_pairs=allowed)
    pairs = world.pairs
    if not pairs:
        return [], 1.0, 1.0
    rng = np.random.default_rng(seed)
    Q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], (samples, robot.n_joints))
    touch = np.array([world.distances(q) <= world.clearance_m for q in Q])  # (samples, pairs)
    share = touch.mean(axis=0)
    keep = share >= ALWAYS
    out = [{"pieces": [a, b],
            "why": (f"within the checker's clearance ({world.clearance_m * 1e3:g} mm) in "
                    f"{int(touch[:, k].sum())} of {samples} random configurations: their "
                    "hulls overlap whatever the joints do, so checking them says nothing "
                    "(found by planecal robot import)")}
           for k, (a, b, _) in enumerate(pairs) if keep[k]]
    before = float((~touch.any(axis=1)).mean())
    after = float((~touch[:, ~keep].any(axis=1)).mean()) if (~keep).any() else 1.0
    return out, before, after
