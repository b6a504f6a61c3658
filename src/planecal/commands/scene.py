"""planecal scene new --robot NAME|DIR --out SCENE.json [--plates 1|3] [--name NAME]
[--floor-z Z]

A default cell for any robot (planecal.sampling.default_cell): plates in its reach at its
size, on stands and tilted towards it, the laser on its flange, no obstacles; the
placement chosen by how many of the sampling's own random poses are reachable and clear
of the cell, and a clear calibration position above the first plate. The scene names its
robot: a name under models/, or the robot's folder relative to the scene's folder (an
imported robot). Edit the file to match the real cell (docs/FORMATS.md).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from planecal.base.errors import InputError
from planecal.commands.value_options import bounded

FLOOR_LIMIT_M = 20.0  # the scene file's own bound on heights (formats.scene.CELL_M)


def add_arguments(p):
    p.add_argument("action", choices=("new",), help="new: write a default cell")
    p.add_argument("--robot", required=True, metavar="NAME|DIR",
                   help="the robot: a name under models/ or a folder holding robot.json")
    p.add_argument("--out", required=True, metavar="SCENE.json", help="the scene file to write")
    p.add_argument("--plates", type=int, choices=(1, 3), default=1,
                   help="one plate, or three at three orientations (default %(default)s)")
    p.add_argument("--name", help="the scene's name (default: the file's stem)")
    p.add_argument("--floor-z", type=bounded(-FLOOR_LIMIT_M, FLOOR_LIMIT_M, "m"), default=0.0,
                   metavar="M",
                   help="the floor (or table) height in the robot's base frame (default "
                        "%(default)s: the base stands on it)")


def robot_reference(given: str, out: Path) -> str:
    """What the scene file says for its robot: a models/ name as given, else the robot's
    folder relative to the scene's folder."""
    p = Path(given)
    if not p.suffix and len(p.parts) == 1 and not p.is_dir():
        return given
    folder = p.parent if p.suffix == ".json" else p
    rel = os.path.relpath(folder.resolve(), out.parent.resolve())
    return rel if os.sep in rel or rel.startswith(".") else f".{os.sep}{rel}"


def files(args):
    """What the output guard checks before the run (``commands.io_options``): the robot;
    the new scene file (never an existing one)."""
    from planecal.commands.io_options import Files
    from planecal.model.robot import robot_path
    f = Files().read(robot_path(args.robot))
    return f.write(args.out, "--out", new=True)


def run(args) -> int:
    from planecal.formats.base import dumps
    from planecal.model.robot import load_robot
    from planecal.sampling.default_cell import default_cell

    out = Path(args.out)  # a new file in a folder that exists (``files``)
    if out.suffix != ".json":
        raise InputError(f"--out {out}: a scene file ends in .json")
    robot = load_robot(args.robot)
    ref = robot_reference(args.robot, out)
    quiet = args.quiet
    doc = default_cell(robot, ref, args.name or out.stem, args.plates, out.parent,
                       args.floor_z, log=(lambda m: None) if quiet else
                       (lambda m: print(m, file=sys.stderr)))
    out.write_text(dumps(doc), encoding="utf-8")
    print(f"scene written to {out} (robot {ref}: {robot.name}; {args.plates} plate(s); "
          f"calibration position {doc['positions']['calibration_deg']} deg)")
    return 0
