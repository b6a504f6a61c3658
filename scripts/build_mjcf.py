#!/usr/bin/env python
"""Write models/<robot>/<robot>.xml (robot-only MJCF) from models/<robot>/robot.json.

usage: python scripts/build_mjcf.py [ROBOT] [--check]
--check exits 1 (writing nothing) when the committed file differs from what the
builder produces now.
"""
from __future__ import annotations

import argparse
import sys

from planecal.errors import InputError
from planecal.robot import load_robot
from planecal.twin.mjcf import robot_xml, robot_xml_path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("robot", nargs="?", default="mc70")
    ap.add_argument("--check", action="store_true", help="compare, do not write")
    args = ap.parse_args(argv)
    try:
        robot = load_robot(args.robot)
        text = robot_xml(robot)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    path = robot_xml_path(robot)
    if args.check:
        same = path.exists() and path.read_text() == text
        print(f"{path}: {'up to date' if same else 'differs from the builder output'}")
        return 0 if same else 1
    path.write_text(text)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
