"""The options of a command that writes a controller file (``planecal export``, ``planecal
history rollback``): the format, the controller's current encoder offsets, the output and
its guard; the writer is ``planecal.present.controller``."""
from __future__ import annotations

import numpy as np

from planecal.base.errors import InputError


def add_controller_arguments(p) -> None:
    from planecal.present.controller import FORMATS

    p.add_argument("--format", choices=FORMATS, default=None,
                   help="fd11: encoder offset counts (default); offsets: joint offsets in rad "
                        "(any robot); ur: the UR ROS driver's kinematics YAML (default for "
                        "a UR)")
    p.add_argument("--out", metavar="FILE", help="write the values here (JSON; YAML for ur)")
    p.add_argument("--force", action="store_true",
                   help="replace --out even if it is not a controller file planecal wrote, and "
                        "write a result whose verdict found it no better than a simpler level")
    p.add_argument("--current-qe0", metavar="C1,...,C6", default=None,
                   help="the encoder offsets the samples were taken with, if not robot.json's")


def current_qe0(text: str | None) -> np.ndarray | None:
    """--current-qe0: six integers, or None."""
    if text is None:
        return None
    try:
        v = [int(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"--current-qe0: expected six integers separated by commas, got "
                         f"{text[:60]!r}") from None
    if len(v) != 6:
        raise InputError(f"--current-qe0: expected six integers, got {len(v)}")
    if any(abs(c) >= 2**62 for c in v):  # the robot's encoder range: the writer's check
        raise InputError(f"--current-qe0: {text[:60]}: not encoder counts")
    return np.array(v, np.int64)


def refuse_worse(doc, path, force: bool) -> None:
    """InputError naming ``path`` where the result's verdict refuses it
    (``estimation.verdict.refusal``: no better than a simpler level) and ``force`` is not
    given: the check every writer of a controller file (export, urdf, compensate) makes."""
    from planecal.estimation.verdict import refusal
    why = refusal(doc)
    if why and not force:
        raise InputError(f"{path}: {why}")
