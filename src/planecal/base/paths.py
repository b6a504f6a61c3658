"""Where the project's data (models/, scenes/) lives.

The package is installed in place (``pip install -e .``) from a checkout whose root holds
models/ and scenes/; ``PLANECAL_HOME`` overrides the root.
"""
from __future__ import annotations

import os
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[3]


def project_root() -> Path:
    env = os.environ.get("PLANECAL_HOME")
    return Path(env) if env else _ROOT


def data_path(*parts: str) -> Path:
    return project_root().joinpath(*parts)
