"""planecal export RESULT.json [--format fd11|offsets|ur] [--out FILE] [--force]
[--current-qe0 C1,..,C6] [--scene S] [--history DB] [--note TEXT]

What a controller takes after a calibration, in one of three forms:

``fd11`` (the default, but for a UR): the values an operator enters into the FD11: the new
encoder offset of each joint, as the integer counts the controller takes
(``encoder.encoder_zero_counts``: qe0' = qe0 - g (C^-1 delta), the wrist coupling applied,
so a delta4 or delta5 moves the zero of q6 even while delta6 is fixed). Printed as a
table: joint, current qe0, new qe0', the change in counts, the rounding residual per joint
in urad, and its effect at the flange in um (at the scene's calibration position).
``--out`` writes them as JSON (``qe0_counts``: six integers). The current values are the
encoder offsets the samples were converted with: robot.json's (``offset_counts``), or
``--current-qe0`` when the controller already holds others.

``offsets`` (any robot): the joint offsets in radians, JSON (``planecal-joint-offsets/1``),
with their sign convention: the model's joint angle is theta_j = theta0_j + q_j +
delta_j, q_j the controller's reading, so a controller whose reading grows by delta_j
(its zero moved by -delta_j) matches the nominal model.

``ur`` (a robot whose controller is a UR, robot.json ``controller.kind``): the UR ROS
driver's kinematics file (ur_description's ``kinematics:`` YAML, as ur_calibration writes
it): per joint the origin x y z roll pitch yaw of its segment, ``kinematics.Kinematics``'
joint transform Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d) of the calibrated model (joint
offsets, and at level full the geometry and base frame; the first segment carries the
base frame), the URDF joint turning about z after it, and the flange (tool0) on
wrist_3_link. A ``hash`` names planecal's calibration: the driver warns that it is not the
robot's own factory calibration, as it is not.

Only encoder offsets reach ``fd11`` and ``offsets`` (``estimation.calibrate.
encoder_offsets``): the joint offsets the calibration fitted; a joint it kept fixed
(delta1 and delta6: no plane calibration can tell J1's zero from the plates' turn, nor
J6's from the sensor's roll) keeps its current value, and the table says so. A result
that fitted delta1 or delta6 freely is refused (exit 2): its value is a combination of
frames, not a joint zero. A whole-model result's geometry, base frame and compliance are
no encoder offsets either: ``planecal compensate`` corrects a program's targets with them
(``ur`` takes the geometry and base frame; compliance, which depends on the pose, stays
out of every format). A result made for another robot than the scene's is refused. The
calibrated URDF: ``planecal urdf --params RESULT.json``.

The export is recorded in the cell's history (docs/HISTORY.md), linked to the calibration
entry that wrote the result file (found by its SHA-256). ``planecal history rollback N``
writes the controller file of an earlier calibration with the same writer
(``planecal.present.controller``).
"""
from __future__ import annotations

from planecal.commands.controller_options import (add_controller_arguments, checked_out,
                                                  current_qe0)
from planecal.commands.history_options import (add_history_arguments, command_provenance,
                                               new_entry, open_history, record, result_link)


def add_arguments(p):
    p.add_argument("result", metavar="RESULT.json",
                   help="a calibration result (planecal calibrate --out) or parameter file")
    add_controller_arguments(p)
    p.add_argument("--scene", default="thesis_final",
                   help="scene: robot and calibration position (default %(default)s)")
    add_history_arguments(p)


def run(args) -> int:
    from planecal.formats.base import read_json
    from planecal.io.params import load_params
    from planecal.model.scene import load_scene
    from planecal.present.controller import ControllerFile, write_controller_file

    out = checked_out(args, [args.result])
    hist = open_history(args, [args.result, out])
    qe0 = current_qe0(args.current_qe0)
    scene = load_scene(args.scene)
    doc = read_json(args.result, "calibration result")
    params = load_params(args.result, scene.robot)
    sha, against = result_link(hist, args.result)
    req = ControllerFile(args.format, out, qe0, str(args.result), sha)
    written = write_controller_file(doc, params, scene, req)
    prov = command_provenance(scene, [("result", args.result)])
    record(hist, new_entry(args, "export", "ok", 0, prov, robot_sha256=scene.robot.digest,
                           against=against, result_sha256=sha, summary=written,
                           output=str(out) if out else None))
    return 0
