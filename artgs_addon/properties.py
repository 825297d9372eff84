"""Per-scene settings ``Scene.artgs``: folders, proposal method, preview density, stage states."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import EnumProperty, FloatProperty, PointerProperty, StringProperty

from ..core.model import registry

#: Stages whose state the panels show, in order: importing the capture (Blender only), then the
#: engine's stages under their registry names (``report.json`` keys, ``artgs`` sub-commands).
STAGES = ("capture", *(spec.name for spec in registry.STAGES))

STATUSES = (("NOT_RUN", "Not Run", "The stage has not run in this scene"),
            ("RUNNING", "Running", "The stage is running"),
            ("DONE", "Done", "The stage finished"),
            ("FAILED", "Failed", "The stage failed; the message says why"))


class ArtgsStageState(bpy.types.PropertyGroup):
    """State of one stage: status, progress while running, key figures or the failure reason."""

    status: EnumProperty(name="Status", items=STATUSES, default="NOT_RUN")
    progress: FloatProperty(name="Progress", min=0.0, max=1.0, subtype="FACTOR")
    message: StringProperty(name="Message", description="Progress, key figures or failure reason")

    @property
    def text(self) -> str:
        """One line for the panel."""
        if self.status == "NOT_RUN":
            return "not run"
        if self.status == "RUNNING":
            return f"running {100 * self.progress:.0f}%" + (f": {self.message}" if self.message else "")
        if self.status == "DONE":
            return "done" + (f": {self.message}" if self.message else "")
        return f"failed: {self.message}"

    def set(self, status: str, message: str = "", progress: float = 0.0) -> None:
        self.status = status
        self.message = message
        self.progress = progress

    def snapshot(self) -> tuple[str, str, float]:
        return self.status, self.message, self.progress

    def restore(self, snap: tuple[str, str, float]) -> None:
        self.status, self.message, self.progress = snap


class ArtgsSceneSettings(bpy.types.PropertyGroup):
    capture_dir: StringProperty(
        name="Capture", subtype="DIR_PATH",
        description="Capture folder (transforms.json, images/, depth/, masks/)")
    output_dir: StringProperty(
        name="Output", subtype="DIR_PATH",
        description="Folder for the engine's outputs (splat.ply, proposals.json, ...)")
    proposal_method: EnumProperty(
        name="Proposal Method", default="motion",
        items=(("motion", "Motion", "Joints from how parts move in the interaction frames"),
               ("vlm", "VLM", "Joints proposed by a vision-language model (needs online access)")))
    preview_density: FloatProperty(
        name="Preview Density", default=1.0, min=0.01, max=1.0, subtype="FACTOR",
        description="Fraction of the preference's preview point cap used in this scene")
    splat_object: PointerProperty(
        name="Splat Preview", type=bpy.types.Object,
        description="The splat preview object (used to size and place the bones)")
    @property
    def capture_path(self) -> Path | None:
        """The capture folder as an absolute path, None when not set."""
        return _abspath(self.capture_dir)

    @property
    def output_path(self) -> Path | None:
        """The output folder as an absolute path, None when not set."""
        return _abspath(self.output_dir)

    def stage(self, name: str) -> ArtgsStageState:
        if name not in STAGES:
            raise KeyError(f"unknown stage {name!r}; expected one of {STAGES}")
        return getattr(self, name)


# One state per stage, named as the stage (``settings.stage(name)``).
ArtgsSceneSettings.__annotations__.update(
    {name: PointerProperty(type=ArtgsStageState) for name in STAGES})


def _abspath(value: str) -> Path | None:
    return Path(bpy.path.abspath(value)).resolve() if value.strip() else None


CLASSES = (ArtgsStageState, ArtgsSceneSettings)


def register_properties() -> None:
    bpy.types.Scene.artgs = PointerProperty(type=ArtgsSceneSettings)


def unregister_properties() -> None:
    del bpy.types.Scene.artgs
