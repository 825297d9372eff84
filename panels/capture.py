"""Capture section: import the capture's cameras and point preview."""

from __future__ import annotations

import bpy

from .common import ArtgsPanel, draw_state


class ARTGS_PT_capture(ArtgsPanel, bpy.types.Panel):
    bl_label = "Capture"
    bl_parent_id = "ARTGS_PT_pipeline"

    def draw(self, context: bpy.types.Context) -> None:
        settings = context.scene.artgs
        col = self.layout.column()
        col.prop(settings, "preview_density")
        col.operator("artgs.import_capture", icon="OUTLINER_OB_CAMERA")
        draw_state(col, settings.capture)


CLASSES = (ARTGS_PT_capture,)
