"""What the ArtGS panels share: the sidebar placement and how a stage's state is drawn."""

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
