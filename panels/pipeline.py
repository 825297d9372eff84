"""The ArtGS sidebar tab's main panel: the capture and output folders."""

from __future__ import annotations

import bpy

from .common import ArtgsPanel


class ARTGS_PT_pipeline(ArtgsPanel, bpy.types.Panel):
    bl_label = "ArtGS Pipeline"

    def draw(self, context: bpy.types.Context) -> None:
        settings = context.scene.artgs
        col = self.layout.column()
        col.prop(settings, "capture_dir")
        col.prop(settings, "output_dir")


CLASSES = (ARTGS_PT_pipeline,)
