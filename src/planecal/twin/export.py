"""Write a scene's MuJoCo model (robot + tool + cell) as MJCF for a viewer.

usage: python -m planecal.twin.export SCENE OUT.xml [--truth-seed N | --truth FILE]

Without a truth option the model holds the scene's nominal sensor pose and plates;
``--truth-seed``/``--truth`` place them at a twin's hidden truth instead (its joint
offsets are in the ``calibration`` keyframe's qpos). Open it with
``python -m mujoco.viewer --mjcf OUT.xml``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planecal.errors import InputError
from planecal.scene import load_scene
from planecal.twin.mjcf import scene_spec, to_xml_exact
from planecal.twin.truth import resolve_truth


def export_scene(scene_name, out: Path, truth=None, seed: int | None = None) -> Path:
    scene = load_scene(scene_name)
    world = None
    if truth is not None or seed is not None:
        world = resolve_truth(scene, truth, 0 if seed is None else seed)
    cal = scene.calibration_q
    if cal is not None and world is not None:
        cal = cal + world.params.joint_offsets
    spec = scene_spec(scene, None if world is None else world.params, calibration_qpos=cal,
                      kin=None if world is None else world.kinematics)
    spec.compile()  # fail here, not in the viewer
    out = Path(out)
    out.write_text(to_xml_exact(spec))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m planecal.twin.export",
                                 description="Write a scene's MJCF (robot + tool + cell).")
    ap.add_argument("scene", help="scene name under scenes/ or a path")
    ap.add_argument("out", type=Path, help="output .xml")
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--truth-seed", type=int, help="place sensor and plates at the truth drawn from this seed")
    g.add_argument("--truth", help="truth parameter file")
    args = ap.parse_args(argv)
    try:
        path = export_scene(args.scene, args.out, args.truth, args.truth_seed)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
