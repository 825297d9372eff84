"""Import URDF into Blender (bpy, background) and write the edited joints back: ours with nested
joints and OBJ meshes, the synthetic ground truth (world root, fixed joint, box visuals); a round
trip export -> import -> export keeps the joints to 1e-6."""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
# Engine modules run in this process here: in the bpy 5.x half of `make test` (numpy-only venv)
# this file is skipped, with this reason in the summary.
trimesh = pytest.importorskip("trimesh", reason="needs the engine's packages in Blender's process "
                              "(not in the bpy 5.x venv)")
from mathutils import Matrix  # noqa: E402

import artgs  # noqa: E402
from artgs.artgs_addon import armature, bone_props, urdf_import  # noqa: E402
from artgs.core.model.joints import Joint, rotation_about_axis  # noqa: E402
from artgs.core.model.registry import ExportOptions  # noqa: E402
from artgs.core.model.urdf_io import read_urdf  # noqa: E402
from artgs.core.sim.urdf import Geometry, Link, Mesh, write_urdf  # noqa: E402
from artgs.core.sim.validate import fk_check  # noqa: E402
from artgs.core.stages.export.collision import write_obj  # noqa: E402
from artgs.core.stages.export.stage import link_frames, urdf_joint  # noqa: E402
from artgs.core.synth.layouts import random_spec  # noqa: E402


def _joints() -> list[Joint]:
    door = Joint("door", "revolute", [0.1, 0.2, 1.0], [0.5, -0.3, 0.4], (-0.3, 1.4))
    flap = Joint("flap", "revolute", [1.0, -0.3, 0.2], [0.6, 0.1, 0.9], (0.0, 0.8),
                 parent=door.child)
    drawer = Joint("drawer", "prismatic", [0.9, 0.3, -0.1], [0.2, 0.2, 0.3], (0.0, 0.3))
    return [door, flap, drawer]


def _export(tmp_path, joints):
    """model.urdf + parts/<link>.obj (a box per link, centred away from the link frame)."""
    frames = link_frames(joints)
    links = []
    for k, (name, frame) in enumerate(frames.items()):
        box = trimesh.creation.box([0.1, 0.2, 0.3])
        box.apply_translation([0.05 * k, 0.1, 0.0])
        write_obj(tmp_path / "parts" / f"{name}.obj", [box], colours=False)
        links.append(Link(name, visuals=[Geometry(Mesh(f"parts/{name}.obj"))]))
    path = tmp_path / "model.urdf"
    path.write_text(write_urdf("m", links, [urdf_joint(j, frames, ExportOptions()) for j in joints]))
    return path


def _mesh_world_vertices(obj) -> np.ndarray:
    M = np.array(obj.matrix_world)
    v = np.array([tuple(p.co) for p in obj.data.vertices])
    return v @ M[:3, :3].T + M[:3, 3]


def test_round_trip_export_import_export_keeps_joints(ctx, tmp_path):
    joints = _joints()
    path = _export(tmp_path, joints)
    arm, made, skipped = urdf_import.import_urdf(ctx, path)
    assert (made, skipped) == (4, 0)
    back = {j.name: j for j in armature.read_joints(arm)}
    for j in joints:
        b = back[j.name]
        assert b.type == j.type and b.parent == j.parent
        np.testing.assert_allclose(b.axis, j.axis, atol=1e-6)
        np.testing.assert_allclose(b.origin, j.origin, atol=1e-6)
        np.testing.assert_allclose(b.limit, j.limit, atol=1e-6)
    # meshes sit where the URDF puts them: base box centred at (0, 0.1, 0) in the world
    base = next(o for o in ctx.scene.objects if o.get("artgs_link") == "base")
    np.testing.assert_allclose(_mesh_world_vertices(base).mean(0), [0, 0.1, 0], atol=1e-5)
    again = urdf_import.write_edited_urdf(arm, tmp_path / "again" / "model.urdf")
    assert fk_check(again, joints)["max_error"] < 1e-6
    # posing the door bone moves its mesh (and the flap's) with it
    door_mesh = next(o for o in ctx.scene.objects if o.get("artgs_link") == "door_link")
    before = _mesh_world_vertices(door_mesh)
    armature.set_joint_value(arm, "door", 0.7)
    ctx.view_layer.update()
    after = _mesh_world_vertices(door_mesh)
    want = (before - joints[0].origin) @ rotation_about_axis(joints[0].axis, 0.7).T + joints[0].origin
    np.testing.assert_allclose(after, want, atol=1e-5)


def test_edited_joint_is_written_and_meshes_stay(ctx, tmp_path):
    joints = _joints()
    path = _export(tmp_path, joints)
    arm, _, _ = urdf_import.import_urdf(ctx, path)
    edited = Joint("door", "revolute", [0.0, 0.0, 1.0], [0.45, -0.35, 0.4], (0.0, 1.2))
    arm.data.bones["door"].artgs_joint  # the bone exists
    with armature.edit_mode(ctx, arm) as bones:
        eb = bones["door"]
        length = (eb.tail - eb.head).length
        eb.head = tuple(edited.origin)
        eb.tail = tuple(edited.origin + length * edited.axis)
    arm.data.bones["door"].artgs_joint.limit_upper = 1.2
    out = urdf_import.write_edited_urdf(arm, tmp_path / "edited.urdf")
    model = read_urdf(out)
    got = {j.name: j for j in model.joints}
    np.testing.assert_allclose(got["door"].origin, edited.origin, atol=1e-6)
    np.testing.assert_allclose(got["door"].axis, edited.axis, atol=1e-6)
    np.testing.assert_allclose(got["flap"].origin, joints[1].origin, atol=1e-6)
    # nothing moved at zero: each visual's world pose is unchanged
    old = read_urdf(path)
    for link in old.visuals:
        np.testing.assert_allclose(model.link_poses[link] @ model.visuals[link][0].origin,
                                   old.link_poses[link] @ old.visuals[link][0].origin, atol=1e-9)


def test_synthetic_ground_truth_urdf_imports_with_boxes(ctx, tmp_path):
    spec = random_spec("cabinet", 1)
    path = tmp_path / "gt.urdf"
    path.write_text(spec.to_urdf())
    arm, made, skipped = urdf_import.import_urdf(ctx, path)
    boxes = len(spec.body) + sum(len(q.boxes) for q in spec.parts)
    assert (made, skipped) == (boxes, 0)
    back = {j.name: j for j in armature.read_joints(arm)}
    for j in spec.joints():
        assert back[j.name].parent == "base"
        np.testing.assert_allclose(back[j.name].origin, j.origin, atol=1e-6)
        assert abs(abs(back[j.name].axis @ j.axis) - 1) < 1e-9


def test_check_operator_runs_in_the_engine_and_loads_the_strip(ctx, tmp_path):
    import shutil

    from splat_objects import make_out
    from artgs.operators.export import STRIP_IMAGE

    out = tmp_path / "out"
    make_out(out, "cabinet", 0)
    shutil.copy(out / "gt.urdf", out / "model.urdf")       # the ground truth as "our" model
    ctx.scene.artgs.output_dir = str(out)
    assert bpy.ops.artgs.export_urdf.poll() and bpy.ops.artgs.check_manipulation.poll()
    assert bpy.ops.artgs.check_manipulation("EXEC_DEFAULT") == {"FINISHED"}
    state = ctx.scene.artgs.check
    assert state.status == "DONE" and "opened 2/2" in state.text, state.text
    image = bpy.data.images[STRIP_IMAGE]
    assert tuple(image.size) == (6 * 160, 2 * 120)
    # Import URDF through its operator
    assert bpy.ops.artgs.import_urdf(filepath=str(out / "gt.urdf")) == {"FINISHED"}
