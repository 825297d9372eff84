"""Optimise and Export sections: shown, but their engine stages do not exist in this version."""

from __future__ import annotations

import bpy

from .common import ArtgsPanel, draw_figures, draw_state


def _draw_unavailable(layout: bpy.types.UILayout, action: str, icon: str, state) -> None:
    row = layout.row()
    row.enabled = False
    row.label(text=action, icon=icon)
    layout.label(text="Not available in this version", icon="INFO")
    draw_state(layout, state)


class ARTGS_PT_optimise(ArtgsPanel, bpy.types.Panel):
    bl_label = "Optimise Joints"
    bl_parent_id = "ARTGS_PT_pipeline"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        _draw_unavailable(col, "Optimise Joints (differentiable rendering)",
                          "MOD_HUE_SATURATION", context.scene.artgs.optimise)
        draw_figures(col, context, "optimise")


class ARTGS_PT_export(ArtgsPanel, bpy.types.Panel):
    bl_label = "Export URDF"
    bl_parent_id = "ARTGS_PT_pipeline"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context: bpy.types.Context) -> None:
        col = self.layout.column()
        _draw_unavailable(col, "Export URDF (checked in PyBullet)", "EXPORT",
                          context.scene.artgs.export)
        draw_figures(col, context, "check")


CLASSES = (ARTGS_PT_optimise, ARTGS_PT_export)
