"""Test helper (Blender side): the ``addon`` and ``ctx`` fixtures of tests that drive the add-on's
modules directly rather than through addon_utils."""

from __future__ import annotations

import bpy
import pytest

import artgs
from artgs.artgs_addon import bone_props


@pytest.fixture(scope="module")
def addon():
    """The whole add-on registered (unless something else registered it already).

    bpy 4.5 as a module hangs at process exit while property groups with Python callbacks are
    registered, so whatever this registers it always unregisters.
    """
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
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context
