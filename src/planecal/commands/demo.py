"""planecal demo [--scene S] [--samples N] [--seed K] [--dir D] [--errors ideal|realistic|FILE]
[--level offsets|full|nonkinematic] [--compliance] [--rrd FILE] [--force]

The main job on the built-in twin: rehearse a sampling run on the default scene (the
thesis's final cell) in the world of an error profile (default realistic: a robot of the
MC70's class, with the errors a real one has) by running ``planecal rehearse``, calibrate
from the scene's nominal values exactly as ``planecal calibrate`` would (the same
calibration options), then show what the calibration did: the position
error before and after in the calibrated region (ISO 9283 AP on the same twin,
``studies.validation``), and the identified joint offsets against the twin's hidden truth
in units of the reported standard deviations, with why they can sit far from it.

Files land in ``--dir`` (default runs/demo): demo.tsv (+ sidecar), truth.json (with the
world, ``twin.profile.save_truth``), result.json. The demo replaces its own earlier files
(recognised by their format: a run sidecar, a parameter file, a result file) and nothing
else unless --force. Exit 0; 1 when the fit failed: not converged (it stops there), or a
parameter not identifiable (``planecal calibrate``'s failure; the demo still shows the
position error and the offsets, then exits 1).
"""
from __future__ import annotations

from planecal.commands.value_options import MAX_SAMPLES, count, seed


def add_arguments(p):
    from planecal.commands.cell_options import add_scene_argument
    add_scene_argument(p, "the demo's run", reads=None)
    p.add_argument("--samples", type=count(MAX_SAMPLES), default=150, help="samples to take (default %(default)s)")
    p.add_argument("--seed", type=seed, default=1, help="seed of poses and twin truth (default %(default)s)")
    p.add_argument("--dir", default="runs/demo", help="output directory (default %(default)s)")
    p.add_argument("--errors", default="realistic", metavar="ideal|realistic|FILE.json",
                   help="the twin's error profile (default %(default)s)")
    p.add_argument("--rrd", default=None, metavar="FILE",
                   help="also write Rerun recordings of the run and of the fit (a directory, "
                        "a file name, or 'auto' for recordings/)")
    p.add_argument("--force", action="store_true",
                   help="replace files in --dir even if the demo did not write them")
    from planecal.commands.calibration_options import add_calibration_arguments
    add_calibration_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the scene
    and the error profile; the folder (made with its parents) and the demo's files in it,
    each replaced only when the demo wrote it (its format; the sample file: its sidecar's)."""
    from planecal.commands.io_options import (SIDECAR_FORMAT, Files, profile_inputs,
                                              rrd_output, sample_file_is_ours, scene_inputs)
    from planecal.formats.params import PARAMS_FORMAT, RESULT_FORMAT
    f = Files().read(*scene_inputs(args.scene), *profile_inputs(args.errors, args.scene))
    members = (("demo.tsv", (sample_file_is_ours,)), ("demo.tsv.json", (SIDECAR_FORMAT,)),
               ("demo.tsv.lock", ()), ("truth.json", (PARAMS_FORMAT,)),
               ("result.json", (RESULT_FORMAT,)))
    f.write(args.dir, "--dir", folder=True, parents=True, members=members)
    rrd_output(f, args.rrd)
    return f


def run(args) -> int:
    from planecal.commands.calibration_options import calibration_settings
    from planecal.jobs.demo import DemoRequest, demo

    return demo(DemoRequest(lambda scene: calibration_settings(args, scene.robot, scene=scene),
                            args.scene, args.samples, args.seed, args.dir, args.errors,
                            args.rrd))
