"""Joints as a Blender armature (bpy, background): build, pose, limits, read back, edit, operators."""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
from mathutils import Matrix, Vector  # noqa: E402

import artgs  # noqa: E402
from artgs.artgs_addon import armature, bone_pose, bone_props  # noqa: E402
from artgs.core.model.errors import ArtgsError  # noqa: E402
from artgs.core.model.joints import Articulation, Joint, read_articulation, write_articulation  # noqa: E402
from artgs.operators import bones as bone_operators  # noqa: E402
from artgs.panels import bones as bone_panel  # noqa: E402
from engine_env import TESTS, engine_python  # noqa: E402

DEG = math.pi / 180
_BONE_CLASSES = [c for m in (bone_props, bone_operators, bone_panel) for c in m.CLASSES]


def _box(center, half, axes=np.eye(3)) -> dict:
    return {"center": list(map(float, center)), "axes": np.asarray(axes, float).tolist(),
            "half_size": list(map(float, half))}


def _articulation() -> Articulation:
    """A cabinet: a door hinged on a tilted axis, a drawer sliding out along -y (world frame)."""
    hinge = np.array([0.05, 0.0, 1.0])
    door = Joint("door", "revolute", hinge, [0.5, -0.3, 0.1], (-0.2, 1.4), child="door_link",
                 source="vlm", confidence=0.8, bbox=[10, 20, 30, 40],
                 handle={"point": [0.1, -0.35, 0.5], "approach": [0, -1, 0]},
                 extent=_box([0.25, -0.3, 0.55], [0.25, 0.02, 0.45]))
    drawer = Joint("drawer", "prismatic", [0, -1, 0], [-0.3, -0.25, 0.2], (0.0, 0.35),
                   source="motion", states={0: 0.0, 1: 0.1},
                   extent=_box([-0.3, -0.2, 0.2], [0.2, 0.1, 0.08]))
    return Articulation([door, drawer], {"view": 3, "capture": "/data/cab"})


def _points(art: Articulation, n: int = 60, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points inside each part's box (label i+1) and base points far from them (label 0)."""
    rng = np.random.default_rng(seed)
    chunks, labels = [], []
    for i, j in enumerate(art.joints):
        half = np.asarray(j.extent["half_size"]) * 0.9
        chunks.append(rng.uniform(-1, 1, (n, 3)) * half + j.extent["center"])
        labels.append(np.full(n, i + 1))
    chunks.append(rng.uniform(-1, 1, (n, 3)) * 0.4 + [0.0, 1.5, 0.4])
    labels.append(np.zeros(n, int))
    return np.concatenate(chunks), np.concatenate(labels)


def _preview(ctx, points: np.ndarray, matrix: Matrix | None = None) -> bpy.types.Object:
    """A vertex-only mesh whose vertices are ``points`` in the world (under ``matrix``)."""
    matrix = matrix or Matrix.Identity(4)
    M = np.array(matrix)
    local = (points - M[:3, 3]) @ np.linalg.inv(M[:3, :3]).T
    mesh = bpy.data.meshes.new("splat")
    mesh.vertices.add(len(points))
    mesh.vertices.foreach_set("co", local.astype(np.float32).ravel())
    obj = bpy.data.objects.new("splat", mesh)
    ctx.collection.objects.link(obj)
    obj.matrix_world = matrix
    return obj


def _evaluated_world(ctx, obj) -> np.ndarray:
    ctx.view_layer.update()
    ev = obj.evaluated_get(ctx.evaluated_depsgraph_get())
    co = np.empty(3 * len(ev.data.vertices), np.float32)
    ev.data.vertices.foreach_get("co", co)
    M = np.array(ev.matrix_world)
    return co.reshape(-1, 3).astype(float) @ M[:3, :3].T + M[:3, 3]


def _apply(T: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ T[:3, :3].T + T[:3, 3]


def _transform() -> Matrix:
    """Rotation + translation + uniform scale."""
    return Matrix.LocRotScale(Vector((0.4, -1.2, 0.3)),
                              Matrix.Rotation(0.7, 3, Vector((0.3, 1.0, 0.2)).normalized()),
                              Vector((1.7, 1.7, 1.7)))


def _transformed_armature(ctx, matrix: Matrix) -> bpy.types.Object:
    """An existing (empty) joints armature moved by ``matrix``; later builds keep the transform."""
    obj = armature.build_armature(ctx, Articulation([]))
    obj.matrix_world = matrix
    ctx.view_layer.update()
    return obj


def _assert_joints_equal(got: list[Joint], want: list[Joint], tol: float = 1e-6) -> None:
    assert [j.name for j in got] == [j.name for j in want]
    for g, w in zip(got, want):
        gd, wd = g.to_dict(), w.to_dict()
        assert set(gd) == set(wd), g.name
        for key in ("axis", "origin", "limit"):
            np.testing.assert_allclose(gd[key], wd[key], atol=tol, err_msg=f"{g.name}.{key}")
        for key in set(wd) - {"axis", "origin", "limit"}:
            assert _close(gd[key], wd[key], tol), f"{g.name}.{key}: {gd[key]} != {wd[key]}"


def _close(got, want, tol: float = 1e-6) -> bool:
    """Equal, numbers within ``tol`` (a Blender round trip may change the last bits, which
    differ between CPUs), recursing into dicts and lists."""
    if isinstance(want, dict):
        return isinstance(got, dict) and set(got) == set(want) and all(
            _close(got[k], want[k], tol) for k in want)
    if isinstance(want, (list, tuple)):
        return isinstance(got, (list, tuple)) and len(got) == len(want) and all(
            _close(a, b, tol) for a, b in zip(got, want))
    if isinstance(want, float) or isinstance(got, float):
        return isinstance(got, (int, float)) and got == pytest.approx(want, abs=tol)
    return got == want


def test_register_unregister_leaves_nothing_behind(addon):
    artgs.unregister()
    try:
        assert not any(c.is_registered for c in _BONE_CLASSES)
        assert not any(hasattr(bpy.types, c.__name__) for c in _BONE_CLASSES)
        assert "artgs_joint" not in bpy.types.Bone.bl_rna.properties
        assert "artgs_joint" not in bpy.types.EditBone.bl_rna.properties
        assert "add_joint" not in dir(bpy.ops.artgs)
    finally:
        artgs.register()
    assert all(c.is_registered for c in _BONE_CLASSES)
    assert "artgs_joint" in bpy.types.Bone.bl_rna.properties
    assert "artgs_joint" in bpy.types.EditBone.bl_rna.properties
    assert "add_joint" in dir(bpy.ops.artgs)


def test_armature_built_from_proposals_file_matches_it(ctx, tmp_path):
    path = tmp_path / "proposals.json"
    write_articulation(path, _articulation())
    art = read_articulation(path)
    obj = armature.build_armature(ctx, art, size=0.8)
    bones = obj.data.bones
    assert obj.type == "ARMATURE" and [b.name for b in bones] == ["door", "drawer"]
    for joint in art.joints:
        bone = bones[joint.name]
        props = bone.artgs_joint
        assert props.joint_type == joint.type
        np.testing.assert_allclose((props.lower, props.upper), joint.limit, atol=1e-6)
        assert (props.parent_link, props.child_link, props.source) == \
            (joint.parent, joint.child, joint.source)
        np.testing.assert_allclose(bone.head_local, joint.origin, atol=1e-6)
        np.testing.assert_allclose(np.array(bone.tail_local - bone.head_local),
                                   joint.axis * armature.BONE_LENGTH * 0.8, atol=1e-6)
        assert bone.use_deform and bone.parent is None
    assert bones["door"].color.palette != bones["drawer"].color.palette
    assert bones["door"].artgs_joint.confidence == pytest.approx(0.8)
    door, drawer = obj.pose.bones["door"], obj.pose.bones["drawer"]
    assert tuple(door.lock_rotation) == (True, False, True) and all(door.lock_location)
    assert tuple(drawer.lock_location) == (True, False, True) and all(drawer.lock_rotation)
    rot, loc = door.constraints
    assert (rot.type, loc.type) == ("LIMIT_ROTATION", "LIMIT_LOCATION")
    assert (rot.min_y, rot.max_y, loc.min_y, loc.max_y) == pytest.approx((-0.2, 1.4, 0, 0))
    rot, loc = drawer.constraints
    assert (rot.min_y, rot.max_y, loc.min_y, loc.max_y) == pytest.approx((0, 0, 0, 0.35))
    assert json.loads(obj.data[armature.META_KEY]) == art.meta


def test_rebuild_replaces_bones_groups_and_modifier_cleanly(ctx):
    art = _articulation()
    pts, labels = _points(art)
    preview = _preview(ctx, pts)
    first = armature.build_armature(ctx, art, preview=preview)
    second = armature.build_armature(ctx, Articulation([art.joints[1]]), preview=preview)
    assert second == first and len([o for o in bpy.data.objects if o.type == "ARMATURE"]) == 1
    assert [b.name for b in second.data.bones] == ["drawer"]
    assert [g.name for g in preview.vertex_groups] == ["drawer"]
    assert [m.type for m in preview.modifiers] == ["ARMATURE"]
    first.name = "cabinet joints"  # renamed by the user: still the one rebuilt
    bpy.data.objects.new("ArtGS Joints", None)  # and the name taken by something else
    third = armature.build_armature(ctx, art, preview=preview)
    assert third == first and [b.name for b in third.data.bones] == ["door", "drawer"]
    assert [g.name for g in preview.vertex_groups] == ["door", "drawer"]
    armature.build_armature(ctx, Articulation([art.joints[1]]), preview=preview)
    members = [v.index for v in preview.data.vertices if v.groups]
    np.testing.assert_array_equal(members, np.flatnonzero(labels == 2))
    assert len(second.pose.bones["drawer"].constraints) == 2


def test_posing_bones_moves_their_parts_like_the_joints(ctx):
    art = _articulation()
    pts, labels = _points(art)
    # armature and preview both under non-trivial transforms; joints and points stay in the world
    obj = _transformed_armature(ctx, _transform())
    preview = _preview(ctx, pts, Matrix.Translation((0.1, 0.2, -0.3)))
    armature.build_armature(ctx, art, preview=preview)
    np.testing.assert_allclose(_evaluated_world(ctx, preview), pts, atol=1e-5)
    door, drawer = art.joints

    armature.set_joint_value(obj, "door", 30 * DEG)
    moved = _evaluated_world(ctx, preview)
    np.testing.assert_allclose(moved[labels == 1], _apply(door.transform(30 * DEG), pts[labels == 1]),
                               atol=1e-5)
    np.testing.assert_allclose(moved[labels != 1], pts[labels != 1], atol=1e-5)

    armature.set_joint_value(obj, "door", 0.0)
    armature.set_joint_value(obj, "drawer", 0.2)
    moved = _evaluated_world(ctx, preview)
    np.testing.assert_allclose(moved[labels == 2], _apply(drawer.transform(0.2), pts[labels == 2]),
                               atol=1e-5)
    np.testing.assert_allclose(moved[labels != 2], pts[labels != 2], atol=1e-5)


def test_nested_joint_moves_with_its_parent(ctx):
    art = _articulation()
    drawer = art.joints[1]
    flap = Joint("flap", "revolute", [1, 0, 0], [-0.3, -0.31, 0.12], (0.0, 1.0),
                 parent=drawer.child, extent=_box([-0.3, -0.305, 0.2], [0.15, 0.004, 0.06]))
    art.joints.append(flap)
    pts, labels = _points(Articulation([drawer, flap]), n=40)  # labels: 1 drawer, 2 flap
    preview = _preview(ctx, pts)
    obj = armature.build_armature(ctx, art, preview=preview)
    assert obj.data.bones["flap"].parent.name == "drawer"
    armature.set_joint_value(obj, "drawer", 0.2)
    armature.set_joint_value(obj, "flap", 0.5)
    moved = _evaluated_world(ctx, preview)
    np.testing.assert_allclose(moved[labels == 2],
                               _apply(drawer.transform(0.2) @ flap.transform(0.5), pts[labels == 2]),
                               atol=1e-5)
    np.testing.assert_allclose(moved[labels == 1], _apply(drawer.transform(0.2), pts[labels == 1]),
                               atol=1e-5)
    _assert_joints_equal(armature.read_joints(obj), art.joints)  # rest pose: as built


def test_constraints_keep_bones_within_limits_and_on_their_axis(ctx):
    art = _articulation()
    pts, labels = _points(art)
    preview = _preview(ctx, pts)
    obj = armature.build_armature(ctx, art, preview=preview)
    door, drawer = art.joints
    pb_door, pb_drawer = obj.pose.bones["door"], obj.pose.bones["drawer"]

    pb_door.rotation_euler = (0.0, 120 * DEG, 0.0)  # above the upper limit 1.4 rad
    np.testing.assert_allclose(_evaluated_world(ctx, preview)[labels == 1],
                               _apply(door.transform(1.4), pts[labels == 1]), atol=1e-5)
    pb_door.rotation_euler = (0.0, -1.0, 0.0)  # below the lower limit -0.2 rad
    np.testing.assert_allclose(_evaluated_world(ctx, preview)[labels == 1],
                               _apply(door.transform(-0.2), pts[labels == 1]), atol=1e-5)
    pb_door.rotation_euler = (0.5, 30 * DEG, -0.4)  # other axes are held at zero
    pb_door.location = (0.1, 0.2, 0.3)
    np.testing.assert_allclose(_evaluated_world(ctx, preview)[labels == 1],
                               _apply(door.transform(30 * DEG), pts[labels == 1]), atol=1e-5)

    pb_drawer.location = (0.3, 0.9, -0.2)  # beyond 0.35 m, and off the slide direction
    pb_drawer.rotation_euler = (0.3, 0.2, 0.1)
    np.testing.assert_allclose(_evaluated_world(ctx, preview)[labels == 2],
                               _apply(drawer.transform(0.35), pts[labels == 2]), atol=1e-5)


def test_write_then_read_is_the_identity_under_an_object_transform(ctx):
    art = _articulation()
    obj = _transformed_armature(ctx, _transform())
    armature.build_armature(ctx, art, size=0.9)
    assert np.allclose(np.array(obj.matrix_world), np.array(_transform()))
    _assert_joints_equal(armature.read_joints(obj), art.joints)
    # the bones themselves (not only the stored copy) carry the joints
    for joint in art.joints:
        drawn = armature.joint_of_bone(obj, joint.name)
        np.testing.assert_allclose(drawn.axis, joint.axis, atol=1e-6)
        np.testing.assert_allclose(drawn.origin, joint.origin, atol=1e-6)
        assert drawn.limit == pytest.approx(joint.limit, abs=1e-6)


def test_non_uniform_scale_reads_world_directions_and_points(ctx):
    art = _articulation()
    obj = armature.build_armature(ctx, art)
    S = Matrix.Translation((1, 2, 3)) @ Matrix.Diagonal((1.0, 2.0, 3.0, 1.0))
    obj.matrix_world = S
    ctx.view_layer.update()
    M = np.array(S)
    joints = {j.name: j for j in armature.read_joints(obj)}
    for joint in art.joints:
        want_axis = M[:3, :3] @ joint.axis
        np.testing.assert_allclose(joints[joint.name].axis, want_axis / np.linalg.norm(want_axis),
                                   atol=1e-6)
        np.testing.assert_allclose(joints[joint.name].origin, _apply(M, joint.origin), atol=1e-6)
        assert joints[joint.name].source == "user"  # the user moved the joints


def test_negative_scale_is_refused_with_the_fix(ctx):
    obj = armature.build_armature(ctx, _articulation())
    obj.scale = (1.0, -1.0, 1.0)
    ctx.view_layer.update()
    with pytest.raises(ArtgsError, match=r"negative.*Object > Apply > Scale \(Ctrl\+A\)"):
        armature.read_joints(obj)
    with pytest.raises(ArtgsError, match=r"Object > Apply > Scale"):
        armature.build_armature(ctx, _articulation())


def test_edit_mode_changes_are_read_as_user_joints(ctx):
    art = _articulation()
    M = _transform()
    obj = _transformed_armature(ctx, M)
    armature.build_armature(ctx, art)
    ctx.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    eb = obj.data.edit_bones["door"]
    shift = Vector((0.1, 0.0, -0.05))
    eb.head += shift
    eb.tail += shift + Vector((0.1, 0.0, 0.0))
    head, tail = M @ eb.head, M @ eb.tail
    joints = {j.name: j for j in armature.read_joints(obj)}  # still in edit mode
    assert obj.mode == "EDIT"
    door = joints["door"]
    assert door.source == "user" and door.type == "revolute"
    np.testing.assert_allclose(door.origin, head, atol=1e-5)
    np.testing.assert_allclose(door.axis, np.array((tail - head).normalized()), atol=1e-6)
    assert _close(door.extent, art.joints[0].extent) and _close(door.handle, art.joints[0].handle)
    assert door.confidence == pytest.approx(0.8) and door.limit == pytest.approx((-0.2, 1.4), abs=1e-6)
    _assert_joints_equal([joints["drawer"]], [art.joints[1]])  # untouched: as built
    bpy.ops.object.mode_set(mode="OBJECT")
    # a limit edited in the panel also makes the joint the user's, and the constraint follows
    obj.data.bones["drawer"].artgs_joint.upper_distance = 0.5
    joints = {j.name: j for j in armature.read_joints(obj)}
    assert joints["drawer"].source == "user" and joints["drawer"].limit[1] == pytest.approx(0.5)
    con = obj.pose.bones["drawer"].constraints["ArtGS Limit Location"]
    assert con.max_y * 1.7 == pytest.approx(0.5, abs=1e-6)  # local units of the scaled armature
    # switching the type swaps locks, constraint and colour at once
    obj.data.bones["drawer"].artgs_joint.joint_type = "revolute"
    pb = obj.pose.bones["drawer"]
    assert pb.constraints["ArtGS Limit Rotation"].max_y == pytest.approx(0.5)
    assert pb.constraints["ArtGS Limit Location"].max_y == 0 and all(pb.lock_location)
    assert obj.data.bones["drawer"].color.palette == obj.data.bones["door"].color.palette


def test_bone_settings_survive_edit_mode_and_can_be_edited_there(ctx):
    obj = armature.build_armature(ctx, _articulation())
    ctx.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    props = obj.data.edit_bones["door"].artgs_joint
    assert props.joint_type == "revolute" and props.source == "vlm"
    props.upper_angle = 80 * DEG
    assert obj.pose.bones["door"].constraints[0].max_y == pytest.approx(80 * DEG)  # at once
    bpy.ops.object.mode_set(mode="OBJECT")
    props = obj.data.bones["door"].artgs_joint
    assert props.upper == pytest.approx(80 * DEG) and props.child_link == "door_link"
    assert json.loads(props.built)["extent"] == _articulation().joints[0].extent


def test_add_remove_and_save_operators(ctx, tmp_path):
    ctx.scene.artgs.output_dir = str(tmp_path)
    assert not bpy.ops.artgs.save_joints.poll()  # nothing to save yet
    ctx.scene.cursor.location = (0.2, 0.3, 0.4)
    assert bpy.ops.artgs.add_joint() == {"FINISHED"}
    obj = armature.find_armature(ctx)
    assert obj is not None and [b.name for b in obj.data.bones] == ["joint"]
    bone = obj.data.bones["joint"]
    np.testing.assert_allclose(bone.head_local, (0.2, 0.3, 0.4), atol=1e-6)
    np.testing.assert_allclose(np.array((bone.tail_local - bone.head_local).normalized()),
                               (0, 0, 1), atol=1e-6)
    assert bone.artgs_joint.joint_type == "revolute" and bone.artgs_joint.source == "user"
    assert obj.pose.bones["joint"].constraints[0].max_y == pytest.approx(math.pi / 2)
    ctx.scene.cursor.location = (-0.2, 0.0, 0.1)
    assert bpy.ops.artgs.add_joint(joint_type="prismatic") == {"FINISHED"}
    assert len(obj.data.bones) == 2 and obj.data.bones.active.name != "joint"
    slide = obj.data.bones.active.name
    assert obj.mode == "OBJECT"

    # saving keeps the file's other fields and reads back as user joints
    write_articulation(tmp_path / "proposals.json", Articulation([], {"view": 5, "method": "vlm"}))
    assert bpy.ops.artgs.save_joints() == {"FINISHED"}
    saved = read_articulation(tmp_path / "proposals.json")
    assert saved.meta == {"view": 5, "method": "vlm"}
    assert [(j.name, j.type, j.source) for j in saved.joints] == \
        [("joint", "revolute", "user"), (slide, "prismatic", "user")]
    np.testing.assert_allclose(saved.joints[1].origin, (-0.2, 0.0, 0.1), atol=1e-6)
    _assert_joints_equal(armature.read_joints(obj), saved.joints)  # saved = the new reference

    bpy.ops.artgs.select_joint(name="joint")
    assert bpy.ops.artgs.remove_joint() == {"FINISHED"}
    assert [b.name for b in obj.data.bones] == [slide]
    assert not bpy.ops.artgs.remove_joint.poll()  # no active joint left


def test_remove_joint_returns_its_points_to_the_base(ctx):
    art = _articulation()
    pts, labels = _points(art)
    preview = _preview(ctx, pts)
    obj = armature.build_armature(ctx, art, preview=preview)
    ctx.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="POSE")
    obj.data.bones.active = obj.data.bones["door"]
    assert bpy.ops.artgs.remove_joint() == {"FINISHED"}
    assert obj.mode == "POSE" and "door" not in preview.vertex_groups
    armature.set_joint_value(obj, "drawer", 0.1)
    moved = _evaluated_world(ctx, preview)
    np.testing.assert_allclose(moved[labels != 2], pts[labels != 2], atol=1e-5)


def test_bone_added_by_hand_is_saved_as_a_user_joint_with_locks(ctx, tmp_path):
    ctx.scene.artgs.output_dir = str(tmp_path)
    obj = armature.build_armature(ctx, _articulation())
    ctx.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    eb = obj.data.edit_bones.new("lid")  # as Shift+A does: no joint settings yet
    eb.head, eb.tail = (0.0, 0.0, 1.0), (0.3, 0.0, 1.0)
    bpy.ops.object.mode_set(mode="POSE")
    assert len(obj.pose.bones["lid"].constraints) == 0
    assert bpy.ops.artgs.save_joints() == {"FINISHED"}
    saved = {j.name: j for j in read_articulation(tmp_path / "proposals.json").joints}
    lid = saved["lid"]
    assert (lid.type, lid.source, lid.child) == ("revolute", "user", "lid_link")
    np.testing.assert_allclose(lid.axis, (1, 0, 0), atol=1e-6)
    np.testing.assert_allclose(lid.origin, (0, 0, 1), atol=1e-6)
    _assert_joints_equal([saved["door"]], [_articulation().joints[0]])
    pb = obj.pose.bones["lid"]
    assert len(pb.constraints) == 2 and tuple(pb.lock_rotation) == (True, False, True)


@pytest.mark.parametrize("mode", ["OBJECT", "POSE", "EDIT"])
def test_select_joint_in_every_mode(ctx, mode):
    """Picking a joint in the Bones panel selects that bone alone and makes it active, in Object,
    Pose and Edit mode, on Blender 4.x (``Bone.select``) and 5.x (``PoseBone.select``)."""
    obj = armature.build_armature(ctx, _articulation())
    ctx.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode=mode)
    for name, other in (("door", "drawer"), ("drawer", "door")):
        assert bpy.ops.artgs.select_joint(name=name) == {"FINISHED"}
        assert bone_pose.is_selected(obj, name) and not bone_pose.is_selected(obj, other)
        bones = obj.data.edit_bones if mode == "EDIT" else obj.data.bones
        assert bones.active.name == name and obj.mode == mode
    with pytest.raises(RuntimeError, match="No joint named 'lid'"):
        bpy.ops.artgs.select_joint(name="lid")
    bpy.ops.object.mode_set(mode="OBJECT")
    assert obj.data.bones.active.name == "drawer"  # the choice survives leaving the mode


#: Builds the test armature with bpy 4.5 (the engine's interpreter) and saves it.
_MAKE_45_BLEND = """
import sys, bpy, artgs
sys.path.insert(0, {tests!r})
from test_armature import _articulation
from artgs.artgs_addon import armature
artgs.register()
bpy.ops.wm.read_factory_settings(use_empty=True)
obj = armature.build_armature(bpy.context, _articulation())
bpy.context.view_layer.objects.active = obj
bpy.ops.object.mode_set(mode="POSE")
obj.data.bones.active = obj.data.bones["door"]
obj.data.bones["door"].select = True
bpy.ops.wm.save_as_mainfile(filepath={blend!r})
print("VERSION", bpy.app.version_string)
artgs.unregister()
"""


def test_scene_made_in_4_5_selects_in_this_blender(ctx, tmp_path):
    """A scene.blend saved by bpy 4.5 opens here (5.x in the second half of `make test`) and its
    joints can be picked in Pose mode and Object mode."""
    engine = engine_python()
    blend = tmp_path / "made_in_45.blend"
    proc = subprocess.run([engine, "-c", _MAKE_45_BLEND.format(tests=str(TESTS),
                                                                blend=str(blend))],
                          capture_output=True, text=True, timeout=300)
    if "No module named 'bpy'" in proc.stderr:
        pytest.skip(f"the engine's interpreter {engine} has no bpy 4.5 to make the scene")
    assert proc.returncode == 0 and "VERSION 4.5" in proc.stdout, proc.stderr[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    obj = bpy.data.objects["ArtGS Joints"]
    assert obj.mode == "POSE" and obj.data.bones.active.name == "door"
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.artgs.select_joint(name="drawer") == {"FINISHED"}
    assert bone_pose.is_selected(obj, "drawer") and not bone_pose.is_selected(obj, "door")
    bpy.ops.object.mode_set(mode="OBJECT")
    assert bpy.ops.artgs.select_joint(name="door") == {"FINISHED"}
    assert obj.data.bones.active.name == "door" and bone_pose.is_selected(obj, "door")
    # the joints read back from the 4.5 scene as they were built
    _assert_joints_equal(armature.read_joints(obj), _articulation().joints)
