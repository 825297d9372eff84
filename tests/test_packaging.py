"""pyproject.toml lists every package of the tree (a regular, non-editable install must hold them all)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_folder_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"artgs"} | {
        "artgs." + ".".join(init.parent.relative_to(ROOT).parts)
        for top in ("core", "artgs_addon", "operators", "panels")
        for init in (ROOT / top).rglob("__init__.py") if "__pycache__" not in init.parts}
    assert found == listed, f"missing: {sorted(found - listed)}, stale: {sorted(listed - found)}"
