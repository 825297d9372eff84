"""The ArtGS sidebar tab: the main panel (folders) and the helper that draws a stage's state."""

from __future__ import annotations

import bpy

from ..artgs_addon.properties import ArtgsStageState

_ICONS = {"NOT_RUN": "RADIOBUT_OFF", "RUNNING": "SORTTIME", "DONE": "CHECKMARK", "FAILED": "ERROR"}


def draw_state(layout: bpy.types.UILayout, state: ArtgsStageState) -> None:
    """The stage's state: a progress bar while running, else one line (figures or the reason)."""
    if state.status == "RUNNING":
        layout.progress(factor=state.progress, type="BAR", text=state.text)
        return
    layout.label(text=state.text, icon=_ICONS[state.status])


class ArtgsPanel:
    """Common settings of the ArtGS panels (3D view sidebar, tab "ArtGS")."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "ArtGS"


class ARTGS_PT_pipeline(ArtgsPanel, bpy.types.Panel):
    bl_label = "ArtGS Pipeline"

    def draw(self, context: bpy.types.Context) -> None:
        settings = context.scene.artgs
        col = self.layout.column()
        col.prop(settings, "capture_dir")
        col.prop(settings, "output_dir")


CLASSES = (ARTGS_PT_pipeline,)
