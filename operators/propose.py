"""Propose Bones: initial joints from the engine (``artgs propose``), built as an armature."""

from __future__ import annotations

import bpy
import numpy as np

from ..artgs_addon import preferences
from ..artgs_addon.armature import armature_name, build_armature
from ..artgs_addon.pointcloud import points_modifier_last
from ..artgs_addon.splat_preview import splat_preview_in
from ..artgs_addon.worker import WorkerResult
from ..core.model import layout
from ..core.model.joints import Articulation, read_articulation
from ._job import WorkerOperator, engine_inputs_ready, stage_args

_PREFS = "Preferences > Add-ons > ArtGS"


def object_size(obj: bpy.types.Object | None, articulation: Articulation) -> float:
    """Size of the object in metres: the splat preview's largest dimension, else the largest
    moving-part box of the proposals, else 1."""
    if obj is not None and max(obj.dimensions) > 0:
        return float(max(obj.dimensions))
    sizes = [2.0 * float(np.max(j.extent["half_size"])) for j in articulation.joints
             if j.extent and "half_size" in j.extent]
    return max(sizes) if sizes else 1.0


class ARTGS_OT_propose_bones(WorkerOperator, bpy.types.Operator):
    """Propose joints (from motion in the interaction frames or from a vision-language model) and
    build them as an armature"""

    bl_idname = "artgs.propose_bones"
    bl_label = "Propose Bones"
    bl_options = {"REGISTER", "UNDO"}
    stage = "propose"
    command = "propose"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return engine_inputs_ready(context)

    def prepare(self, context: bpy.types.Context) -> str | None:
        if context.scene.artgs.proposal_method != "vlm":
            return None
        if not bpy.app.online_access:
            return ("The VLM proposal method needs network access, which Blender's "
                    "'Allow Online Access' preference (Preferences > System > Network) forbids; "
                    "enable it, or use the Motion method")
        if not preferences.get(context).vlm_endpoint:
            return f"The VLM proposal method needs 'VLM Endpoint' set in {_PREFS}"
        return None

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        settings = context.scene.artgs
        prefs = preferences.get(context)
        args = stage_args(context) + ["--method", settings.proposal_method]
        if settings.proposal_method == "vlm":
            args += ["--vlm-endpoint", prefs.vlm_endpoint]
            if prefs.vlm_model:
                args += ["--vlm-model", prefs.vlm_model]
        return args

    def worker_env(self, context: bpy.types.Context) -> dict[str, str]:
        key = preferences.get(context).vlm_api_key
        return {"ARTGS_VLM_API_KEY": key} if key else {}

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        settings = context.scene.artgs
        articulation = read_articulation(settings.output_path / layout.PROPOSALS)
        preview = splat_preview_in(settings.output_path, settings.splat_object)
        arm = build_armature(context, articulation, preview=preview,
                             size=object_size(preview, articulation),
                             name=armature_name(settings.capture_path, settings.output_path),
                             output=settings.output_path)
        if preview is not None:
            points_modifier_last(preview)
        kinds = ", ".join(f"{j.name} ({j.type})" for j in articulation.joints)
        return f"{len(articulation.joints)} joints in '{arm.name}': {kinds or 'none'}"


CLASSES = (ARTGS_OT_propose_bones,)
