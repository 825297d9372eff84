"""Reconstruct Splat (worker ``artgs reconstruct``) and Import Splat PLY (a preview of a 3DGS PLY)."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import IntProperty, StringProperty

from ..artgs_addon import preferences
from ..artgs_addon.splat_preview import build_splat_preview, splat_preview_in
from ..artgs_addon.worker import WorkerResult
from ..core.model import layout
from ..core.model.errors import ArtgsError
from ._job import WorkerOperator, engine_inputs_ready, figures_text, job_running, stage_args


def load_splat_preview(context: bpy.types.Context, path: Path) -> str:
    """Show ``path`` as the scene's splat preview, replacing the preview of a PLY in the same
    folder (previews of other output folders stay); returns the key figures."""
    settings = context.scene.artgs
    old = splat_preview_in(path.parent, settings.splat_object)
    built = build_splat_preview(context, path, preferences.preview_cap(context))
    if old is not None:
        mesh = old.data
        bpy.data.objects.remove(old)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)
    settings.splat_object = built.obj
    return f"{built.gaussians} Gaussians, preview {built.points} points ({built.seconds:.2f} s)"


class ARTGS_OT_reconstruct(WorkerOperator, bpy.types.Operator):
    """Reconstruct the static Gaussian splat from the capture (runs in the engine)"""

    bl_idname = "artgs.reconstruct"
    bl_label = "Reconstruct Splat"
    bl_options = {"REGISTER", "UNDO"}
    stage = "reconstruct"
    command = "reconstruct"

    iterations: IntProperty(name="Iterations", default=0, min=0,
                            description="Iteration cap (0: until converged)")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return engine_inputs_ready(context)

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        return stage_args(context, self.iterations)

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        preview = load_splat_preview(context, context.scene.artgs.output_path / layout.SPLAT)
        return figures_text(self._figures) or preview


class ARTGS_OT_import_splat(bpy.types.Operator):
    """Show a Gaussian splat PLY (default: the output folder's splat.ply) as a coloured point cloud"""

    bl_idname = "artgs.import_splat"
    bl_label = "Import Splat PLY"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="PLY File", subtype="FILE_PATH", options={"SKIP_SAVE"},
                             description="3DGS PLY to show (empty: OUT/splat.ply)")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        settings = getattr(context.scene, "artgs", None)
        out = settings.output_path if settings else None
        return not job_running() and out is not None and (out / layout.SPLAT).is_file()

    def execute(self, context: bpy.types.Context) -> set[str]:
        settings = context.scene.artgs
        path = Path(bpy.path.abspath(self.filepath)) if self.filepath else \
            settings.output_path / layout.SPLAT
        try:
            summary = load_splat_preview(context, path)
        except (ArtgsError, OSError, ValueError) as exc:
            settings.reconstruct.set("FAILED", str(exc))
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        settings.reconstruct.set("DONE", summary, 1.0)
        self.report({"INFO"}, f"Splat preview: {summary}")
        return {"FINISHED"}


CLASSES = (ARTGS_OT_reconstruct, ARTGS_OT_import_splat)
