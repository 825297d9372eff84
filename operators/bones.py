"""Operators to edit the joints armature: add, remove, select a joint, save the joints."""

from __future__ import annotations

from typing import Callable

import bpy
from bpy.props import EnumProperty, StringProperty

from ..artgs_addon.armature import (OUTPUT_KEY, add_joint, armature_name, build_armature,
                                    find_armature, output_key, remove_joint, save_joints)
from ..artgs_addon.bone_pose import select_only
from ..artgs_addon.bone_props import JOINT_TYPE_ITEMS
from ..core.model.errors import ArtgsError
from ..core.model.joints import Articulation
from ..core.model.layout import PROPOSALS

_EDIT_MODES = ("OBJECT", "POSE", "EDIT_ARMATURE")


def _active_bone_name(obj: bpy.types.Object) -> str | None:
    bones = obj.data.edit_bones if obj.mode == "EDIT" else obj.data.bones
    return bones.active.name if bones.active is not None else None


def _run(op: bpy.types.Operator, action: Callable[[], str]) -> set[str]:
    """Run ``action`` (it returns the message for the status bar); report errors, don't raise."""
    try:
        message = action()
    except (ArtgsError, OSError) as exc:
        op.report({"ERROR"}, str(exc))
        return {"CANCELLED"}
    op.report({"INFO"}, message)
    return {"FINISHED"}


def _object_size(context: bpy.types.Context) -> float:
    """Size for a new armature: the splat preview's largest dimension, else 1 m."""
    settings = getattr(context.scene, "artgs", None)
    preview = getattr(settings, "splat_object", None)
    size = max(preview.dimensions) if preview is not None else 0.0
    return size if size > 0 else 1.0


class ARTGS_OT_add_joint(bpy.types.Operator):
    """Add a joint (bone) at the 3D cursor, about the world Z axis; creates the output folder's
    armature if needed"""

    bl_idname = "artgs.add_joint"
    bl_label = "Add Joint"
    bl_options = {"REGISTER", "UNDO"}

    joint_type: EnumProperty(name="Type", items=JOINT_TYPE_ITEMS, default="revolute")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return context.scene is not None and context.mode in _EDIT_MODES

    def execute(self, context: bpy.types.Context) -> set[str]:
        def add() -> str:
            obj = find_armature(context)
            if obj is None:
                settings = context.scene.artgs
                obj = build_armature(context, Articulation([]), size=_object_size(context),
                                     name=armature_name(settings.capture_path,
                                                        settings.output_path),
                                     output=settings.output_path)
            name = add_joint(context, obj, context.scene.cursor.location, (0.0, 0.0, 1.0),
                             self.joint_type)
            return f"Added {self.joint_type} joint '{name}' to '{obj.name}'"

        return _run(self, add)


class ARTGS_OT_remove_joint(bpy.types.Operator):
    """Remove the active joint (bone); its points go back to the base"""

    bl_idname = "artgs.remove_joint"
    bl_label = "Remove Joint"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        if context.mode not in _EDIT_MODES:
            return False
        obj = find_armature(context)
        if obj is None or _active_bone_name(obj) is None:
            cls.poll_message_set("Select a joint (bone) first")
            return False
        return True

    def execute(self, context: bpy.types.Context) -> set[str]:
        obj = find_armature(context)
        name = _active_bone_name(obj)

        def remove() -> str:
            remove_joint(context, obj, name)
            return f"Removed joint '{name}'"

        return _run(self, remove)


class ARTGS_OT_select_joint(bpy.types.Operator):
    """Make this joint (bone) the active one"""

    bl_idname = "artgs.select_joint"
    bl_label = "Select Joint"
    bl_options = {"REGISTER", "UNDO"}

    name: StringProperty(name="Joint", description="Name of the joint's bone")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return find_armature(context) is not None

    def execute(self, context: bpy.types.Context) -> set[str]:
        obj = find_armature(context)
        if not select_only(obj, self.name):
            self.report({"ERROR"}, f"No joint named '{self.name}' in '{obj.name}'")
            return {"CANCELLED"}
        return {"FINISHED"}


class ARTGS_OT_save_joints(bpy.types.Operator):
    """Write the output folder's joints, with your edits, to proposals.json there; later stages use them"""

    bl_idname = "artgs.save_joints"
    bl_label = "Save Joints"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        if find_armature(context) is None:
            cls.poll_message_set("No joints armature for this output folder in the scene")
            return False
        settings = getattr(context.scene, "artgs", None)
        if settings is None or settings.output_path is None:
            cls.poll_message_set("Choose an output folder first")
            return False
        return True

    def execute(self, context: bpy.types.Context) -> set[str]:
        obj = find_armature(context)
        output = context.scene.artgs.output_path
        path = output / PROPOSALS

        def save() -> str:
            joints = save_joints(obj, path)
            obj[OUTPUT_KEY] = output_key(output)  # an armature of no folder now belongs to this one
            edited = sum(j.source == "user" for j in joints)
            return f"Saved {len(joints)} joints ({edited} by the user) to {path}"

        return _run(self, save)


CLASSES = (ARTGS_OT_add_joint, ARTGS_OT_remove_joint, ARTGS_OT_select_joint, ARTGS_OT_save_joints)
