"""Import Capture: the capture's cameras and a coloured point preview, in Blender's process."""

from __future__ import annotations

import sys

import bpy

from ..artgs_addon import preferences
from ..artgs_addon.capture_scene import build_capture
from ..core.capture import load_capture
from ..core.errors import ArtgsError
from ._job import job_running


def preview_cap(context: bpy.types.Context) -> int:
    """Points allowed in a preview: the preference's cap times the scene's density."""
    return max(1, int(preferences.get(context).preview_cap * context.scene.artgs.preview_density))


class ARTGS_OT_import_capture(bpy.types.Operator):
    """Add the capture's cameras and a coloured point cloud of its static depth frames"""

    bl_idname = "artgs.import_capture"
    bl_label = "Import Capture"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        settings = getattr(context.scene, "artgs", None)
        path = settings.capture_path if settings else None
        return not job_running() and path is not None and (path / "transforms.json").is_file()

    def execute(self, context: bpy.types.Context) -> set[str]:
        settings = context.scene.artgs
        state = settings.capture
        try:
            capture = load_capture(settings.capture_path)
        except (ArtgsError, OSError) as exc:
            return self._fail(state, str(exc))
        except ImportError as exc:  # Blender's own Python has no OpenCV to decode the images
            return self._fail(state, f"reading the capture needs {exc.name or exc} in Blender's "
                              f"Python: {sys.executable} -m pip install opencv-python-headless")
        built = build_capture(context, capture, preview_cap(context))
        summary = (f"{len(built.cameras)} cameras, {built.points_kept} of {built.points_total} "
                   f"points ({built.build_seconds:.2f} s)")
        state.set("DONE", summary, 1.0)
        self.report({"INFO"}, f"Imported {built.collection.name}: {summary}")
        return {"FINISHED"}

    def _fail(self, state, message: str) -> set[str]:
        state.set("FAILED", message)
        self.report({"ERROR"}, message)
        return {"CANCELLED"}


CLASSES = (ARTGS_OT_import_capture,)
