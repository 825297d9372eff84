"""The pose side of a joint bone: channel locks, limit constraints, colour, joint value, selection.

Shared by the armature builder (armature.py) and the joint settings' update callback
(bone_props.py), so neither imports the other. Selection follows the running Blender: 4.x keeps
a bone's selection on ``Bone.select``, 5.x on ``PoseBone.select`` (edit bones keep theirs in both).
"""

from __future__ import annotations

import bpy

COLOURS = {"revolute": "THEME04", "prismatic": "THEME03"}  # bone colour palettes: blue, green
CONSTRAINT = "ArtGS Limit"


def select_only(obj: bpy.types.Object, name: str) -> bool:
    """Select bone ``name`` of the armature ``obj`` alone and make it active, in any mode
    (Object, Pose, Edit) and on Blender 4.x and 5.x; False if there is no such bone."""
    if obj.mode == "EDIT":
        bones = obj.data.edit_bones
        bone = bones.get(name)
        if bone is None:
            return False
        for other in bones:
            other.select = other.select_head = other.select_tail = False
        bone.select = bone.select_head = bone.select_tail = True
        bones.active = bone
        return True
    bone = obj.data.bones.get(name)
    if bone is None:
        return False
    for other in _selectables(obj):
        other.select = False
    _selectable(obj, name).select = True
    obj.data.bones.active = bone
    return True


def is_selected(obj: bpy.types.Object, name: str) -> bool:
    """Whether bone ``name`` is selected (edit bones in Edit mode, else the bone's pose selection)."""
    if obj.mode == "EDIT":
        return bool(obj.data.edit_bones[name].select)
    return bool(_selectable(obj, name).select)


def _pose_selection() -> bool:
    """Blender 5.x keeps bone selection on pose bones."""
    return "select" in bpy.types.PoseBone.bl_rna.properties


def _selectables(obj: bpy.types.Object):
    return obj.pose.bones if _pose_selection() else obj.data.bones


def _selectable(obj: bpy.types.Object, name: str):
    return obj.pose.bones[name] if _pose_selection() else obj.data.bones[name]



def set_joint_value(obj: bpy.types.Object, name: str, value: float) -> None:
    """Pose bone ``name`` at joint value ``value`` (radians, or metres in the world)."""
    pb = obj.pose.bones[name]
    pb.location = (0.0, 0.0, 0.0)
    pb.rotation_euler = (0.0, 0.0, 0.0)
    pb.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
    pb.scale = (1.0, 1.0, 1.0)
    if obj.data.bones[name].artgs_joint.joint_type == "revolute":
        pb.rotation_euler = (0.0, value, 0.0)
    else:
        pb.location = (0.0, value / world_per_unit(obj, name), 0.0)


def refresh_bone(obj: bpy.types.Object, name: str, props=None) -> None:
    """Set bone ``name``'s pose locks, limit constraint and colour from its joint settings.

    ``props`` are the settings to use (default: the bone's; in edit mode, the edit bone's).
    """
    bone = obj.data.bones.get(name)
    pb = obj.pose.bones.get(name)
    if bone is None or pb is None:
        return  # a bone added in edit mode gets its pose bone when edit mode ends
    if props is None:
        props = bone.artgs_joint
        bone.color.palette = COLOURS[props.joint_type]
    revolute = props.joint_type == "revolute"
    pb.rotation_mode = "XYZ"
    pb.lock_location = (True, revolute, True)
    pb.lock_rotation = (True, not revolute, True)
    pb.lock_rotation_w = True
    pb.lock_scale = (True, True, True)
    for con in [c for c in pb.constraints if c.name.startswith(CONSTRAINT)]:
        pb.constraints.remove(con)
    # every channel is limited (locks only guide the interactive tools): zero but the joint's own
    rot = pb.constraints.new("LIMIT_ROTATION")
    rot.name = f"{CONSTRAINT} Rotation"
    rot.use_limit_x = rot.use_limit_y = rot.use_limit_z = True
    loc = pb.constraints.new("LIMIT_LOCATION")
    loc.name = f"{CONSTRAINT} Location"
    for axis in "xyz":
        setattr(loc, f"use_min_{axis}", True)
        setattr(loc, f"use_max_{axis}", True)
    if revolute:
        rot.min_y, rot.max_y = props.lower, props.upper
    else:
        unit = world_per_unit(obj, name)
        loc.min_y, loc.max_y = props.lower / unit, props.upper / unit
    for con in (rot, loc):
        con.owner_space = "LOCAL"
        con.use_transform_limit = True


def refresh_joint_bone(props) -> None:
    """Update callback of the joint settings: refresh the bone they belong to, in every user."""
    arm = props.id_data
    if not isinstance(arm, bpy.types.Armature):
        return
    ptr = props.as_pointer()
    owner = next((b for b in (*arm.edit_bones, *arm.bones) if b.artgs_joint.as_pointer() == ptr),
                 None)
    if owner is None:
        return
    owner.color.palette = COLOURS[props.joint_type]
    for obj in bpy.data.objects:
        if obj.data == arm and obj.pose is not None:
            refresh_bone(obj, owner.name, props)


def world_per_unit(obj: bpy.types.Object, name: str) -> float:
    """World metres per armature unit along bone ``name`` (its pose Y axis)."""
    bone = obj.data.bones[name]
    direction = (bone.tail_local - bone.head_local).normalized()
    return (obj.matrix_world.to_3x3() @ direction).length