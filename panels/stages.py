"""The Optimise and Export sections of the pipeline panel."""

from __future__ import annotations

import bpy

from .common import ArtgsPanel, draw_figures, draw_state


class ARTGS_PT_optimise(ArtgsPanel, bpy.types.Panel):
    bl_label = "Optimise Joints"
    bl_parent_id = "ARTGS_PT_pipeline"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        col.operator("artgs.optimise_joints", icon="MOD_HUE_SATURATION")
        draw_state(col, context.scene.artgs.optimise)
        draw_figures(col, context, "optimise")


class ARTGS_PT_export(ArtgsPanel, bpy.types.Panel):
    bl_label = "Export URDF"
    bl_parent_id = "ARTGS_PT_pipeline"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        col.operator("artgs.export_urdf", icon="EXPORT")
        draw_state(col, context.scene.artgs.export)
        draw_figures(col, context, "export")
        row = col.row(align=True)
        row.operator("artgs.check_manipulation", icon="CON_ARMATURE")
        row.operator("artgs.show_check_frames", text="", icon="IMAGE_DATA")
        draw_state(col, context.scene.artgs.check)
        image = bpy.data.images.get("ArtGS Check Frames")
        if image is not None and image.preview is not None:
            col.template_icon(icon_value=image.preview.icon_id, scale=6.0)
        col.separator()
        row = col.row(align=True)
        row.operator("artgs.import_urdf", icon="IMPORT")
        row.operator("artgs.write_edited_urdf", icon="FILE_TICK")
        draw_figures(col, context, "check")


CLASSES = (ARTGS_PT_optimise, ARTGS_PT_export)
