"""What the ArtGS panels share: the sidebar placement and how a stage's state is drawn."""

from __future__ import annotations

import bpy

from ..artgs_addon.last_run import key_figures
from ..artgs_addon.properties import ArtgsStageState

_ICONS = {"NOT_RUN": "RADIOBUT_OFF", "RUNNING": "SORTTIME", "DONE": "CHECKMARK", "FAILED": "ERROR"}


def draw_state(layout: bpy.types.UILayout, state: ArtgsStageState) -> None:
    """The stage's state: a progress bar while running, else one line (figures or the reason)."""
    if state.status == "RUNNING":
        layout.progress(factor=state.progress, type="BAR", text=state.text)
        return
    layout.label(text=state.text, icon=_ICONS[state.status])


def draw_figures(layout: bpy.types.UILayout, context: bpy.types.Context, stage: str) -> None:
    """The last run's key figures of ``stage`` (a report.json stage) in the output folder."""
    lines = key_figures(context.scene.artgs.output_path, stage)
    if not lines:
        return
    col = layout.column(align=True)
    col.scale_y = 0.8
    for line in lines:
        col.label(text=line)


class ArtgsPanel:
    """Common settings of the ArtGS panels (3D view sidebar, tab "ArtGS")."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "ArtGS"
