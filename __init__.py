"""ArtGS for Blender: articulated objects from multi-view RGB-D captures.

Outside Blender this package is ``artgs`` (the engine lives in ``artgs.core``); inside Blender
it is the extension ``bl_ext.<repo>.artgs``. Importing it loads nothing of Blender: only
``register()`` pulls in the add-on's modules, so ``import artgs.core`` works without bpy.

``register()`` registers, in order: preferences, scene properties, bone properties, operators,
then the panels (the main panel first, its sections in display order). Every module exposes a
``CLASSES`` tuple (registered in order, unregistered in reverse) and optionally
``register_properties()`` / ``unregister_properties()`` (called after its classes are registered
and before they are unregistered). Only this module knows the list, so the add-on's packages never
import their package parents.
"""

from __future__ import annotations

from types import ModuleType


def _modules() -> list[ModuleType]:
    """The modules that register something, in registration order."""
    from .artgs_addon import bone_props, preferences, properties
    from .operators import bones as bone_operators
    from .operators import capture, engine, export, optimise, propose, splat
    from .panels import bones as bone_panel
    from .panels import capture as capture_panel
    from .panels import pipeline, stages
    from .panels import splat as splat_panel

    return [preferences, properties, bone_props,
            engine, capture, splat, propose, bone_operators, optimise, export,
            pipeline, capture_panel, splat_panel, bone_panel, stages]


def register() -> None:
    """Register preferences, properties, operators and panels with Blender."""
    import bpy

    for module in _modules():
        for cls in module.CLASSES:
            bpy.utils.register_class(cls)
        if hasattr(module, "register_properties"):
            module.register_properties()


def unregister() -> None:
    """Unregister everything ``register`` added, in reverse order; running jobs are cancelled."""
    import bpy

    from .artgs_addon import preferences
    from .operators import _job

    _job.cancel_all()
    preferences.last_check.clear()
    for module in reversed(_modules()):
        if hasattr(module, "unregister_properties"):
            module.unregister_properties()
        for cls in reversed(module.CLASSES):
            bpy.utils.unregister_class(cls)
