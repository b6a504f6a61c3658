"""planecal mjcf [--scene S] --out OUT.xml [--truth-seed N | --truth FILE] [--force]

Write a scene's MuJoCo model (robot, tool and cell) as MJCF for a viewer
(``python -m mujoco.viewer --mjcf OUT.xml``). Without a truth option the model holds the
scene's nominal sensor pose and plates; ``--truth-seed`` / ``--truth`` place them at a
twin's hidden truth instead (its joint offsets are in the ``calibration`` keyframe's qpos).
"""
from __future__ import annotations

from planecal.commands.value_options import seed


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the MuJoCo model (a name, planecal scenes, or a path)", reads=None)
    p.add_argument("--out", required=True, metavar="OUT.xml", help="MJCF file to write")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--truth-seed", type=seed, default=None,
                   help="place sensor and plates at the twin's truth drawn from this seed")
    g.add_argument("--truth", default=None, metavar="FILE",
                   help="place them at this truth (parameter file, e.g. rehearse --truth-out)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing OUT.xml planecal did not write")


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.io.outputs import MJCF_MARK
    return Files().read(args.truth, *scene_inputs(args.scene)).write(args.out, "--out", MJCF_MARK)


def run(args) -> int:
    from planecal.model.scene import load_scene
    from planecal.twin.export import export_scene

    scene = load_scene(args.scene)
    out = args.out  # checked before the run (``files``)
    export_scene(scene, out, args.truth, args.truth_seed)
    print(f"MJCF written to {out}; view it with: python -m mujoco.viewer --mjcf {out}")
    return 0
