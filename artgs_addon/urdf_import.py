"""Any URDF as Blender objects: one joint armature (the design of armature.py) with the links'
visual meshes parented to the bones of the joints that move them.

The URDF is read by core/model/urdf_io.py (numpy + xml only). Meshes are imported with Blender's
own OBJ/STL importers in the URDF's axes (no axis conversion), placed at their link's pose at zero
joint values; ``<box>`` visuals become box meshes; other formats are skipped and counted. The
armature records the URDF it came from (``URDF_KEY``) so the edited joints can be written back
into a copy of it (:func:`write_edited_urdf`).
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..core.model.urdf_io import Visual, articulation_of, read_urdf, rewrite_joints
from .armature import build_armature, read_joints

URDF_KEY = "artgs_urdf"       # on the armature object: the URDF file it was imported from


def import_urdf(context: bpy.types.Context, path: str | Path) -> tuple[bpy.types.Object, int, int]:
    """Build the armature and the link meshes of ``path``; (armature, meshes, skipped visuals)."""
    path = Path(path)
    model = read_urdf(path)
    articulation = articulation_of(model)
    extent = np.array([T[:3, 3] for T in model.link_poses.values()])
    size = max(float(np.ptp(extent, axis=0).max()) if len(extent) > 1 else 0.0, 0.5)
    arm = build_armature(context, articulation, size=size, name=f"ArtGS Joints {path.stem}")
    arm[URDF_KEY] = str(path.resolve())
    context.view_layer.update()
    made = skipped = 0
    for link, visuals in model.visuals.items():
        for k, visual in enumerate(visuals):
            obj = _visual_object(context, visual, f"{link}_{k}" if k else link)
            if obj is None:
                skipped += 1
                continue
            world = model.link_poses[link] @ visual.origin @ np.diag([*visual.scale, 1.0])
            joint = model.moving_link.get(link)
            obj.parent = arm
            if joint:
                obj.parent_type = "BONE"
                obj.parent_bone = joint
            context.view_layer.update()
            obj.matrix_world = Matrix(world.tolist())
            obj["artgs_link"] = link
            made += 1
    context.view_layer.update()
    return arm, made, skipped


def write_edited_urdf(arm: bpy.types.Object, dst: str | Path) -> Path:
    """Write a copy of the armature's source URDF with the joints as edited on the armature."""
    src = arm.get(URDF_KEY)
    if not src:
        raise ValueError(f"'{arm.name}' was not imported from a URDF")
    rewrite_joints(src, read_joints(arm), dst)
    return Path(dst)


def _visual_object(context: bpy.types.Context, visual: Visual, name: str) -> bpy.types.Object | None:
    """A new mesh object holding the visual's geometry in its link-local coordinates."""
    if visual.box is not None:
        return _box(context, visual.box, name)
    if visual.path is None or not visual.path.is_file():
        return None
    suffix = visual.path.suffix.lower()
    before = set(bpy.data.objects)
    if suffix == ".obj":
        bpy.ops.wm.obj_import(filepath=str(visual.path), forward_axis="Y", up_axis="Z")
    elif suffix == ".stl" and hasattr(bpy.ops.wm, "stl_import"):
        bpy.ops.wm.stl_import(filepath=str(visual.path), forward_axis="Y", up_axis="Z")
    else:
        return None
    new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
    if not new:
        return None
    if len(new) > 1:                       # several objects in one file: join them
        with context.temp_override(active_object=new[0], selected_editable_objects=new,
                                   selected_objects=new):
            bpy.ops.object.join()
    obj = new[0]
    obj.name = name
    obj.matrix_world = Matrix.Identity(4)
    return obj


def _box(context: bpy.types.Context, size: np.ndarray, name: str) -> bpy.types.Object:
    h = np.asarray(size, float) / 2
    verts = [(sx * h[0], sy * h[1], sz * h[2]) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    obj = bpy.data.objects.new(name, mesh)
    context.collection.objects.link(obj)
    return obj
