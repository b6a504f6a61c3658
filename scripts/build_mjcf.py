#!/usr/bin/env python
"""Write models/<robot>/<robot>.xml (robot-only MJCF) from models/<robot>/robot.json,
and models/<robot>/scene.xml (floor and light around an <include> of it).

usage: python scripts/build_mjcf.py [ROBOT] [--check]
--check exits 1 (writing nothing) when the committed file differs from what the
builder produces now.
"""
from __future__ import annotations

import argparse
import sys

from planecal.base.errors import InputError
from planecal.model.robot import load_robot
from planecal.twin.mjcf import robot_xml, robot_xml_path, view_scene_path, view_scene_xml


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("robot", nargs="?", default="mc70")
    ap.add_argument("--check", action="store_true", help="compare, do not write")
    args = ap.parse_args(argv)
    try:
        robot = load_robot(args.robot)
        files = [(robot_xml_path(robot), robot_xml(robot)),
                 (view_scene_path(robot), view_scene_xml(robot))]
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    status = 0
    for path, text in files:
        if args.check:
            same = path.exists() and path.read_text() == text
            print(f"{path}: {'up to date' if same else 'differs from the builder output'}")
            status |= 0 if same else 1
        else:
            path.write_text(text)
            print(f"wrote {path}")
    return status


if __name__ == "__main__":
    sys.exit(main())
