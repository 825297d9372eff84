"""Joint settings of a bone, ``Bone.artgs_joint`` (also on ``EditBone``, sharing the same data).

Registered on both bone types so the settings can be read and edited in every mode; Blender copies a
bone's properties into edit mode and back, so they survive edit mode. Limits are stored once
(``lower``/``upper``, radians or metres in the world frame); ``*_angle`` and ``*_distance`` are
views of the same values with angle or length units for the panel. Changing the type or a limit
updates the bone's pose locks, limit constraint and colour at once (see bone_pose.py).
"""

from __future__ import annotations

import json

import bpy
from bpy.props import EnumProperty, FloatProperty, PointerProperty, StringProperty

from .bone_pose import refresh_joint_bone

JOINT_TYPE_ITEMS = (
    ("revolute", "Revolute", "Rotates about the bone (head to tail is the hinge axis)"),
    ("prismatic", "Prismatic", "Slides along the bone (head to tail is the slide direction)"),
)
SOURCE_ITEMS = (
    ("vlm", "VLM", "Proposed by a vision-language model"),
    ("motion", "Motion", "Proposed from motion in the interaction frames"),
    ("user", "User", "Added or edited by hand"),
    ("optimise", "Optimise", "Found by the optimisation: a moving part the proposals missed"),
)


def _changed(self: "ArtgsJointProps", context: bpy.types.Context | None) -> None:
    refresh_joint_bone(self)


def _view(key: str) -> dict:
    """``get``/``set`` arguments exposing the stored ``key`` under another unit subtype."""
    def get(self: "ArtgsJointProps") -> float:
        return getattr(self, key)

    def set_(self: "ArtgsJointProps", value: float) -> None:
        setattr(self, key, value)

    return {"get": get, "set": set_}


def _confidence(self: "ArtgsJointProps") -> float:
    if not self.built:
        return 0.0
    return float(json.loads(self.built).get("confidence") or 0.0)


class ArtgsJointProps(bpy.types.PropertyGroup):
    """The joint a bone stands for; its axis and origin are the bone itself (head to tail)."""

    joint_type: EnumProperty(name="Type", items=JOINT_TYPE_ITEMS, default="revolute",
                             update=_changed)
    lower: FloatProperty(name="Lower", description="Lower limit, radians or metres",
                         update=_changed)
    upper: FloatProperty(name="Upper", description="Upper limit, radians or metres",
                         update=_changed)
    lower_angle: FloatProperty(name="Lower", subtype="ANGLE", unit="ROTATION",
                               description="Lowest angle of the joint",
                               **_view("lower"))
    upper_angle: FloatProperty(name="Upper", subtype="ANGLE", unit="ROTATION",
                               description="Highest angle of the joint",
                               **_view("upper"))
    lower_distance: FloatProperty(name="Lower", subtype="DISTANCE", unit="LENGTH",
                                  description="Lowest slide of the joint",
                                  **_view("lower"))
    upper_distance: FloatProperty(name="Upper", subtype="DISTANCE", unit="LENGTH",
                                  description="Highest slide of the joint",
                                  **_view("upper"))
    parent_link: StringProperty(name="Parent Link", default="base",
                                description="Link the joint is attached to ('base' or another "
                                            "joint's child link)")
    child_link: StringProperty(name="Child Link", description="Link the joint moves")
    source: EnumProperty(name="Source", items=SOURCE_ITEMS, default="user",
                         description="Where the joint came from")
    confidence: FloatProperty(name="Confidence", subtype="FACTOR", get=_confidence,
                              description="Confidence of the proposal (read-only)")
    built: StringProperty(name="Built", options={"HIDDEN"},
                          description="The joint as built or last saved (JSON), to tell edits")


CLASSES = (ArtgsJointProps,)


def register_properties() -> None:
    """Add ``artgs_joint`` to bones and edit bones (after ``CLASSES`` are registered)."""
    bpy.types.Bone.artgs_joint = PointerProperty(type=ArtgsJointProps)
    bpy.types.EditBone.artgs_joint = PointerProperty(type=ArtgsJointProps)


def unregister_properties() -> None:
    """Remove what ``register_properties`` added (before ``CLASSES`` are unregistered)."""
    del bpy.types.EditBone.artgs_joint
    del bpy.types.Bone.artgs_joint
