"""planecal export RESULT.json [--format fd11|offsets|ur] [--out FILE] [--force]
[--current-qe0 C1,..,C6] [--scene S] [--history DB] [--note TEXT]

What a controller takes after a calibration, in one of three forms, written by
``planecal.present.controller`` (its docstring says what each holds): ``fd11`` (the
default, but for a UR) the new encoder offsets as the integer counts the FD11 takes, with
the rounding residual and the change from the current values (robot.json's, or
``--current-qe0``); ``offsets`` (any robot) the joint offsets in radians with their sign;
``ur`` the UR ROS driver's kinematics file. Only encoder offsets reach ``fd11`` and
``offsets``; a result that fitted delta1 or delta6 freely is refused (exit 2), one made
for another robot than the scene's, and one whose verdict found it no better than a simpler
level (``estimation.verdict``; ``--force`` writes it). A whole-model result's geometry, base frame and
compliance: ``planecal compensate`` corrects a program's targets with them; the calibrated
URDF: ``planecal urdf --params RESULT.json``. ``--out`` goes through the output guard
(``--force`` to replace a file planecal did not write).

The export is recorded in the cell's history (docs/HISTORY.md), linked to the calibration
entry that wrote the result file (found by its SHA-256). ``planecal history rollback N``
writes the controller file of an earlier calibration with the same writer
(``planecal.present.controller``).
"""
from __future__ import annotations

from planecal.commands.controller_options import add_controller_arguments, current_qe0
from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               new_entry, open_history, record, result_link)


def add_arguments(p):
    p.add_argument("result", metavar="RESULT.json",
                   help="a calibration result (planecal calibrate --out) or parameter file")
    add_controller_arguments(p)
    p.add_argument("--scene", default="thesis_final",
                   help="scene: robot and calibration position (default %(default)s)")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.io_options import Files, scene_inputs
    from planecal.io.outputs import YAML_MARK
    from planecal.present.controller import FORMAT, OFFSETS_FORMAT
    f = Files().read(args.result, *scene_inputs(args.scene))
    return f.write(args.out, "--out", (FORMAT, OFFSETS_FORMAT, YAML_MARK))


def run(args) -> int:
    from planecal.commands.controller_options import refuse_worse
    from planecal.formats.base import read_json
    from planecal.io.params import load_params
    from planecal.model.scene import load_scene
    from planecal.present.controller import ControllerFile, write_controller_file

    out = args.out  # checked before the run (``files``)
    hist = open_history(args, [args.result, out])
    qe0 = current_qe0(args.current_qe0)
    scene = load_scene(args.scene)
    doc = read_json(args.result, "calibration result")
    refuse_worse(doc, args.result, args.force)
    params = load_params(args.result, scene.robot)
    sha, against = result_link(hist, args.result)
    req = ControllerFile(args.format, out, qe0, str(args.result), sha)
    written = write_controller_file(doc, params, scene, req)
    prov = command_provenance(scene, [("result", args.result)])
    record(hist, new_entry(args, "export", "ok", 0, prov, robot_sha256=scene.robot.digest,
                           against=against, result_sha256=sha, summary=written,
                           output=str(out) if out else None))
    return 0
