"""The checkout the tests run from: its examples/ and docs/ (not shipped in the package;
the package's own data is found through planecal.base.paths)."""
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def repo_path(*parts: str) -> Path:
    return REPO.joinpath(*parts)
