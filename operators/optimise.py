"""Optimise Joints: fit the joints to the interaction frames in the engine (``artgs optimise``).

The engine streams the joints every few steps; the armature's bones follow them live. Esc (or a
failure) puts the bones back where they were. At the end the armature is rebuilt from
``articulation.json`` and the splat preview is bound by the optimisation's part labels (posing a
bone moves exactly its part) and coloured by part.
"""

from __future__ import annotations

import time
from typing import Any

import bpy
import numpy as np
from bpy.props import IntProperty

from ..artgs_addon.armature import armature_name, build_armature, find_armature, place_joints, \
    read_joints
from ..artgs_addon.pointcloud import points_modifier_last
from ..artgs_addon.splat_preview import gaussian_indices, splat_preview_in
from ..artgs_addon.worker import WorkerResult
from ..core.model import layout
from ..core.model.joints import read_articulation
from ._job import WorkerOperator, engine_inputs_ready, stage_args
from .propose import object_size

#: Colour attribute of a splat preview showing its part labels (base grey, parts in turn).
PART_COLORS = "Part"
_PALETTE = np.array([[0.5, 0.5, 0.5], [0.9, 0.3, 0.2], [0.2, 0.6, 0.9], [0.3, 0.8, 0.3],
                     [0.9, 0.7, 0.2], [0.7, 0.3, 0.8], [0.2, 0.8, 0.8]], np.float32)
_LIVE_INTERVAL = 0.5  # seconds between live bone updates


def colour_by_part(preview: bpy.types.Object, labels: np.ndarray) -> None:
    """A ``Part`` colour attribute on the preview (made active) from per-vertex part labels."""
    mesh = preview.data
    old = mesh.color_attributes.get(PART_COLORS)
    if old is not None:
        mesh.color_attributes.remove(old)
    rgba = np.ones((len(labels), 4), np.float32)
    rgba[:, :3] = _PALETTE[np.asarray(labels) % len(_PALETTE)]
    col = mesh.color_attributes.new(PART_COLORS, "FLOAT_COLOR", "POINT")
    col.data.foreach_set("color", rgba.ravel())
    mesh.color_attributes.active_color = col


class ARTGS_OT_optimise_joints(WorkerOperator, bpy.types.Operator):
    """Fit the joints, their states and the parts to the interaction frames by differentiable
    rendering of the splat (the proposals, with your edits saved, are the start)"""

    bl_idname = "artgs.optimise_joints"
    bl_label = "Optimise Joints"
    bl_options = {"REGISTER", "UNDO"}
    stage = "optimise"
    command = "optimise"

    iterations: IntProperty(name="Iterations", default=0, min=0,
                            description="Steps of the main fit (0: the engine's default)")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        settings = getattr(context.scene, "artgs", None)
        return engine_inputs_ready(context) and \
            (settings.output_path / layout.PROPOSALS).is_file()

    def prepare(self, context: bpy.types.Context) -> str | None:
        self._arm = find_armature(context)
        self._lines = ({j.name: (j.origin, j.axis) for j in read_joints(self._arm)}
                       if self._arm is not None else {})
        self._last_live = 0.0
        return None

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        return stage_args(context, self.iterations)

    def on_progress(self, context: bpy.types.Context, figures: dict[str, Any]) -> None:
        joints = figures.get("joints")
        now = time.monotonic()
        if self._arm is None or not joints or now - self._last_live < _LIVE_INTERVAL:
            return
        self._last_live = now
        place_joints(context, self._arm, {j["name"]: (j["origin"], j["axis"]) for j in joints})

    def restore(self, context: bpy.types.Context) -> None:
        if self._arm is not None and self._lines:
            place_joints(context, self._arm, self._lines)

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        settings = context.scene.artgs
        out = settings.output_path
        articulation = read_articulation(out / layout.ARTICULATION)
        preview = splat_preview_in(out, settings.splat_object)
        labels = None
        if preview is not None and (out / layout.PART_LABELS).is_file():
            index = gaussian_indices(preview)
            if index is not None:
                labels = np.load(out / layout.PART_LABELS)[index]
                colour_by_part(preview, labels)
        arm = build_armature(context, articulation, preview=preview,
                             size=object_size(preview, articulation),
                             name=armature_name(settings.capture_path, out), output=out,
                             labels=labels)
        if preview is not None:
            points_modifier_last(preview)
        worst = max((float(j.extra.get("residual", 0.0)) for j in articulation.joints
                     if j.extra), default=0.0)
        return (f"{len(articulation.joints)} joints optimised in '{arm.name}'"
                + (f", worst residual {worst:.4g}" if worst else ""))


CLASSES = (ARTGS_OT_optimise_joints,)
