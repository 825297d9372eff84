"""Import Capture: the engine (``artgs capture-preview``) validates the capture and writes its
cameras and a capped point preview to a temporary .npz; Blender builds them with numpy only."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import bpy

from ..artgs_addon import preferences
from ..artgs_addon.capture_scene import build_capture
from ..artgs_addon.worker import WorkerResult
from ..core.model.capture_preview import read_preview
from ._job import WorkerOperator, job_running

PREVIEW_FILE = "capture_preview.npz"


class ARTGS_OT_import_capture(WorkerOperator, bpy.types.Operator):
    """Add the capture's cameras and a coloured point cloud of its static depth frames (the
    capture is read and checked in the engine)"""

    bl_idname = "artgs.import_capture"
    bl_label = "Import Capture"
    bl_options = {"REGISTER", "UNDO"}
    stage = "capture"
    command = "capture-preview"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        settings = getattr(context.scene, "artgs", None)
        path = settings.capture_path if settings else None
        return not job_running() and path is not None and (path / "transforms.json").is_file()

    def prepare(self, context: bpy.types.Context) -> str | None:
        self._tmp = Path(tempfile.mkdtemp(prefix="artgs-capture-"))
        return None

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        return [str(context.scene.artgs.capture_path), "--preview", str(self._tmp / PREVIEW_FILE),
                "--max-points", str(preferences.preview_cap(context))]

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        built = build_capture(context, read_preview(self._tmp / PREVIEW_FILE))
        return (f"{len(built.cameras)} cameras, {built.points_kept} of {built.points_total} "
                f"points ({built.build_seconds:.2f} s)")

    def cleanup(self, context: bpy.types.Context) -> None:
        shutil.rmtree(self._tmp, ignore_errors=True)


CLASSES = (ARTGS_OT_import_capture,)
