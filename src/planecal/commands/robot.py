"""planecal robot import ROBOT.urdf --out DIR [options] | planecal robot show NAME|DIR

``import``: a URDF made into a planecal robot description in the new folder DIR:
robot.json (the chain as modified DH with Hayati's beta, base and flange frames; joint
limits; an encoder and controller model; the URDF's masses), shapes.json and meshes/ (its
visual and collision elements). The import checks the written description's flange
against the URDF's own forward kinematics (yourdfpy) over 200 random poses and refuses
above 1e-9 m; what it cannot take (a branching tree, a prismatic or continuous joint, a
missing limit) is refused with a one-line reason naming the joint (exit 2). Then
``planecal scene new --robot DIR`` gives it a cell. See planecal.io.urdf_import and
docs/ROBOTS.md.

``show``: a robot description (a name under models/ or a folder): its chain, limits,
inverse kinematics, shapes, masses and error profiles.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from planecal.base.errors import InputError
from planecal.commands.value_options import count

ACTIONS = ("import", "show")


def add_arguments(p):
    p.add_argument("action", choices=ACTIONS, help="import a URDF, or show a description")
    p.add_argument("source", metavar="URDF|ROBOT",
                   help="import: the URDF file; show: a robot name (models/) or folder")
    p.add_argument("--out", metavar="DIR", help="import: the new folder to write")
    p.add_argument("--name", help="import: the robot's name (default: the URDF's)")
    p.add_argument("--tip", metavar="LINK",
                   help="import: the flange link (default: the end of the fixed joints after "
                        "the sixth joint; tool0 where they branch)")
    p.add_argument("--package", metavar="NAME=DIR", action="append", default=[],
                   help="import: where package://NAME/ meshes are (repeatable)")
    p.add_argument("--visual", choices=("urdf", "collision"), default="urdf",
                   help="import: draw the URDF's visual elements, or its collision ones "
                        "(visual meshes missing or too heavy) (default %(default)s)")
    p.add_argument("--counts-per-rev", type=count(2**31), default=1 << 20, metavar="N",
                   help="import: encoder counts per joint revolution (default %(default)s)")
    p.add_argument("--coupling", metavar="ROW,COL,VALUE", action="append", default=[],
                   help="import: a coupling entry C[row, col] = value of q = C x (1-based; "
                        "repeatable; default: none, C = I)")
    p.add_argument("--encoder-bits", type=count(62), default=24, metavar="B",
                   help="import: encoder width (default %(default)s)")
    p.add_argument("--tick-s", type=float, default=0.008, metavar="S",
                   help="import: the controller's tick (default %(default)s s)")
    p.add_argument("--speed-fraction", type=float, default=0.1, metavar="F",
                   help="import: the step limit as this fraction of the slowest joint's URDF "
                        "velocity (default %(default)s)")
    p.add_argument("--max-step-counts", type=count(2**31), metavar="N",
                   help="import: the step limit per tick (default: from --speed-fraction)")
    p.add_argument("--trip-step-counts", type=count(2**31), metavar="N",
                   help="import: the controller's trip limit per tick (default: the slowest "
                        "joint's URDF velocity)")
    p.add_argument("--repeatability-mm", type=float, default=None, metavar="MM",
                   help="import: the datasheet's pose repeatability, +- mm at the flange "
                        "(default: none written; the robot then gets the MC70's 0.07 mm "
                        "scaled by its reach, and robot show says so)")
    p.add_argument("--payload-kg", type=float, metavar="KG",
                   help="import: the rated payload (the generic error profile scales by it)")
    p.add_argument("--snap-rad", type=float, default=None, metavar="RAD",
                   help="import: an rpy of the chain's joint origins this close to a multiple "
                        "of 90 deg is taken as it, the URDF's rounding (default 1e-4; 0 keeps "
                        "every angle as written)")
    p.add_argument("--controller", choices=("fd11", "ur"),
                   help="import: the controller family, for planecal export's formats")
    p.add_argument("--json", action="store_true", help="show: print as JSON")


def _packages(items: list[str]) -> dict:
    out = {}
    for item in items:
        name, sep, folder = item.partition("=")
        if not sep or not name or not folder:
            raise InputError(f"--package {item!r}: expected NAME=DIR")
        out[name] = folder
    return out


def _coupling(items: list[str]) -> list:
    out = []
    for item in items:
        parts = item.split(",")
        try:
            row, col, value = int(parts[0]), int(parts[1]), float(parts[2])
        except (ValueError, IndexError):
            raise InputError(f"--coupling {item!r}: expected ROW,COL,VALUE (e.g. 6,5,-0.0169)") from None
        if len(parts) != 3 or not (1 <= row <= 6 and 1 <= col <= 6):
            raise InputError(f"--coupling {item!r}: expected ROW,COL,VALUE with ROW and COL "
                             "joint numbers 1..6")
        out.append([row, col, value])
    return out


def files(args):
    """What the output guard checks before an import (``commands.io_options``): the URDF
    and the package folders; the new robot folder (never an existing one)."""
    from planecal.commands.io_options import Files
    f = Files()
    if args.action == "import":
        f.read(args.source, *(folder for _, folder in _packages(args.package).items()))
        f.write(args.out, "--out", folder=True, new=True)
    return f


IMPORT_ONLY = ("out", "name", "tip", "package", "coupling", "max_step_counts",
               "trip_step_counts", "payload_kg", "controller", "snap_rad")


def run(args) -> int:
    if args.action == "show":
        given = [o for o in IMPORT_ONLY if getattr(args, o) not in (None, [])]
        if given:
            raise InputError(f"--{given[0].replace('_', '-')}: an option of robot import; "
                             "robot show reads and writes nothing else")
        return _show(args)
    if args.json:
        raise InputError("--json: an option of robot show")
    return _import(args)


def _import(args) -> int:
    from planecal.io import urdf_description as ud
    from planecal.io import urdf_import as ui
    from planecal.model.geometry import robot_link_meshes
    from planecal.model.robot import load_robot

    if not args.out:
        raise InputError("robot import: give --out DIR, the new folder to write")
    out = Path(args.out)  # a new folder in one that exists (checked before the run: ``files``)
    _check_numbers(args)
    coupling = _coupling(args.coupling)
    path = Path(args.source)
    imp, u = ui.import_chain(path, args.tip, ui.SNAP_RAD if args.snap_rad is None
                             else args.snap_rad)
    ui.shapes_and_masses(path, imp, u, _packages(args.package),
                         "collision" if args.visual == "collision" else "visual")
    enc = ud.EncoderSettings(args.counts_per_rev, args.encoder_bits, args.tick_s,
                             args.speed_fraction, args.max_step_counts, args.trip_step_counts,
                             args.repeatability_mm, args.payload_kg, args.controller)
    doc = ud.description(path, imp, args.name or imp.name, enc)
    doc["encoder"]["coupling"] = coupling  # checked (non-singular C) with the rest on load
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        ui.write(tmp, doc, ui.shapes_document(path, imp), imp)
        try:  # what the files say, validated; a problem named in the URDF's terms
            robot = load_robot(tmp)
            parts = {k: len(robot_link_meshes(robot, k)) for k in ("visual", "collision")}
        except InputError as e:
            raise InputError(str(e).replace(str(tmp), f"{path} (as {out})")) from None
        worst = ui.check_flange(path, imp, robot.kinematics)
        clear = _allow_touching(tmp, robot, parts, imp) if parts["collision"] else None
        os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    robot = load_robot(out)
    _summary(robot, imp, worst, parts, clear)
    print(f"written to {out}/ (robot.json, shapes.json, meshes/); next: planecal scene new "
          f"--robot {out} --out CELL.json")
    return 0


def _check_numbers(args) -> None:
    """The import's numeric options: finite and in range (one line each)."""
    import math
    checks = (("--speed-fraction", args.speed_fraction, 0, 1, False),
              ("--tick-s", args.tick_s, 0, 1, False),
              ("--repeatability-mm", args.repeatability_mm, 0, 5, True),
              ("--payload-kg", args.payload_kg, 0, 10_000, True),
              ("--snap-rad", args.snap_rad, 0, 0.01, True))
    for flag, v, lo, hi, low_ok in checks:
        if v is None:
            continue
        if not (math.isfinite(v) and (lo <= v if low_ok else lo < v) and v <= hi):
            raise InputError(f"{flag} {v:g}: must be a number in {'[' if low_ok else '('}"
                             f"{lo:g}, {hi:g}]")


def _allow_touching(folder: Path, robot, parts: dict, imp) -> tuple:
    """Allow, in the new shapes.json, the collision pieces that touch in every sampled
    configuration (``safety.self_contact``), each with its reason printed and recorded:
    (clear share before, after, pairs allowed)."""
    import json

    from planecal.formats.base import dumps
    from planecal.safety.self_contact import SAMPLES, always_touching
    pairs, before, after = always_touching(robot)
    if pairs:
        f = folder / "shapes.json"
        doc = json.loads(f.read_text(encoding="utf-8"))
        doc["allowed_pairs"] = doc.get("allowed_pairs", []) + pairs
        f.write_text(dumps(doc), encoding="utf-8")
        for p in pairs:
            imp.warnings.append(f"collision pieces {p['pieces'][0]} and {p['pieces'][1]}: "
                                f"allowed (not checked): {p['why']}")
    return before, after, len(pairs), SAMPLES


def _summary(robot, imp, worst: float, parts: dict, clear) -> None:
    import sys

    from planecal.model.ik import kinematic_family, numeric_reason, solver_name
    print(f"{robot.name}: six revolute joints {', '.join(robot.joint_names)}; base link "
          f"{imp.root!r}, flange link {imp.tip!r}")
    _chain_table(robot)
    print(f"flange against the URDF (yourdfpy) over 200 random poses: {worst:.2g} m at most")
    name = solver_name(robot)
    print(f"inverse kinematics: {name} ({kinematic_family(robot)})"
          + (f": {numeric_reason(robot)}" if name == "numeric" else ""))
    print(f"shapes: {parts['visual']} visual, {parts['collision']} collision pieces; "
          f"masses: {len(robot.masses)}")
    if clear is not None:
        before, after, n, samples = clear
        print(f"self-collision: {before:.0%} of {samples} random configurations clear of the "
              f"arm itself" + (f", {after:.0%} with the {n} pair(s) found allowed"
                               if n else ""))
    print(repeatability_line(robot))
    for note in imp.notes:
        print(f"note: {note}")
    for w in imp.warnings:
        print(f"planecal robot: warning: {w}", file=sys.stderr)


def repeatability_line(robot) -> str:
    """Where the robot's repeatability comes from, in one line."""
    from planecal.model.robot import REFERENCE_REPEATABILITY_MM
    mm = robot.repeatability_m * 1e3
    if robot.repeatability_given:
        return f"repeatability: +-{mm:.3g} mm (robot.json)"
    return (f"repeatability: +-{mm:.3g} mm, a default: robot.json states none, so the MC70's "
            f"{REFERENCE_REPEATABILITY_MM:g} mm scaled by the reach (the twin's noise, the "
            "generic error profile, plan and layouts use it; put the datasheet's in "
            "robot.json's repeatability_mm)")


def collision_status(robot) -> str:
    """What the collision checker checks of the arm, in one line (shapes.json)."""
    import json

    from planecal.model.geometry import robot_shapes, shapes_path
    try:
        shapes = robot_shapes(robot)
    except InputError:
        return "NOT CHECKED: no shapes.json (the twin and the checker need one)"
    if shapes.unchecked:
        return f"NOT CHECKED: {shapes.unchecked}"
    doc = json.loads(shapes_path(robot).read_text(encoding="utf-8"))
    hulls = [p["name"] for p in doc["pieces"] if "visual element" in (p.get("what") or "")]
    return (f"checked: {sum(p.use in ('both', 'collision') for p in shapes.pieces)} pieces, "
            f"{len(shapes.allowed_pairs)} pair(s) allowed (shapes.json says why)"
            + (f"; {len(hulls)} envelope(s) are visual hulls (the URDF has no <collision> "
               "there)" if hulls else ""))


def _chain_table(robot) -> None:
    k = robot.kinematics
    print(f"{'joint':<6} {'alpha_deg':>10} {'a_mm':>9} {'beta_deg':>9} {'theta0_deg':>10} "
          f"{'d_mm':>9} {'limits_deg':>18}")
    for i in range(robot.n_joints):
        lo, hi = np.rad2deg(robot.limits[i])
        print(f"J{i + 1:<5} {np.rad2deg(k.alpha[i]):>10.4f} {k.a[i] * 1e3:>9.3f} "
              f"{np.rad2deg(k.beta[i]):>9.4f} {np.rad2deg(k.theta[i]):>10.4f} "
              f"{k.d[i] * 1e3:>9.3f} {lo:>8.1f} {hi:>8.1f}")
    for name, T in (("base", k.base), ("flange", k.flange)):
        if not np.allclose(T, np.eye(4), atol=1e-12):
            print(f"{name} frame: xyz {np.round(T[:3, 3] * 1e3, 3).tolist()} mm, rotation "
                  f"{np.round(T[:3, :3], 6).tolist()}")


def _show(args) -> int:
    import json

    from planecal.model.geometry import robot_link_meshes
    from planecal.model.ik import kinematic_family, numeric_reason, solver_name
    from planecal.model.kinematics import reach_m
    from planecal.model.robot import load_robot
    from planecal.twin.profile import profile_source

    robot = load_robot(args.source)
    try:
        parts = {k: len(robot_link_meshes(robot, k)) for k in ("visual", "collision")}
    except InputError:
        parts = None
    info = {"name": robot.name, "file": str(robot.source), "sha256": robot.digest,
            "ik": solver_name(robot), "family": kinematic_family(robot),
            "reach_m": reach_m(robot.kinematics), "masses": len(robot.masses),
            "shapes": parts, "errors": {p: profile_source(p, robot) for p in ("ideal", "realistic")},
            "repeatability_mm": robot.repeatability_m * 1e3,
            "repeatability_source": "robot.json" if robot.repeatability_given else "default",
            "collision": collision_status(robot)}
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{robot.name} ({robot.source})")
    _chain_table(robot)
    print(f"reach <= {info['reach_m']:.3f} m; inverse kinematics: {info['ik']} ({info['family']})"
          + (f": {numeric_reason(robot)}" if info["ik"] == "numeric" else ""))
    print("shapes: " + ("none (no shapes.json: the twin and the checker need them)" if parts is None
                        else f"{parts['visual']} visual, {parts['collision']} collision pieces")
          + f"; masses: {len(robot.masses)}")
    print(f"collision: {info['collision']}")
    print(repeatability_line(robot))
    for p, src in info["errors"].items():
        print(f"error profile {p}: {src}")
    return 0
