"""planecal mjcf [--scene S] --out OUT.xml [--truth-seed N | --truth FILE] [--force]

Write a scene's MuJoCo model (robot, tool and cell) as MJCF for a viewer
(``python -m mujoco.viewer --mjcf OUT.xml``). Without a truth option the model holds the
scene's nominal sensor pose and plates; ``--truth-seed`` / ``--truth`` place them at a
twin's hidden truth instead (its joint offsets are in the ``calibration`` keyframe's qpos).
"""
from __future__ import annotations

from planecal.commands.value_options import seed


def add_arguments(p):
    from planecal.model.scene import DEFAULT_SCENE
    p.add_argument("--scene", default=DEFAULT_SCENE,
                   help="scene name (planecal scenes) or path (default %(default)s)")
    p.add_argument("--out", required=True, metavar="OUT.xml", help="MJCF file to write")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--truth-seed", type=seed, default=None,
                   help="place sensor and plates at the twin's truth drawn from this seed")
    g.add_argument("--truth", default=None, metavar="FILE",
                   help="place them at this truth (parameter file, e.g. rehearse --truth-out)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing OUT.xml planecal did not write")


def run(args) -> int:
    from planecal.io.outputs import check_output
    from planecal.model.scene import load_scene
    from planecal.twin.export import export_scene

    scene = load_scene(args.scene)
    ours = _written_by_us(args.out)  # a model this command wrote may be replaced
    out = check_output(args.out, inputs=(args.truth, scene.path), force=args.force or ours)
    export_scene(scene, out, args.truth, args.truth_seed)
    print(f"MJCF written to {out}; view it with: python -m mujoco.viewer --mjcf {out}")
    return 0


def _written_by_us(path) -> bool:
    from pathlib import Path

    from planecal.twin.export import MARKER
    p = Path(path)
    try:
        with open(p, "rb") as f:
            return MARKER.encode() in f.read(512)
    except OSError:
        return False
