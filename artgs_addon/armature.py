"""Joints as an editable Blender armature, and the (edited) joints read back from it.

One armature object per articulated object, one bone per joint, named after the joint. The armature
of an output folder is named after its capture (``armature_name``) and records the folder
(``OUTPUT_KEY`` on the object), so several objects can share a scene: ``find_armature`` only
returns the armature of the scene's current output folder (or one not yet tied to any folder). The bone IS
the joint axis: head = the joint origin (a point on the hinge line; for a prismatic joint a point of
the moving part), tail = head + axis * length. Roll carries no meaning. In pose mode a revolute
bone only rotates about its own Y axis (head to tail) and a prismatic bone only slides along it,
within the limits (channel locks plus a Limit Rotation / Limit Location constraint in local space).
Revolute bones are blue, prismatic bones green.

Each bone keeps the joint as built (or last saved) as JSON in ``Bone.artgs_joint.built``:
``read_joints`` returns it unchanged while the bone still matches it, otherwise the joint read from
the bone with ``source: "user"`` and the other fields (extent, handle, states ...) kept.
"""

from __future__ import annotations

import json
import math
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import bpy
import numpy as np
from mathutils import Matrix, Vector

from ..core.model.errors import ArtgsError, InputError
from ..core.model.joints import Articulation, Joint, read_articulation, write_articulation
from ..core.geometry.parts import assign_parts
from .bone_pose import COLOURS, refresh_bone, select_only, set_joint_value

SIZE_KEY = "artgs_size"    # on the armature data: object size in metres; marks ArtGS armatures
META_KEY = "artgs_meta"    # on the armature data: the joints file's top-level fields (JSON)
NAME_KEY = "artgs_name"    # on the armature data: the ``name`` it was built under
OUTPUT_KEY = "artgs_output"  # on the armature object: the output folder its joints belong to
BONE_LENGTH = 0.25         # bone length as a fraction of the object size
MODIFIER = "ArtGS Joints"
NEW_LIMITS = {"revolute": (0.0, math.pi / 2), "prismatic": (0.0, 0.5)}  # prismatic: x object size
_MAX_NAME_BYTES = 63       # Blender truncates longer bone names
_FIX_SCALE = "Object > Apply > Scale (Ctrl+A)"


def is_joint_armature(obj: bpy.types.Object | None) -> bool:
    """Whether ``obj`` is an armature made by ``build_armature``."""
    return obj is not None and obj.type == "ARMATURE" and SIZE_KEY in obj.data


def armature_name(capture: Path | None, output: Path | None) -> str:
    """Name of an object's joints armature: "ArtGS Joints <capture folder name>" (else the output
    folder's name)."""
    folder = capture if capture is not None and capture.name else output
    return f"ArtGS Joints {folder.name}" if folder is not None and folder.name else "ArtGS Joints"


def output_key(output: Path) -> str:
    """How an output folder is recorded on its armature (``OUTPUT_KEY``)."""
    return str(Path(output).resolve())


def find_armature(context: bpy.types.Context) -> bpy.types.Object | None:
    """The joints armature to work on: the active one, the active preview's, else the first in the
    scene; with an output folder in the scene settings, only the armature recorded for that folder
    qualifies, or, if there is none, one recorded for no folder (never another folder's)."""
    active = context.active_object
    candidates = [o for o in (active, active.parent if active is not None else None,
                              *context.scene.objects) if is_joint_armature(o)]
    settings = getattr(context.scene, "artgs", None)
    output = settings.output_path if settings is not None else None
    if output is not None:
        key = output_key(output)
        candidates = ([o for o in candidates if o.get(OUTPUT_KEY) == key]
                      or [o for o in candidates if OUTPUT_KEY not in o])
    return candidates[0] if candidates else None


def previews_of(obj: bpy.types.Object) -> list[bpy.types.Object]:
    """Mesh objects deformed by the armature ``obj``."""
    return [o for o in bpy.data.objects if o.type == "MESH"
            and any(m.type == "ARMATURE" and m.object == obj for m in o.modifiers)]


def check_transform(obj: bpy.types.Object) -> None:
    """Refuse a zero or negative (mirroring) scale: rotations would turn the wrong way."""
    det = float(np.linalg.det(np.array(obj.matrix_world)[:3, :3]))
    if not det > 1e-12:
        scale = tuple(round(v, 4) for v in obj.matrix_world.to_scale())
        kind = "a negative (mirroring)" if det < 0 else "a zero"
        raise ArtgsError(f"Armature '{obj.name}' has {kind} scale {scale}, so its joints would "
                         f"turn the wrong way; apply the scale first: {_FIX_SCALE}")


def build_armature(context: bpy.types.Context, articulation: Articulation,
                   preview: bpy.types.Object | None = None, size: float = 1.0,
                   name: str = "ArtGS Joints", output: Path | None = None,
                   labels: np.ndarray | None = None) -> bpy.types.Object:
    """Create, or rebuild in place, the armature ``name`` with one bone per joint (world frame).

    With ``output`` the armature recorded for that output folder is rebuilt (a new one records
    it); without, the one built under ``name`` for no folder. It is rebuilt even if the user
    renamed it and keeps its object transform: bones are placed so the joints are right in the
    world. With ``preview`` (a mesh whose vertices are the object's points), each joint's points
    (``core.parts.assign_parts``) go to a vertex group named after its bone and an Armature
    modifier deforms them, so posing a bone moves its part; the preview is parented to the armature.
    ``labels`` (per preview vertex: 0 base, k joint k, e.g. the optimisation's part labels)
    replace the assignment by the joints' boxes.
    """
    if not (math.isfinite(size) and size > 0):
        raise ArtgsError(f"object size must be a positive number of metres, not {size}")
    for joint in articulation.joints:
        if len(joint.name.encode("utf-8")) > _MAX_NAME_BYTES:
            raise ArtgsError(f"joint '{joint.name}': name longer than {_MAX_NAME_BYTES} bytes, "
                             f"too long for a Blender bone; rename it")
    if preview is not None and preview.type != "MESH":
        raise ArtgsError(f"preview '{preview.name}' must be a mesh object, not {preview.type}")
    obj = _built_before(name, output)
    if obj is None:
        obj = bpy.data.objects.new(name, bpy.data.armatures.new(name))
        context.collection.objects.link(obj)
        obj.show_in_front = True
        obj.data[NAME_KEY] = name
        if output is not None:
            obj[OUTPUT_KEY] = output_key(output)
    context.view_layer.update()
    check_transform(obj)
    arm = obj.data
    arm[SIZE_KEY] = float(size)
    arm[META_KEY] = json.dumps(articulation.meta)
    old_names = [b.name for b in arm.bones]
    to_arm = obj.matrix_world.inverted()
    by_link = {j.child: j.name for j in articulation.joints}
    with edit_mode(context, obj) as bones:
        for eb in list(bones):
            bones.remove(eb)
        for joint in articulation.joints:
            eb = bones.new(joint.name)
            _place(eb, to_arm, joint.origin, joint.axis, BONE_LENGTH * size)
            _fill(eb.artgs_joint, joint)
        for joint in articulation.joints:
            parent = by_link.get(joint.parent)
            if parent is not None and parent != joint.name:
                bones[joint.name].parent = bones[parent]
    for bone in arm.bones:
        refresh_bone(obj, bone.name)
        set_joint_value(obj, bone.name, 0.0)
    if preview is not None:
        _bind_preview(obj, preview, articulation.joints, old_names, labels)
    obj.select_set(True)
    context.view_layer.objects.active = obj
    return obj


def _built_before(name: str, output: Path | None) -> bpy.types.Object | None:
    """The joints armature recorded for ``output``, or (without a folder) the one built under
    ``name`` for no folder; the one still called ``name`` first."""
    arms = [o for o in bpy.data.objects if is_joint_armature(o)]
    if output is not None:
        found = [o for o in arms if o.get(OUTPUT_KEY) == output_key(output)]
    else:
        found = [o for o in arms if OUTPUT_KEY not in o and o.data.get(NAME_KEY) == name]
    return next((o for o in found if o.name == name), found[0] if found else None)


def read_joints(obj: bpy.types.Object) -> list[Joint]:
    """The joints of the armature ``obj`` in the world frame, edits included (also in edit mode)."""
    if not is_joint_armature(obj):
        raise ArtgsError(f"'{obj.name}' is not an ArtGS joints armature")
    check_transform(obj)
    if obj.mode == "EDIT":
        obj.update_from_editmode()
    size = float(obj.data[SIZE_KEY])
    M = np.array(obj.matrix_world)
    return [_read_bone(M, bone, size) for bone in obj.data.bones]


def joint_of_bone(obj: bpy.types.Object, name: str) -> Joint:
    """The joint drawn by bone ``name`` (rest pose, world frame), ignoring what was built."""
    return _bone_joint(np.array(obj.matrix_world), obj.data.bones[name])


def add_joint(context: bpy.types.Context, obj: bpy.types.Object, origin, axis=(0.0, 0.0, 1.0),
              joint_type: str = "revolute", name: str = "joint") -> str:
    """Add a user joint at world ``origin`` along world ``axis``; returns its (unique) bone name."""
    check_transform(obj)
    size = float(obj.data[SIZE_KEY])
    to_arm = obj.matrix_world.inverted()
    lower, upper = NEW_LIMITS[joint_type]
    if joint_type == "prismatic":
        lower, upper = lower * size, upper * size
    with edit_mode(context, obj) as bones:
        eb = bones.new(name)
        _place(eb, to_arm, np.asarray(origin, float), np.asarray(axis, float), BONE_LENGTH * size)
        props = eb.artgs_joint
        props.joint_type = joint_type
        props.lower, props.upper = lower, upper
        props.parent_link, props.child_link, props.source = "base", f"{eb.name}_link", "user"
        eb.color.palette = COLOURS[joint_type]
        name = eb.name
        select_only(obj, name)
    refresh_bone(obj, name)
    return name


def remove_joint(context: bpy.types.Context, obj: bpy.types.Object, name: str) -> None:
    """Remove joint (bone) ``name``; its points go back to the base in the previews."""
    if name not in obj.data.bones and not (obj.mode == "EDIT" and name in obj.data.edit_bones):
        raise ArtgsError(f"no joint named '{name}' in '{obj.name}'")
    with edit_mode(context, obj) as bones:
        bones.remove(bones[name])
    for preview in previews_of(obj):
        group = preview.vertex_groups.get(name)
        if group is not None:
            preview.vertex_groups.remove(group)


def save_joints(obj: bpy.types.Object, path: str | Path) -> list[Joint]:
    """Write the armature's joints to ``path`` atomically, keeping the file's other fields.

    The saved joints become the new reference: they read back unchanged until edited again.
    Pose locks and constraints are refreshed too (bones added by hand, a rescaled armature).
    """
    joints = read_joints(obj)
    path = Path(path)
    meta = json.loads(obj.data.get(META_KEY, "{}"))
    if path.is_file():
        try:
            meta = read_articulation(path).meta
        except InputError:
            pass  # an unreadable file is replaced; the armature's stored fields are used
    write_articulation(path, Articulation(joints, meta))
    obj.data[META_KEY] = json.dumps(meta)
    by_name = {j.name: j for j in joints}
    bones = obj.data.edit_bones if obj.mode == "EDIT" else obj.data.bones
    for bone in bones:
        joint = by_name[bone.name]
        bone.artgs_joint.built = json.dumps(joint.to_dict())
        bone.artgs_joint.source = joint.source or "user"
    for name in by_name:
        refresh_bone(obj, name, obj.data.edit_bones[name].artgs_joint if obj.mode == "EDIT" else None)
    return joints








@contextmanager
def edit_mode(context: bpy.types.Context, obj: bpy.types.Object) -> Iterator:
    """Edit the bones of ``obj`` (yields its edit bones), then return to its previous mode.

    Edit mode is always left once so new bones get their pose bones; the armature ends up active.
    """
    if not obj.visible_get(view_layer=context.view_layer):
        raise ArtgsError(f"Armature '{obj.name}' is hidden or not in this view layer; show it "
                         f"(Object > Show/Hide > Show Hidden Objects, Alt+H) to edit its joints")
    previous = obj.mode
    if context.view_layer.objects.active is not obj and context.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    context.view_layer.objects.active = obj
    if previous != "EDIT":
        bpy.ops.object.mode_set(mode="EDIT")
    try:
        yield obj.data.edit_bones
    finally:
        bpy.ops.object.mode_set(mode="OBJECT")
        if previous in ("EDIT", "POSE"):
            bpy.ops.object.mode_set(mode=previous)


def place_joints(context: bpy.types.Context, obj: bpy.types.Object,
                 lines: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """Move the bones named in ``lines`` onto new world-frame joint lines ``(origin, axis)``
    (e.g. while an optimisation converges); other bones and every joint property stay."""
    to_arm = obj.matrix_world.inverted()
    length = BONE_LENGTH * float(obj.data[SIZE_KEY])
    with edit_mode(context, obj) as bones:
        for name, (origin, axis) in lines.items():
            eb = bones.get(name)
            if eb is not None and np.linalg.norm(axis) > 0:
                _place(eb, to_arm, np.asarray(origin, float), np.asarray(axis, float), length)


def _place(eb: bpy.types.EditBone, to_arm: Matrix, origin: np.ndarray, axis: np.ndarray,
           length: float) -> None:
    """Put edit bone ``eb`` on the world-frame line from ``origin`` along ``axis``."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    eb.head = to_arm @ Vector(origin)
    eb.tail = to_arm @ Vector(np.asarray(origin, float) + axis * length)
    eb.roll = 0.0
    eb.use_deform = True


def _fill(props, joint: Joint) -> None:
    props.joint_type = joint.type
    props.lower, props.upper = joint.limit
    props.parent_link = joint.parent
    props.child_link = joint.child
    props.source = joint.source or "user"
    props.built = json.dumps(joint.to_dict())


def _read_bone(M: np.ndarray, bone: bpy.types.Bone, size: float) -> Joint:
    props = bone.artgs_joint
    joint = _bone_joint(M, bone)
    if not props.built:
        return joint
    built = Joint.from_dict(json.loads(props.built), f"bone '{bone.name}'")
    if _same(joint, built, size):
        if props.source != (built.source or "user"):
            built.source = props.source
        return built
    for key in ("states", "confidence", "bbox", "handle", "extent", "extra"):
        setattr(joint, key, getattr(built, key))
    return joint


def _bone_joint(M: np.ndarray, bone: bpy.types.Bone) -> Joint:
    """The joint drawn by ``bone`` under the object matrix ``M`` (4x4)."""
    head = M[:3, :3] @ np.array(bone.head_local) + M[:3, 3]
    tail = M[:3, :3] @ np.array(bone.tail_local) + M[:3, 3]
    p = bone.artgs_joint
    if p.lower > p.upper:
        raise ArtgsError(f"joint '{bone.name}': lower limit {p.lower:g} is above the upper limit "
                         f"{p.upper:g}; fix it in the Bones panel")
    return Joint(name=bone.name, type=p.joint_type, axis=tail - head, origin=head,
                 limit=(p.lower, p.upper), parent=p.parent_link or "base",
                 child=p.child_link or f"{bone.name}_link", source="user")


def _same(a: Joint, b: Joint, size: float) -> bool:
    """Same joint up to the float32 precision of bones and properties."""
    reach = max(1.0, size, float(np.abs(b.origin).max()))  # float32 error grows with coordinates
    tol_pos = 1e-5 * reach
    tol_axis = 1e-5 * reach / (BONE_LENGTH * size)
    return (a.name == b.name and a.type == b.type and a.parent == b.parent and a.child == b.child
            and float(np.linalg.norm(a.axis - b.axis)) <= tol_axis
            and float(np.linalg.norm(a.origin - b.origin)) <= tol_pos
            and all(abs(x - y) <= 1e-6 * max(1.0, abs(y)) for x, y in zip(a.limit, b.limit)))




def _bind_preview(obj: bpy.types.Object, preview: bpy.types.Object, joints: list[Joint],
                  old_names: list[str], labels: np.ndarray | None = None) -> None:
    """Vertex groups from the part labels, an Armature modifier, and parenting to ``obj``."""
    mesh = preview.data
    if labels is None:
        co = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", co)
        Mw = np.array(preview.matrix_world)
        labels = assign_parts(co.reshape(-1, 3) @ Mw[:3, :3].T + Mw[:3, 3], joints)
    for name in set(old_names) | {j.name for j in joints}:
        group = preview.vertex_groups.get(name)
        if group is not None:
            preview.vertex_groups.remove(group)
    for i, joint in enumerate(joints):
        group = preview.vertex_groups.new(name=joint.name)
        members = np.flatnonzero(labels == i + 1)
        if len(members):
            group.add(members.tolist(), 1.0, "REPLACE")
    for mod in [m for m in preview.modifiers if m.type == "ARMATURE" and m.object == obj]:
        preview.modifiers.remove(mod)
    mod = preview.modifiers.new(MODIFIER, "ARMATURE")
    mod.object = obj
    mod.use_vertex_groups = True
    mod.use_bone_envelopes = False
    world = preview.matrix_world.copy()
    preview.parent = obj
    preview.parent_type = "OBJECT"
    preview.matrix_parent_inverse = obj.matrix_world.inverted()
    preview.matrix_basis = world
