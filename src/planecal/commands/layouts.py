"""planecal layouts [--scene S] [--samples N] [--seed K] [--level offsets|full|nonkinematic] [--compliance]
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
from planecal.commands.value_options import MAX_SAMPLES, count, seed


def add_arguments(p):
    from planecal.commands.calibration_options import add_calibration_arguments
    p.add_argument("--scene", default="three_plates", help="scene (default %(default)s)")
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150,
                   help="poses per layout (default %(default)s)")
    p.add_argument("--seed", type=seed, default=0, help="pose draw seed (default %(default)s)")
    add_calibration_arguments(p)
    p.add_argument("--tol", type=float, default=1e-6,
                   help="base set threshold on |R_kk| / |R_00| of the pivoted QR "
                        "(default %(default)g)")
    p.add_argument("--out", help="write the study (JSON, planecal-layouts/1) here")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not an earlier layouts study")


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.studies.layouts import FORMAT
    return Files().read(*scene_inputs(args.scene)).write(args.out, "--out", FORMAT)


def run(args) -> int:
    import shutil
    from dataclasses import replace

    from planecal.commands.calibration_options import calibration_settings
    from planecal.io.params import save_json
    from planecal.model.scene import load_scene
    from planecal.safety.collision import CollisionWorld
    from planecal.studies.layouts import layout_study
    from planecal.present.layouts import format_layouts
    from planecal.model.layout import display_of

    out = args.out  # checked before the run (``files``)
    if not 0 < args.tol < 1:
        raise InputError(f"--tol must be in (0, 1), got {args.tol:g}")
    scene = load_scene(args.scene)
    settings = replace(calibration_settings(args, scene.robot, scene=scene),
                       base_tolerance=args.tol)
    res = layout_study(scene, settings, args.samples, args.seed, CollisionWorld(scene))
    res["level"] = settings.label
    print(format_layouts(res, display_of, shutil.get_terminal_size((100, 24)).columns))
    if out:
        save_json(out, res)
        print(f"study written to {out}")
    return 0
