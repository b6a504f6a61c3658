"""Public six-axis robot descriptions the tests ship (tests/data/robots/*/README.md says
where each comes from and its licence): the URDF, the package folder its meshes are
found in, and the import options a user would give. ``imported(name)`` imports one once
per test session (``planecal robot import``, as a user runs it)."""
from __future__ import annotations

from pathlib import Path

DATA = Path(__file__).parent / "data" / "robots"

ARMS = {
    "kr16": (DATA / "kuka_kr16" / "urdf" / "kr16_2.urdf", ["--visual", "collision"]),
    "kr210": (DATA / "kuka_kr210" / "urdf" / "kr210l150.urdf", ["--visual", "collision"]),
    "irb4600": (DATA / "abb_irb4600_40_255" / "urdf" / "robot_description.urdf",
                ["--visual", "collision"]),
    "puma560": (DATA / "unimation_puma560_description" / "urdf" / "puma560_robot.urdf", []),
}


class Imported:
    """The session's imports: ``get(name) -> (folder, stdout, stderr)``, one import per arm."""

    def __init__(self, root: Path):
        self.root = root
        self._done: dict = {}

    def get(self, name: str):
        if name not in self._done:
            import contextlib
            import io

            from planecal.cli import main
            urdf, opts = ARMS[name]
            out, err = io.StringIO(), io.StringIO()
            folder = self.root / name
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                rc = main(["robot", "import", str(urdf), "--out", str(folder), *opts])
            assert rc == 0, (name, err.getvalue())
            self._done[name] = (folder, out.getvalue(), err.getvalue())
        return self._done[name]
