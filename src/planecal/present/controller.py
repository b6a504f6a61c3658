"""What a controller takes after a calibration, in one of three forms, written by one writer
for ``planecal export`` (a result file) and ``planecal history rollback`` (an earlier result
of a cell's history): ``write_controller_file``.

``fd11`` (the default, but for a UR): the values an operator enters into the FD11: the new
encoder offset of each joint, as the integer counts the controller takes
(``encoder.encoder_zero_counts``: qe0' = qe0 - g (C^-1 delta), the wrist coupling applied,
so a delta4 or delta5 moves the zero of q6 even while delta6 is fixed). Printed as a
table: joint, current qe0, new qe0', the change in counts, the rounding residual per joint
in urad, and its effect at the flange in um (at the scene's calibration position). The
file (JSON, ``planecal-fd11-offsets/1``) holds ``qe0_counts``: six integers. The current
values are the encoder offsets the samples were converted with: robot.json's
(``offset_counts``), or those the controller already holds (``current_qe0``).

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
(delta1 and delta6) keeps its current value, and the table says so. A result that fitted
delta1 or delta6 freely is refused (InputError): its value is a combination of frames,
not a joint zero. A whole-model result's geometry, base frame and compliance are no
encoder offsets either (``ur`` takes the geometry and base frame; compliance, which
depends on the pose, stays out of every format).
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError

FORMAT = "planecal-fd11-offsets/1"
OFFSETS_FORMAT = "planecal-joint-offsets/1"
FORMATS = ("fd11", "offsets", "ur")
SIGN = ("theta_j = theta0_j + q_j + delta_j, q_j the controller's joint angle: a controller "
        "whose reading grows by delta_j (its zero moved by -delta_j) matches the nominal model")
UR_SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


@dataclass(frozen=True)
class ControllerFile:
    """What to write: the ``fmt`` (None: the robot's controller's), where (``out``; None:
    print only), the encoder offsets the controller holds now (``current_qe0``; None:
    robot.json's), how the output names the result (``source``: its path, or "history
    entry N") and ``tag``, a hash of the result (the UR file's ``hash``)."""
    fmt: str | None
    out: Path | None
    current_qe0: np.ndarray | None
    source: str
    tag: str


def format_for(robot, fmt: str | None) -> str:
    """The format asked for, or the robot's controller's (ur for a UR, else fd11)."""
    return fmt or ("ur" if robot.controller_kind == "ur" else "fd11")


def write_controller_file(doc: dict, params, scene, req: ControllerFile) -> dict:
    """Print the controller's values of a result (``doc``, its ``params``) and write them
    to ``req.out`` (module docstring); returns what was written (the JSON document, or
    the UR file's segments and hash)."""
    robot = scene.robot
    fmt = format_for(robot, req.fmt)
    if fmt == "ur":
        return _ur(req, robot, params)
    delta, fitted, kept, label = controller_offsets(doc, params, req.source)
    extra = _model_corrections(params)
    if extra:
        print(f"note: {req.source} also corrects {extra} (level {label}); the controller "
              "takes joint offsets only, so they are not in these values: correct the "
              "program's targets with planecal compensate", file=sys.stderr)
    if fmt == "offsets":
        return _offsets(req, robot, delta, fitted, kept, label)
    return _fd11(req, robot, scene, delta, fitted, kept, label)


def controller_offsets(doc, params, where):
    """(offsets (6,), calibrated names, kept names, level label) the controller may take
    from a result (its ``encoder_offsets``, else its ``free``: a result of an older
    planecal); a parameter file without either: its six offsets as given."""
    from planecal.estimation.calibrate import encoder_offsets
    from planecal.model.layout import level1_layout

    from planecal.present.calibration import label as level_label
    label = level_label(doc)
    eo = doc.get("encoder_offsets")
    if isinstance(eo, dict):
        if eo.get("reason"):
            raise InputError(f"{where}: no encoder offsets for the controller: {eo['reason']}")
        return (np.array(eo["joint_offsets_rad"], float), list(eo["calibrated"]),
                list(eo["kept_initial"]), label)
    names = [f"delta{j}" for j in range(1, 7)]
    if not isinstance(doc.get("free"), list):
        return params.joint_offsets.copy(), names, [], "parameter file"
    from planecal.io.params import params_from_dict
    layout = level1_layout(params.n_planes)
    free = layout.mask([n for n in doc["free"] if n in names])
    initial = params_from_dict(doc["initial"], where) if isinstance(doc.get("initial"), dict) \
        else params.copy()
    if not isinstance(doc.get("initial"), dict):
        initial.joint_offsets = np.zeros(6)
    try:
        delta, fitted, kept = encoder_offsets(layout, free, params, initial)
    except InputError as e:
        raise InputError(f"{where}: no encoder offsets for the controller: {e}") from None
    return delta, fitted, kept, label


def _model_corrections(params) -> str:
    """What else than joint offsets a result corrects, in words ('' for nothing)."""
    parts = [what for what, on in (("the joint geometry", params.geometry.any()),
                                   ("the base frame", params.base.any()),
                                   ("the joint compliance", params.compliance.any()),
                                   ("the gear error", params.gear.any()),
                                   ("the backlash", params.backlash.any()),
                                   ("the laser's linearity", params.laser.any())) if on]
    return ", ".join(parts)


def _fd11(req: ControllerFile, robot, scene, delta, fitted, kept, label) -> dict:
    from planecal.io.params import save_json
    from planecal.model.encoder import counts_in_range, encoder_zero_counts

    qe0 = robot.qe0.astype(np.int64) if req.current_qe0 is None else req.current_qe0
    if not counts_in_range(robot, qe0):
        raise InputError(f"--current-qe0: {qe0.tolist()}: not encoder counts of {robot.name} "
                         f"(0 .. 2**{robot.encoder_bits} - 1)")
    q_ref = scene.calibration_q if scene.calibration_q is not None else np.zeros(6)
    new, residual, tcp = encoder_zero_counts(robot, delta, qe0, q_ref)
    if not counts_in_range(robot, new):
        raise InputError(f"{req.source}: the offsets move an encoder zero outside the "
                         f"{robot.encoder_bits}-bit range: {new.tolist()}")
    change = new - qe0
    print(f"FD11 encoder offsets for {robot.name} from {req.source} (calibration level {label})")
    print(f"{'joint':<6} {'delta_urad':>11} {'current':>9} {'new':>9} {'change':>8} "
          f"{'rounding_urad':>13}  offset")
    for j in range(6):
        name = f"delta{j + 1}"
        how = "calibrated" if name in fitted else _kept(robot, delta, j, int(change[j]))
        print(f"J{j + 1:<5} {delta[j] * 1e6:>11.1f} {qe0[j]:>9d} {new[j]:>9d} "
              f"{change[j]:>+8d} {residual[j] * 1e6:>13.3f}  {how}")
    print(f"rounding to whole counts moves the flange by {tcp * 1e6:.2f} um at the "
          f"calibration position of {scene.name}")
    doc = {"format": FORMAT, "robot": robot.name, "result": req.source,
           "qe0_counts": [int(v) for v in new],
           "current_qe0_counts": [int(v) for v in qe0],
           "change_counts": [int(v) for v in change],
           "joint_offsets_rad": [float(v) for v in delta],
           "calibrated": fitted, "kept_current": kept, "level": label,
           "rounding_residual_urad": [float(v * 1e6) for v in residual],
           "rounding_flange_um": tcp * 1e6}
    if req.out:
        save_json(req.out, doc)
        print(f"written to {req.out}")
    return doc


def _kept(robot, delta, j: int, change: int) -> str:
    """Why a joint not fitted still changes its encoder zero: the other joints' offsets
    through the wrist coupling (``qe0' = qe0 - g (C^-1 delta)``; on the MC70 q6 = x6 +
    b x4 + c x5: the zeros of J4's and J5's motors move q6 unless J6's zero follows)."""
    if change == 0:
        return "kept: not fitted (current value)"
    inv = np.linalg.inv(robot.coupling)
    via = [f"J{k + 1}'s" for k in range(len(delta)) if k != j and inv[j, k] and delta[k]]
    if not via:
        return f"kept: not fitted ({change:+d}: rounding)"
    return (f"kept: delta{j + 1} not fitted (0); {change:+d} from {' and '.join(via)} offsets "
            f"through the wrist coupling (their motors' zeros move q{j + 1} unless "
            f"J{j + 1}'s zero follows)")


def _offsets(req: ControllerFile, robot, delta, fitted, kept, label) -> dict:
    from planecal.io.params import save_json
    from planecal.io.urdf import joint_names

    names = joint_names(robot)
    print(f"joint offsets for {robot.name} from {req.source} (calibration level {label}); "
          f"sign: {SIGN}")
    print(f"{'joint':<22} {'delta_rad':>14} {'delta_mdeg':>11}  offset")
    for j in range(6):
        how = "calibrated" if f"delta{j + 1}" in fitted else "kept: not fitted (0)"
        print(f"{names[j]:<22} {delta[j]:>14.9f} {np.rad2deg(delta[j]) * 1e3:>11.3f}  {how}")
    doc = {"format": OFFSETS_FORMAT, "robot": robot.name, "sha256": robot.digest,
           "result": req.source, "joint_names": names,
           "joint_offsets_rad": [float(v) for v in delta], "sign": SIGN,
           "calibrated": fitted, "kept": kept, "level": label}
    if req.out:
        save_json(req.out, doc)
        print(f"written to {req.out}")
    return doc


def ur_kinematics(robot, params) -> dict:
    """The UR ROS driver's kinematics (module docstring) of the calibrated model."""
    from planecal.model.kinematics import rpy_angles
    from planecal.model.measurement import kinematics_of

    kin = kinematics_of(robot, params)
    if not np.allclose(kin.flange, np.eye(4), atol=1e-12):
        raise InputError(f"{robot.name}: the flange frame is not wrist 3's frame (F != I): "
                         "not a UR kinematics file's chain")
    out = {}
    for i, name in enumerate(UR_SEGMENTS):
        T = kin.joint_transform(i)
        if i == 0:
            T = kin.base @ T
        x, y, z = (float(v) for v in T[:3, 3])
        roll, pitch, yaw = rpy_angles(T[:3, :3])
        out[name] = {"x": x, "y": y, "z": z, "roll": roll, "pitch": pitch, "yaw": yaw}
    return out


def _ur(req: ControllerFile, robot, params) -> dict:
    if robot.controller_kind != "ur":
        raise InputError(f"--format ur: {robot.name}'s controller is not a UR (robot.json "
                         "controller.kind); --format offsets is for any robot")
    from planecal.io.urdf import not_in_urdf
    left = not_in_urdf(params)  # what a fixed chain cannot hold
    if left:
        print(f"note: {req.source} also fits {', '.join(left)}: not in a kinematics file, "
              "a fixed chain (planecal compensate corrects targets with the joints' errors)",
              file=sys.stderr)
    segs = ur_kinematics(robot, params)
    lines = [f"# UR ROS driver kinematics (ur_description's kinematics file) of {robot.name},",
             f"# calibrated by planecal from {req.source}; not the robot's factory "
             "calibration: the driver warns that its hash differs, as it does",
             "kinematics:"]
    for name, v in segs.items():
        lines.append(f"  {name}:")
        lines += [f"    {k}: {_yaml_num(x)}" for k, x in v.items()]
    tag = f"calib_planecal_{req.tag[:16]}"
    lines.append(f"  hash: {tag}")
    text = "\n".join(lines) + "\n"
    if req.out:
        _write_text(req.out, text)
        print(f"UR kinematics written to {req.out}")
    else:
        print(text, end="")
    return {"format": "ur-kinematics", "robot": robot.name, "result": req.source,
            "kinematics": segs, "hash": tag}


def _write_text(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file beside ``path`` and rename it over ``path``."""
    import os
    path = Path(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _yaml_num(v: float) -> str:
    return "0" if abs(v) < 1e-15 else repr(float(v))  # below that: the floating point's dust
