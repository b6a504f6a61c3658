"""planecal export RESULT.json [--format fd11|offsets|ur] [--out FILE] [--force]
[--current-qe0 C1,..,C6] [--scene S] [--history DB] [--note TEXT]

What a controller takes after a calibration, in one of three forms, written by
``planecal.present.controller`` (its docstring says what each holds): ``fd11`` (the
default, but for a UR) the new encoder offsets as the integer counts the FD11 takes, with
the rounding residual and the change from the current values (robot.json's, or
``--current-qe0``); ``offsets`` (any robot) the joint offsets in radians with their sign;
``ur`` the UR ROS driver's kinematics file. Only encoder offsets reach ``fd11`` and
``offsets``; a result that fitted delta1 or delta6 freely is refused (exit 2), and one made
for another robot than the scene's. The scene is the one the result records (its
provenance); a --scene that contradicts it is refused. A result that is not a calibration
(the fit did not converge, or could not identify a free parameter: its status is not
``converged``) is refused in one line with nothing written, in every format; --force
writes it anyway and says so on stderr. A whole-model result's geometry, base frame and
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
    from planecal.commands.cell_options import add_scene_argument
    p.add_argument("result", metavar="RESULT.json",
                   help="a calibration result (planecal calibrate --out) or parameter file")
    add_controller_arguments(p)
    add_scene_argument(p, "the robot and calibration position", reads="the result's provenance")
    add_history_arguments(p)


def files(args):
    """What the output guard checks before the run (``commands.io_options``)."""
    from planecal.commands.cell_options import result_scene_inputs
    from planecal.commands.io_options import Files
    from planecal.io.outputs import YAML_MARK
    from planecal.present.controller import FORMAT, OFFSETS_FORMAT
    f = Files().read(args.result, *result_scene_inputs(args.result, args.scene))
    return f.write(args.out, "--out", (FORMAT, OFFSETS_FORMAT, YAML_MARK))


def run(args) -> int:
    from planecal.jobs.exports import ExportRequest, export

    out = args.out  # checked before the run (``files``)
    hist = open_history(args, [args.result, out])
    qe0 = current_qe0(args.current_qe0)
    sha, against = result_link(hist, args.result)
    written, result = export(ExportRequest(args.result, sha, args.format, out, qe0, args.scene,
                                           args.force))
    prov = command_provenance(result.scene, [("result", args.result)])
    return record(hist, new_entry(args, "export", "ok", 0, prov,
                                  robot_sha256=result.scene.robot.digest, against=against,
                                  result_sha256=sha, summary=written,
                                  output=str(out) if out else None))
