"""A scene's MuJoCo model (robot + tool + cell) as MJCF for a viewer: ``planecal mjcf``.

Without a truth the model holds the scene's nominal sensor pose and plates; with one
(``truth``: a parameter file, or ``seed``: the twin's truth drawn from it) they are placed
at the twin's hidden truth (its joint offsets are in the ``calibration`` keyframe's qpos).
"""
from __future__ import annotations

from pathlib import Path

from planecal.io.outputs import MJCF_MARK
from planecal.model.scene import Scene, load_scene
from planecal.twin.mjcf import scene_spec, to_xml_exact
from planecal.twin.truth import resolve_truth

MARKER = MJCF_MARK.decode()  # first line of every file export_scene writes


def export_scene(scene: Scene | str, out, truth=None, seed: int | None = None) -> Path:
    scene = load_scene(scene) if not isinstance(scene, Scene) else scene
    world = None
    if truth is not None or seed is not None:
        world = resolve_truth(scene, truth, 0 if seed is None else seed)
    cal = scene.calibration_q
    if cal is not None and world is not None:
        cal = cal + world.params.joint_offsets
    spec = scene_spec(scene, None if world is None else world.params, calibration_qpos=cal,
                      kin=None if world is None else world.kinematics)
    spec.compile()  # fail here, not in the viewer
    what = ("nominal" if world is None else
            f"truth {truth}" if truth is not None else f"truth drawn from seed {seed}")
    out = Path(out)
    out.write_text(f"<!-- {MARKER}: scene {scene.name}, {what} -->\n" + to_xml_exact(spec))
    return out
