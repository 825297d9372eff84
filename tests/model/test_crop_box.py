"""The crop box: OUT/crop.json read and validated by the engine; in Blender an Empty shown as a cube,
whose world box reaches the engine through Export URDF and keeps a piece of furniture beside the
object out of the exported meshes."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from artgs.core.model import layout
from artgs.core.model.crop import CropBox, crop_from_matrix, read_crop, write_crop
from artgs.core.model.errors import InputError
from artgs.core.model.joints import rotation_about_axis


def test_crop_json_round_trip_and_bad_input(tmp_path):
    R = rotation_about_axis(np.array([0.0, 0.0, 1.0]), 0.4)
    M = np.eye(4)
    M[:3, :3] = R @ np.diag([0.3, 0.2, 0.5])
    M[:3, 3] = [0.1, -0.2, 0.5]
    box = crop_from_matrix(M)
    np.testing.assert_allclose(box.half_size, [0.3, 0.2, 0.5], atol=1e-12)
    np.testing.assert_allclose(box.axes, R.T, atol=1e-12)
    write_crop(tmp_path, box)
    back = read_crop(tmp_path)
    np.testing.assert_allclose(back.center, box.center)
    inside = box.center + 0.29 * box.axes[0]          # just inside along the rotated x edge
    outside = box.center + 0.31 * box.axes[0]
    assert box.contains(np.array([inside, outside])).tolist() == [True, False]
    assert read_crop(tmp_path / "none") is None
    data = json.loads((tmp_path / layout.CROP).read_text())
    data["half_size"] = [0.3, -0.2, 0.5]
    (tmp_path / layout.CROP).write_text(json.dumps(data))
    with pytest.raises(InputError, match="half_size"):
        read_crop(tmp_path)


def _with_chair(out, spec) -> int:
    """Append a 'chair' (a box of Gaussians) beside the object to OUT/splat.ply; its size."""
    from artgs.core.model.ply import read_ply, write_ply
    from splat_objects import box_surface

    splat = read_ply(out / layout.SPLAT)
    lo, hi = splat.means.min(0), splat.means.max(0)
    T = np.eye(4)
    T[:3, 3] = [hi[0] + 0.4, (lo[1] + hi[1]) / 2, lo[2] + 0.2]
    chair = box_surface(T, np.array([0.2, 0.2, 0.2]), 0.012, np.random.default_rng(1))
    n = len(chair)

    def grow(a, rows):
        return np.concatenate([a, np.repeat(a[:1], n, axis=0) if rows is None else rows])

    write_ply(out / layout.SPLAT, replace(splat, means=grow(splat.means, chair.astype(np.float32)),
                                          quats=grow(splat.quats, None),
                                          log_scales=grow(splat.log_scales, None),
                                          opacity_logits=grow(splat.opacity_logits, None),
                                          sh=grow(splat.sh, None)))
    return n


def test_blender_crop_box_reaches_the_engine_and_crops_the_export(ctx, tmp_path):
    bpy = pytest.importorskip("bpy")
    pytest.importorskip("trimesh", reason="reads the exported meshes")
    import trimesh

    from artgs.artgs_addon.crop_box import CROP_BOX, sync_crop
    from engine_env import generate_capture
    from splat_objects import make_out

    out = tmp_path / "out"
    spec, art = make_out(out, "cabinet", 0)
    from artgs.core.model.ply import read_ply
    object_pts = read_ply(out / layout.SPLAT).means
    chair = _with_chair(out, spec)

    scene = bpy.context.scene
    scene.artgs.output_dir = str(out)
    # the engine's export reads the capture (for its masks: this one has them, so the crop
    # box alone separates the object)
    scene.artgs.capture_dir = str(generate_capture(tmp_path / "cap", "cabinet", 0, width=64,
                                                   height=48))
    assert bpy.ops.artgs.add_crop_box() == {"FINISHED"}
    obj = scene.objects[CROP_BOX]
    assert obj.type == "EMPTY" and obj.empty_display_type == "CUBE"
    # around the object (its Gaussians + 3 cm), turned 3 degrees about z
    lo, hi = object_pts.min(0) - 0.03, object_pts.max(0) + 0.03
    obj.location = tuple((lo + hi) / 2)
    obj.rotation_euler = (0.0, 0.0, np.deg2rad(3.0))
    obj.scale = tuple((hi - lo) / 2 + 0.05)
    bpy.context.view_layer.update()
    assert bpy.ops.artgs.export_urdf("EXEC_DEFAULT") == {"FINISHED"}
    assert scene.artgs.export.status == "DONE", scene.artgs.export.text
    box = read_crop(out)
    np.testing.assert_allclose(box.center, (lo + hi) / 2, atol=1e-6)
    np.testing.assert_allclose(box.half_size, (hi - lo) / 2 + 0.05, atol=1e-6)
    np.testing.assert_allclose(box.axes[0], [np.cos(np.deg2rad(3)), np.sin(np.deg2rad(3)), 0],
                               atol=1e-6)
    report = layout.read_report(out)["stages"]["export"]["separation"]
    assert report["crop"]["outside"] == chair
    mask = np.load(out / layout.OBJECT_MASK)
    assert mask.sum() == len(object_pts) and not mask[len(object_pts):].any()
    # the base mesh stays inside the box (a voxel or two of closing surface aside)
    base = trimesh.load(out / "parts" / "base.obj", force="mesh")
    grown = CropBox(box.center, box.axes, box.half_size + 0.03)
    assert grown.contains(np.asarray(base.vertices)).all()
    # deleting the box removes the crop the add-on wrote
    bpy.data.objects.remove(obj)
    assert sync_crop(scene, out) is None and not (out / layout.CROP).exists()
    # a box already in OUT (reconstruct's separation of a capture without masks) becomes the Empty
    from artgs.artgs_addon.crop_box import crop_of
    c, s = np.cos(0.4), np.sin(0.4)
    sep = CropBox(np.array([0.1, -0.2, 0.5]), np.array([[c, s, 0], [-s, c, 0], [0, 0, 1.0]]),
                  np.array([0.3, 0.2, 0.5]), "separation")
    write_crop(out, sep)
    assert bpy.ops.artgs.add_crop_box() == {"FINISHED"}
    bpy.context.view_layer.update()
    adopted = crop_of(scene.objects[CROP_BOX])
    np.testing.assert_allclose(adopted.center, sep.center, atol=1e-5)
    np.testing.assert_allclose(adopted.axes, sep.axes, atol=1e-5)
    np.testing.assert_allclose(adopted.half_size, sep.half_size, atol=1e-5)
