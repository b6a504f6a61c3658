"""Public six-axis arms (issue 30) from import to a cell that identifies: what the import
checks and says, the realistic twin of an arm whose base frame is not the identity, and
``scene new`` on arms whose collision pieces always touch. The arms: tests/public_robots.py."""
import json

import numpy as np
import pytest

pytest.importorskip("yourdfpy")

from planecal.model.kinematics import frame_error  # noqa: E402
from planecal.model.robot import load_robot  # noqa: E402


def _rotation_angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


def test_realistic_twin_keeps_a_turned_base_frame(public_robots):
    """The KR 210's imported base frame is turned 159.6 deg about z; the realistic
    profile's true base is that frame moved by the profile's small error, never the
    error alone (before: the twin's base was turned 159.6 deg, every pose out of range)."""
    from planecal.twin.profile import draw_geometry, load_profile
    robot = load_robot(public_robots.get("kr210")[0])
    nom = robot.kinematics.base
    assert _rotation_angle(nom[:3, :3]) > np.deg2rad(150)
    profile = load_profile("realistic", robot)
    g = profile.doc.geometry
    for seed in range(5):
        true = draw_geometry(robot, profile, np.random.default_rng(seed)).base
        E = true @ np.linalg.inv(nom)
        # six std of the profile's own draw, per axis
        assert _rotation_angle(E[:3, :3]) < 6 * np.sqrt(3) * g.base.rotation_rad
        assert np.linalg.norm(E[:3, 3]) < 6 * np.sqrt(3) * g.base.translation_m
