"""Splat section: reconstruct the static splat in the engine, or show an existing PLY."""

from __future__ import annotations

import bpy

from .common import ArtgsPanel, draw_figures, draw_state


class ARTGS_PT_splat(ArtgsPanel, bpy.types.Panel):
    bl_label = "Gaussian Splat"
    bl_parent_id = "ARTGS_PT_pipeline"

    def draw(self, context: bpy.types.Context) -> None:
        settings = context.scene.artgs
        col = self.layout.column()
        col.operator("artgs.reconstruct", icon="SHADING_RENDERED")
        col.operator("artgs.import_splat", icon="IMPORT")
        if settings.splat_object is not None:
            col.label(text=f"Preview: {settings.splat_object.name}", icon="POINTCLOUD_DATA")
        draw_state(col, settings.reconstruct)
        draw_figures(col, context, "reconstruct")


CLASSES = (ARTGS_PT_splat,)
