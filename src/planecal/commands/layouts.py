"""planecal layouts [--scene S] [--samples N] [--seed K] [--level offsets|full] [--compliance]
[--free NAMES] [--out L.json]

For 1, 2 and 3 of the scene's plates (every subset), the parameters random collision-free
poses on those plates can identify and the predicted std of each at the twin's noise
(planecal.studies.layouts): the calibration's own base-set selection
(planecal.estimation.calibrate.base_set) with the options every calibrating command takes,
so a parameter listed here is one ``planecal calibrate`` fits from such poses. In the
table, n1 is the first plate of that layout, n2 the second.
"""
from __future__ import annotations

from planecal.base.errors import InputError
from planecal.commands.value_options import seed


def add_arguments(p):
    from planecal.commands.calibration_options import add_calibration_arguments
    p.add_argument("--scene", default="three_plates", help="scene (default %(default)s)")
    p.add_argument("--samples", type=int, default=150,
                   help="poses per layout (default %(default)s)")
    p.add_argument("--seed", type=seed, default=0, help="pose draw seed (default %(default)s)")
    add_calibration_arguments(p)
    p.add_argument("--tol", type=float, default=1e-6,
                   help="base set threshold on |R_kk| / |R_00| of the pivoted QR "
                        "(default %(default)g)")
    p.add_argument("--out", help="write the study (JSON, planecal-layouts/1) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier layouts study")


def run(args) -> int:
    from dataclasses import replace

    from planecal.commands.calibration_options import calibration_settings
    from planecal.io.outputs import check_output
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.layouts import FORMAT, layout_study
    from planecal.present.layouts import format_layouts
    from planecal.model.layout import display_of

    out = check_output(args.out, [], FORMAT, args.force) if args.out else None
    if not 0 < args.tol < 1:
        raise InputError(f"--tol must be in (0, 1), got {args.tol:g}")
    scene = load_scene(args.scene)
    settings = replace(calibration_settings(args, scene.robot), base_tolerance=args.tol)
    res = layout_study(scene, settings, args.samples, args.seed, CollisionWorld(scene))
    res["level"] = settings.label
    print(format_layouts(res, display_of))
    if out:
        save_json(out, res)
        print(f"study written to {out}")
    return 0
