"""`planecal sample` against emulators, the command line every wire test runs.

The link's defaults are the cell's: resend after 20 ms without a reply, give up after
0.5 s of silence, give a laser request up after 0.1 s and let a tick wait 5 ms for the
laser's reply. Behind the emulators the replies come from threads of the test's own
process (or another process), and on a loaded machine such a thread can wait for the CPU
far longer than that: the link then counts a lost reply and resends, the emulator ticks
the twin once more (an extra hold tick, one more laser-noise draw), a tick goes without
its reading, a reply a tick old can even read as a released switch, and a silence ends
the run. Tests that are not about timing therefore run with intervals no stall reaches:
a resend after 1 s, silence 20 s, a first contact given a minute (an emulator in another
process answers once its twin is built), a laser request given a second and each tick
waiting for its reading (``--laser-wait-s`` = the laser's timeout), so a run's samples
are the same on any machine under any load. Tests of resending, silence or boot timeouts pass
their own flags after these (argparse keeps the last).
"""
from __future__ import annotations

RESEND_S = 1.0
SILENCE_S = 20.0
BOOT_S = 60.0  # a controller in another process answers once its twin is built and warm
LASER_TIMEOUT_S = 1.0


def sample_argv(port, tty, out, *extra, seed: int = 2) -> list[str]:
    """argv of `planecal sample` against the FD11 emulator on UDP ``port`` and the laser
    emulator on ``tty``, writing ``out``; ``extra`` flags come last."""
    return ["sample", "--rt", "127.0.0.1", "--rt-port", str(port), "--local-port", "0",
            "--rt-tick-s", "0", "--rt-resend-s", str(RESEND_S), "--rt-silence-s", str(SILENCE_S),
            "--rt-boot-timeout-s", str(BOOT_S),
            "--laser", str(tty), "--laser-timeout-s", str(LASER_TIMEOUT_S),
            "--laser-wait-s", str(LASER_TIMEOUT_S),
            "--seed", str(seed), "--out", str(out), *extra]


def stated_scene(folder, reference: str, silence_s: float | None = None):
    """The thesis_final scene on an MC70 whose robot.json states the controller's session
    behaviour (``controller.sessions``: keep, fresh_after_silence with ``silence_s``, or
    fresh_each_client), written to ``folder`` (the robot in its own folder, with the MC70's
    error profiles beside it, as under models/): the scene's path."""
    import json
    import shutil
    from pathlib import Path

    from planecal.base.paths import data_path

    folder = Path(folder)
    mc70 = data_path("models", "mc70")
    robot = json.loads((mc70 / "robot.json").read_text())
    robot["controller"]["sessions"] = {"reference": reference, "source": "the test's statement"}
    if silence_s is not None:
        robot["controller"]["sessions"]["silence_s"] = silence_s
    robot_dir = folder / f"mc70-{reference}"
    shutil.copytree(mc70 / "errors", robot_dir / "errors")
    shutil.copy(mc70 / "shapes.json", robot_dir / "shapes.json")  # its link shapes (issue 23)
    robot_path = robot_dir / "robot.json"
    robot_path.write_text(json.dumps(robot))
    scene = json.loads(data_path("scenes", "thesis_final.json").read_text())
    scene["robot"] = str(robot_path.resolve())
    scene_path = folder / f"cell-{reference}.json"
    scene_path.write_text(json.dumps(scene))
    return scene_path
