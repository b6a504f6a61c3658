"""Pairs of a robot's collision pieces that touch in (nearly) every configuration, or
that the structure keeps side by side: what ``planecal robot import`` allows in
shapes.json, each with its reason.

A URDF's collision meshes are often coarse hulls: the IRB 4600's link 4 swallows link 6,
so no configuration of the arm is clear of itself and every plate placement of
``scene new`` fails. The checker cannot tell such a pair apart at any angle, so checking
it says nothing about the arm. Sampled at ``SAMPLES`` random configurations within the
limits, a pair is allowed (not checked) when it is within the checker's clearance in at
least ``ALWAYS`` of them, or when it is within it in some and never more than
``NESTED_M`` apart in any: the structure holds the two side by side whatever the joints
do (a UR's nested wrist: forearm and wrist 2 stay 0-11 mm apart on the UR10, 0-24 mm on
the UR10e; base and upper arm 0-12 mm), so the checker's verdict on them is the hulls'
margin, not the arm's motion -- as ``models/ur5/shapes.json`` allows those pairs by hand.
"""
from __future__ import annotations

import numpy as np

from planecal.model.robot import Robot

SAMPLES = 200
ALWAYS = 0.95  # share of the sampled configurations a pair must touch in to be allowed
NESTED_M = 0.03  # a pair never farther apart than this is held side by side (allowed)


def always_touching(robot: Robot, samples: int = SAMPLES, seed: int = 0,
                    links=None, scene=None) -> tuple[list[dict], float, float]:
    """(allowed pairs as shapes.json writes them, {pieces, why}; the share of the sampled
    configurations clear of the arm itself before, and after allowing them). ``links``:
    the robot's collision pieces (``geometry.robot_link_meshes``) without the pairs its
    shapes.json allows (default: its shapes.json, those pairs skipped). With a ``scene``:
    the pairs of its tool's pieces with the arm's instead (``scene new``; the arm's own
    pairs are its shapes.json's business)."""
    from planecal.safety.collision import CollisionWorld
    world = CollisionWorld(scene, robot=robot, links=links, static=[],
                           tools=None if scene is not None else [])
    tool = {p.name for p in world.parts if p.kind == "tool"}
    mine = np.array([scene is None or bool(tool & {a, b}) for a, b, _ in world.pairs], bool)
    if not mine.any():
        return [], 1.0, 1.0
    rng = np.random.default_rng(seed)
    Q = rng.uniform(robot.limits[:, 0], robot.limits[:, 1], (samples, robot.n_joints))
    D = np.array([world.distances(q) for q in Q])[:, mine]  # (samples, pairs) [m]
    names = [p for p, m in zip(world.pairs, mine) if m]
    touch = D <= world.clearance_m
    always = touch.mean(axis=0) >= ALWAYS
    nested = ~always & touch.any(axis=0) & (D.max(axis=0) <= NESTED_M)
    keep = always | nested
    out = []
    for k, (a, b, _) in enumerate(names):
        if not keep[k]:
            continue
        n = (f"within the checker's clearance ({world.clearance_m * 1e3:g} mm) in "
             f"{int(touch[:, k].sum())} of {samples} random configurations")
        why = (f"{n}: their hulls overlap whatever the joints do, so checking them says "
               "nothing" if always[k] else
               f"{n} and never more than {D[:, k].max() * 1e3:.1f} mm apart in any: the "
               "structure holds them side by side (a nested joint), so the checker's "
               "verdict on them is the hulls' margin, not the arm's motion")
        out.append({"pieces": [a, b], "why": f"{why} (found by planecal "
                                             f"{'scene new' if scene else 'robot import'})"})
    before = float((~touch.any(axis=1)).mean())
    after = float((~touch[:, ~keep].any(axis=1)).mean()) if (~keep).any() else 1.0
    return out, before, after
