"""The crop box in Blender: an Empty shown as a cube that the user places around the object.
Before an engine stage that reads it runs, its world box is written to OUT/crop.json
(core/model/crop.py), which every stage reads; without the Empty, a crop.json this add-on wrote
is removed, so deleting the box removes the crop."""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..core.model import layout
from ..core.model.crop import CropBox, crop_from_matrix, read_crop, write_crop

CROP_BOX = "ArtGS Crop Box"
SOURCE = "blender"


def find_crop_box(scene: bpy.types.Scene) -> bpy.types.Object | None:
    obj = scene.objects.get(CROP_BOX)
    return obj if obj is not None and obj.type == "EMPTY" else None


def add_crop_box(context: bpy.types.Context) -> bpy.types.Object:
    """The scene's crop box (made if absent): OUT's crop.json when there is one (e.g. the box
    reconstruct separated from the room), else around the splat preview's bounds (+10 %), else a
    1 m cube at the 3D cursor."""
    obj = find_crop_box(context.scene)
    if obj is None:
        obj = bpy.data.objects.new(CROP_BOX, None)
        obj.empty_display_type = "CUBE"
        obj.empty_display_size = 1.0
        context.scene.collection.objects.link(obj)
        out = context.scene.artgs.output_path
        current = read_crop(out) if out is not None else None
        splat = context.scene.artgs.splat_object
        if current is not None:
            M = np.eye(4)
            M[:3, :3] = current.axes.T * current.half_size
            M[:3, 3] = current.center
            obj.matrix_world = Matrix(M.tolist())
        elif splat is not None and splat.bound_box:
            corners = np.array([splat.matrix_world @ Vector(c)
                                for c in splat.bound_box])
            lo, hi = corners.min(0), corners.max(0)
            obj.location = tuple((lo + hi) / 2)
            obj.scale = tuple(np.maximum((hi - lo) / 2 * 1.1, 0.01))
        else:
            obj.location = context.scene.cursor.location
            obj.scale = (0.5, 0.5, 0.5)
    for other in context.selected_objects:
        other.select_set(False)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def crop_of(obj: bpy.types.Object) -> CropBox:
    """The world box of the cube Empty ``obj`` (display size and world matrix)."""
    M = np.array(obj.matrix_world, float)
    M[:3, :3] *= obj.empty_display_size
    return crop_from_matrix(M, SOURCE)


def sync_crop(scene: bpy.types.Scene, out: Path) -> CropBox | None:
    """Write the scene's crop box to OUT/crop.json; with no box, remove a crop.json this add-on
    wrote (one written by hand stays). Returns the box in force."""
    obj = find_crop_box(scene)
    if obj is not None:
        box = crop_of(obj)
        out.mkdir(parents=True, exist_ok=True)
        write_crop(out, box)
        return box
    current = read_crop(out) if (out / layout.CROP).is_file() else None
    if current is not None and current.source == SOURCE:
        (out / layout.CROP).unlink()
        return None
    return current
