"""Blender's user folders kept out of the developer's home; the registered add-on fixtures
(``addon``, ``ctx``) of Blender-side tests; ``--blender-only``: collect only the Blender-side test
files (those that start with ``pytest.importorskip("bpy")``), for the bpy 5.x half of `make test`,
whose venv has no engine."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

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


@pytest.fixture(scope="module")
def addon():
    """The whole add-on registered in this process (unless something else registered it already),
    for Blender-side tests that drive its modules directly.

    bpy 4.5 as a module hangs at process exit while property groups with Python callbacks are
    registered, so whatever this registers it always unregisters.
    """
    import artgs
    from artgs.artgs_addon import bone_props
    mine = not bone_props.ArtgsJointProps.is_registered
    if mine:
        artgs.register()
    try:
        yield
    finally:
        if mine:
            artgs.unregister()


@pytest.fixture
def ctx(addon):
    """An empty factory scene with the add-on registered."""
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context
