"""planecal scene new --robot NAME|DIR --out SCENE.json [--plates 1|2|3] [--level L]
[--name NAME] [--floor-z Z]

A default cell for any robot (planecal.sampling.default_cell): plates in its reach at its
size, on stands and tilted towards it, the laser on its flange, no obstacles; the
placement chosen by how many of the sampling's own random poses are reachable and clear
of the cell, and a clear calibration position above the first plate. Then the cell is
checked on the poses its default run would use (planecal.studies.cell_check): the level
asked (``--level``, default offsets) must be identifiable with every parameter's
predicted std within the stated bound; plates are added (from ``--plates``, up to three)
until it is, else the command refuses with the reason. It states the predicted tool
error and the robot time per sample (a warning far above thesis_final's). The scene
names its robot: a name under models/, or the robot's folder relative to the scene's
folder (an imported robot). Edit the file to match the real cell (docs/FORMATS.md).
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from planecal.base.errors import InputError
from planecal.commands.value_options import bounded
from planecal.model.levels import LEVELS

FLOOR_LIMIT_M = 20.0  # the scene file's own bound on heights (formats.scene.CELL_M)


def add_arguments(p):
    p.add_argument("action", choices=("new",), help="new: write a default cell")
    p.add_argument("--robot", required=True, metavar="NAME|DIR",
                   help="the robot: a name under models/ or a folder holding robot.json")
    p.add_argument("--out", required=True, metavar="SCENE.json", help="the scene file to write")
    p.add_argument("--plates", type=int, choices=(1, 2, 3), default=1,
                   help="plates to start with, at as many orientations; more are added, up to "
                        "three, until the cell identifies --level (default %(default)s)")
    p.add_argument("--level", choices=LEVELS, default="offsets",
                   help="what the cell must identify on its default run's poses (default "
                        "%(default)s)")
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
    log = (lambda m: None) if quiet else (lambda m: print(m, file=sys.stderr))
    unchecked = _unchecked(robot)
    if unchecked:
        print(f"planecal scene: warning: {robot.name}'s links are not checked for collisions "
              f"({unchecked}): the cell's poses are checked for the tool and the plates only",
              file=sys.stderr)
    verdicts = []

    def judge(scene):
        from planecal.studies.cell_check import check_cell
        v = check_cell(scene, args.level)
        verdicts.append(v)
        log(("" if v.ok else "not enough: ") + v.line())
        return v.ok, v.line()

    doc = default_cell(robot, ref, args.name or out.stem, args.plates, out.parent,
                       args.floor_z, log=log, judge=judge)
    out.write_text(dumps(doc), encoding="utf-8")
    from planecal.studies.cell_check import REFERENCE_S_PER_SAMPLE
    v = verdicts[-1]
    print(f"scene written to {out} (robot {ref}: {robot.name}; {len(doc['plates'])} plate(s); "
          f"calibration position {doc['positions']['calibration_deg']} deg)")
    print(f"checked: {v.line()}")
    if v.slow():
        print(f"planecal scene: warning: {v.seconds_per_sample:.3g} s of robot time per sample "
              f"is far above thesis_final's {REFERENCE_S_PER_SAMPLE:g} s "
              "(the controller's step limit, robot.json's max_step_counts, sets the joints' "
              "speed; long moves between poses add to it): a run of 150 samples takes "
              f"{v.seconds_per_sample * 150 / 3600:.1f} h", file=sys.stderr)
    return 0


def _unchecked(robot) -> str | None:
    """Why the robot's links are not checked for collisions (shapes.json), or None."""
    from planecal.model.geometry import robot_shapes
    try:
        return robot_shapes(robot).unchecked
    except InputError:
        return None
