"""ArtGS for Blender: articulated objects from multi-view RGB-D captures.

Outside Blender this package is ``artgs`` (the engine lives in ``artgs.core``); inside Blender
it is the extension ``bl_ext.<repo>.artgs``. Importing it loads nothing of Blender: only
``register()`` pulls in the operators and panels, so ``import artgs.core`` works without bpy.
"""


def register() -> None:
    """Register the add-on's classes with Blender."""
    from . import artgs_addon

    artgs_addon.register()


def unregister() -> None:
    """Remove everything ``register`` added."""
    from . import artgs_addon

    artgs_addon.unregister()
