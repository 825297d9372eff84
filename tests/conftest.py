"""Blender's user folders kept out of the developer's home; ``--blender-only``: collect only the Blender-side test files (those that start with
``pytest.importorskip("bpy")``), for the bpy 5.x half of `make test`, whose venv has no engine."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

# Blender's user folders (preferences, the add-on's engine.json) in a temporary folder, never the
# developer's own: set before any test imports bpy.
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="artgs-blender-user-"))

_MARK = 'importorskip("bpy")'


def pytest_addoption(parser) -> None:
    parser.addoption("--blender-only", action="store_true",
                     help="only the Blender-side tests (files that importorskip bpy)")


def pytest_ignore_collect(collection_path: Path, config) -> bool | None:
    if not config.getoption("--blender-only") or collection_path.suffix != ".py":
        return None
    if not collection_path.name.startswith("test_"):
        return None
    return _MARK not in collection_path.read_text(encoding="utf-8") or None
