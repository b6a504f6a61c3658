"""Build hook: the robot models and scenes ship inside the package.

models/ and scenes/ stay at the top of the repository (they are edited there, and read
there by an editable install); a build copies them into the package as
``planecal/data/models`` and ``planecal/data/scenes``, so a wheel and ``pip install .``
carry them and ``planecal.base.paths`` finds them next to the installed code, wherever
that is (a venv, ``--user``, ``--target``, ``--prefix``). Everything else is in
pyproject.toml.
"""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
DATA = ("models", "scenes")  # top-level folders shipped as planecal/data/<name>


class BuildPyWithData(build_py):
    """setuptools' build_py, then DATA copied into the built package (not in editable
    mode: an editable install reads the checkout's folders)."""

    def run(self):
        super().run()
        if self.editable_mode:
            return
        for name in DATA:
            src = ROOT / name
            if not src.is_dir() or not any(src.iterdir()):
                raise SystemExit(f"setup.py: {src} is missing or empty: a planecal package "
                                 "without it cannot run (build from a full checkout or sdist)")
            dst = Path(self.build_lib) / "planecal" / "data" / name
            shutil.rmtree(dst, ignore_errors=True)
            shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


setup(cmdclass={"build_py": BuildPyWithData})
