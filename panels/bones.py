"""The Bones panel: propose joints (with the stage's state), list the joints of the output folder's
armature, edit the active one, add/remove/save."""

from __future__ import annotations

import bpy

from ..artgs_addon.armature import find_armature
from .common import draw_figures, draw_state

ICONS = {"revolute": "ORIENTATION_GIMBAL", "prismatic": "EMPTY_SINGLE_ARROW"}


class ARTGS_PT_bones(bpy.types.Panel):
    """Joints as bones: propose them, then edit them in the viewport or here, then save them."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "ArtGS"
    bl_parent_id = "ARTGS_PT_pipeline"
    bl_label = "Bones"

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        settings = getattr(context.scene, "artgs", None)
        if settings is not None:
            row = layout.row(align=True)
            row.prop(settings, "proposal_method", text="")
            row.operator("artgs.propose_bones", icon="BONE_DATA")
            draw_state(layout, settings.propose)
            draw_figures(layout, context, "propose")
        row = layout.row(align=True)
        row.operator("artgs.add_joint", icon="ADD", text="Add")
        row.operator("artgs.remove_joint", icon="REMOVE", text="Remove")
        row.operator("artgs.save_joints", icon="FILE_TICK", text="Save")

        obj = find_armature(context)
        if obj is None:
            layout.label(text="No joints yet: propose or add one", icon="INFO")
            return
        layout.label(text=obj.name, icon="ARMATURE_DATA")
        bones = obj.data.edit_bones if obj.mode == "EDIT" else obj.data.bones
        col = layout.column(align=True)
        for bone in bones:
            props = bone.artgs_joint
            op = col.operator("artgs.select_joint", text=bone.name,
                              icon=ICONS[props.joint_type], depress=bone == bones.active)
            op.name = bone.name
        active = bones.active
        if active is None:
            return
        self._draw_joint(layout.box(), active)

    @staticmethod
    def _draw_joint(box: bpy.types.UILayout, bone) -> None:
        props = bone.artgs_joint
        box.prop(bone, "name", text="Joint")
        box.prop(props, "joint_type")
        kind = "angle" if props.joint_type == "revolute" else "distance"
        row = box.row(align=True)
        row.prop(props, f"lower_{kind}")
        row.prop(props, f"upper_{kind}")
        box.prop(props, "parent_link")
        box.prop(props, "child_link")
        box.prop(props, "source")
        if props.built:
            row = box.row()
            row.enabled = False
            row.prop(props, "confidence")
        box.label(text="Axis: head to tail of the bone (move it in Edit Mode)", icon="INFO")


CLASSES = (ARTGS_PT_bones,)
