"""planecal layouts [--scene S] [--samples N] [--seed K] [--free NAMES] [--out L.json]

For 1, 2 and 3 of the scene's plates (every subset), the parameters random collision-free
poses on those plates can identify (a rank test of the distance Jacobian: the base set,
and each excluded parameter with its reason) and the predicted std of each identifiable
one at the twin's noise (planecal.studies.layouts). In the table, n1 is the first plate
of that layout, n2 the second. --level offsets: level 1's parameters (joint offsets,
sensor pose, planes); --level full: the whole kinematic model's (level 2).
"""
from __future__ import annotations

from planecal.base.errors import InputError
from planecal.commands.value_options import seed


def add_arguments(p):
    p.add_argument("--scene", default="three_plates", help="scene (default %(default)s)")
    p.add_argument("--samples", type=int, default=150,
                   help="poses per layout (default %(default)s)")
    p.add_argument("--seed", type=seed, default=0, help="pose draw seed (default %(default)s)")
    p.add_argument("--free", default=None,
                   help="parameters to test, comma-separated, or 'all' (default: the "
                        "calibration's default free set, delta1 and delta6 fixed)")
    p.add_argument("--level", choices=["offsets", "full"], default="offsets",
                   help="the model's parameters: level 1's (joint offsets, sensor, planes) or "
                        "the whole kinematic model's (planecal.estimation.calibrate, level 2)")
    p.add_argument("--tol", type=float, default=1e-6,
                   help="rank threshold on the scaled singular values (default %(default)g)")
    p.add_argument("--out", help="write the study (JSON, planecal-layouts/1) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier layouts study")


def run(args) -> int:
    from planecal.safety.collision import CollisionWorld
    from planecal.model.layout import level1_layout
    from planecal.io.outputs import check_output
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.studies.layouts import FORMAT, format_layouts, layout_study

    out = check_output(args.out, [], FORMAT, args.force) if args.out else None
    if not 0 < args.tol < 1:
        raise InputError(f"--tol must be in (0, 1), got {args.tol:g}")
    scene = load_scene(args.scene)
    layout_for = level1_layout if args.level == "offsets" else _full_layouts(scene.robot)
    res = layout_study(scene, layout_for, args.free, args.samples, args.seed,
                       CollisionWorld(scene), tol=args.tol)
    res["level"] = args.level
    print(format_layouts(res, layout_for(len(scene.plates)).display))
    if out:
        save_json(out, res)
        print(f"study written to {out}")
    return 0


def _full_layouts(robot):
    """n_planes -> the whole model's layout (level 2's ``calibration.layout_for``)."""
    try:
        from planecal.estimation.calibrate import layout_for
    except ModuleNotFoundError:
        raise InputError("--level full: this planecal has no whole-model calibration "
                         "(planecal.estimation.calibrate)") from None
    return lambda n: layout_for(robot, n, "full")
