"""The add-on in bpy (background): registration, preferences, polls, Import Capture through the
engine (cameras reproduce K, point count), Import Splat (count, colours), engine failures leave the
scene as it was, two objects in one scene (one armature each).

The whole pipeline through the operators runs in tests/blender/test_addon_pipeline.py (a subprocess).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
import addon_utils  # noqa: E402

from artgs.artgs_addon import preferences  # noqa: E402
from artgs.artgs_addon.armature import find_armature  # noqa: E402
from artgs.artgs_addon.capture_scene import camera_object, pixel_aspect  # noqa: E402
from artgs.artgs_addon.pointcloud import srgb_to_linear  # noqa: E402
from artgs.artgs_addon.splat_preview import SH_C0  # noqa: E402
from artgs.core.model.cameras import Camera, intrinsics, look_at  # noqa: E402
from artgs.core.model.joints import read_articulation  # noqa: E402
from artgs.core.model.ply import SplatArrays, write_ply  # noqa: E402
from engine_env import engine_json, engine_python  # noqa: E402
from engine_env import generate_capture as generate_object  # noqa: E402
from artgs.operators.propose import ARTGS_OT_propose_bones  # noqa: E402

ADDON = "artgs"


def _leftovers() -> list[str]:
    names = [n for n in dir(bpy.types) if n.upper().startswith("ARTGS")]
    for owner, prop in ((bpy.types.Scene, "artgs"), (bpy.types.Bone, "artgs_joint"),
                        (bpy.types.EditBone, "artgs_joint")):
        if hasattr(owner, prop):
            names.append(f"{owner.__name__}.{prop}")
    names += [f"bpy.ops.artgs.{op}" for op in dir(bpy.ops.artgs)]
    return names


def _handlers() -> dict[str, int]:
    return {name: len(getattr(bpy.app.handlers, name)) for name in dir(bpy.app.handlers)
            if isinstance(getattr(bpy.app.handlers, name), list)}


def _enable() -> None:
    assert addon_utils.enable(ADDON, default_set=True, handle_error=None) is not None


def _disable() -> None:
    addon_utils.disable(ADDON, default_set=True, handle_error=None)


def test_register_unregister_twice_leaves_nothing():
    handlers = _handlers()
    for _ in range(2):
        _enable()
        assert hasattr(bpy.types.Scene, "artgs") and hasattr(bpy.types.Bone, "artgs_joint")
        assert "bpy.ops.artgs.import_capture" in _leftovers()
        for name in ("ARTGS_PT_pipeline", "ARTGS_PT_capture", "ARTGS_PT_splat", "ARTGS_PT_bones",
                     "ARTGS_PT_optimise", "ARTGS_PT_export", "ARTGS_OT_import_capture",
                     "ARTGS_OT_reconstruct", "ARTGS_OT_import_splat", "ARTGS_OT_propose_bones",
                     "ARTGS_OT_check_engine"):
            assert hasattr(bpy.types, name), name
        assert bpy.types.ARTGS_PT_capture.bl_parent_id == "ARTGS_PT_pipeline"
        assert bpy.types.ARTGS_PT_pipeline.bl_category == "ArtGS"
        _disable()
        assert _leftovers() == []
        assert _handlers() == handlers


@pytest.fixture(scope="module")
def addon():
    """The add-on enabled through addon_utils (so its preferences exist); always disabled after
    (bpy as a module hangs at exit while Python-defined property groups are registered)."""
    _enable()
    try:
        yield
    finally:
        _disable()


@pytest.fixture
def scene(addon):
    bpy.ops.wm.read_homefile(use_empty=True)
    prefs = preferences.get()
    prefs.engine_python, prefs.preview_cap, prefs.vlm_api_key = "", 200_000, ""
    yield bpy.context.scene
    prefs.engine_python = ""  # the choice is kept in engine.json: later tests get the default


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    return generate_object(tmp_path_factory.mktemp("cap") / "cabinet", "cabinet", 0, width=64,
                           height=48, static_views=4, steps=2)


def _blender_K(obj, width: int, height: int, aspect: tuple[float, float]) -> np.ndarray:
    """Intrinsics from Blender's own projection matrix of camera ``obj``."""
    P = np.array(obj.calc_matrix_camera(bpy.context.evaluated_depsgraph_get(), x=width, y=height,
                                        scale_x=aspect[0], scale_y=aspect[1]))
    return np.array([[width / 2 * P[0, 0], 0, width / 2 * (1 - P[0, 2])],
                     [0, height / 2 * P[1, 1], height / 2 * (1 + P[1, 2])], [0, 0, 1]])


def test_preferences_defaults_and_engine(scene):
    prefs = preferences.get()
    assert prefs.bl_rna.properties["vlm_api_key"].subtype == "PASSWORD"
    assert prefs.preview_cap == 200_000 and prefs.device == "auto"
    # The checkout's .venv (where this test runs) is the default engine.
    assert preferences.engine_python() == preferences.default_engine()
    assert preferences.default_engine().endswith(("python", "python.exe"))


def test_api_key_never_in_blend_or_argv(scene, tmp_path, capture):
    secret = "sk-test-5ecret-abc123"
    prefs = preferences.get()
    prefs.vlm_api_key, prefs.vlm_endpoint = secret, "http://127.0.0.1:9/v1"
    settings = scene.artgs
    settings.capture_dir, settings.output_dir = str(capture), str(tmp_path / "out")
    settings.proposal_method = "vlm"
    args = ARTGS_OT_propose_bones.worker_args(None, bpy.context)
    assert secret not in " ".join(args) and "http://127.0.0.1:9/v1" in args
    assert ARTGS_OT_propose_bones.worker_env(None, bpy.context) == {"ARTGS_VLM_API_KEY": secret}
    path = tmp_path / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)
    data = path.read_bytes()
    assert secret.encode() not in data and b"http://127.0.0.1:9/v1" not in data


def test_polls_need_their_inputs(scene, tmp_path, capture):
    ops = bpy.ops.artgs
    assert not ops.import_capture.poll() and not ops.reconstruct.poll()
    assert not ops.import_splat.poll() and not ops.propose_bones.poll()
    scene.artgs.capture_dir = str(tmp_path)  # a folder without transforms.json
    scene.artgs.output_dir = str(tmp_path / "out")
    assert not ops.import_capture.poll() and not ops.reconstruct.poll()
    scene.artgs.capture_dir = str(capture)
    assert ops.import_capture.poll() and ops.reconstruct.poll() and ops.propose_bones.poll()
    assert not ops.import_splat.poll()
    write_ply(tmp_path / "out" / "splat.ply", _splats(10))
    assert ops.import_splat.poll()


_CAPTURE_FACTS = """
import numpy as np
from artgs.core.model.capture import load_capture
cap = load_capture({capture!r})
result = {{
    "static": [{{"file_path": f.file_path, "c2w": f.camera.c2w.tolist(), "K": f.camera.K.tolist()}}
               for f in cap.static],
    "interaction_cameras": len({{tuple(np.round(f.camera.c2w, 6).ravel()) for f in cap.interaction}}),
    "points": sum(int(np.count_nonzero((f.depth > 0) & f.mask)) for f in cap.static),
}}
"""


def test_import_capture_cameras_and_points(scene, capture):
    scene.artgs.capture_dir = str(capture)
    assert bpy.ops.artgs.import_capture() == {"FINISHED"}
    cap = engine_json(_CAPTURE_FACTS.format(capture=str(capture)))  # images decode in the engine
    collection = bpy.data.collections[capture.name]
    cams = [o for o in collection.objects if o.type == "CAMERA"]
    assert len(cams) == len(cap["static"]) + cap["interaction_cameras"]
    render = scene.render
    assert (render.resolution_x, render.resolution_y) == (64, 48)
    aspect = (render.pixel_aspect_x, render.pixel_aspect_y)
    by_name = {o["artgs_frame"]: o for o in cams}
    for f in cap["static"]:
        obj = by_name[f["file_path"]]
        np.testing.assert_allclose(np.array(obj.matrix_world), f["c2w"], atol=1e-5)
        np.testing.assert_allclose(_blender_K(obj, 64, 48, aspect), f["K"], rtol=1e-6,
                                   atol=1e-6 * 64)
    points = [o for o in collection.objects if o.type == "MESH"]
    assert len(points) == 1
    expected = cap["points"]
    assert len(points[0].data.vertices) == expected
    assert scene.artgs.capture.status == "DONE"
    assert f"{len(cams)} cameras, {expected} of {expected} points" in scene.artgs.capture.message


@pytest.mark.parametrize("K,size", [
    (intrinsics(100.0, 90.0, 33.3, 41.7), (80, 60)),    # fl_y < fl_x, off-centre
    (intrinsics(80.0, 95.0, 20.2, 70.1), (64, 96)),     # portrait, fl_y > fl_x
    (intrinsics(500.0, 500.0, 320.0, 240.0), (640, 480)),
])
def test_camera_intrinsics_reproduce_K(scene, K, size):
    w, h = size
    obj = camera_object("cam", Camera(K, look_at([1, 2, 3], [0, 0, 0]), w, h), scene.collection)
    np.testing.assert_allclose(_blender_K(obj, w, h, pixel_aspect(K)), K, rtol=1e-6, atol=1e-6 * w)


def _mesh_coords(obj) -> np.ndarray:
    co = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def test_import_capture_cap_is_deterministic_subset(scene, capture):
    scene.artgs.capture_dir = str(capture)
    bpy.ops.artgs.import_capture()
    full = {tuple(r) for r in np.round(_mesh_coords(bpy.data.objects[f"{capture.name} points"]), 4)}
    preferences.get().preview_cap = 1000
    scene.artgs.preview_density = 0.5
    coords = []
    for _ in range(2):
        bpy.ops.artgs.import_capture()
        obj = [o for o in bpy.data.collections[-1].objects if o.type == "MESH"][0]
        coords.append(_mesh_coords(obj))
    assert len(coords[0]) == 500 and len(full) > 1000
    np.testing.assert_array_equal(coords[0], coords[1])
    assert all(tuple(r) in full for r in np.round(coords[0], 4))
    assert f"500 of {len(full)} points" in scene.artgs.capture.message


def _splats(n: int, seed: int = 0) -> SplatArrays:
    rng = np.random.default_rng(seed)
    sh = np.zeros((n, 4, 3), np.float32)
    sh[:, 0] = rng.normal(0, 1.0, (n, 3))  # some colours beyond 0..1: clipped
    return SplatArrays(rng.normal(size=(n, 3)).astype(np.float32),
                       rng.normal(size=(n, 4)).astype(np.float32),
                       np.log(rng.uniform(0.01, 0.05, (n, 3))).astype(np.float32),
                       rng.normal(size=n).astype(np.float32), sh)


def _attribute(mesh, name: str, width: int) -> np.ndarray:
    attr = mesh.attributes[name]
    values = np.empty(width * len(attr.data), np.float32)
    attr.data.foreach_get("color" if width == 4 else "value", values)
    return values.reshape(-1, width) if width > 1 else values


def test_import_splat_points_and_colours(scene, tmp_path):
    splats = _splats(2000)
    out = tmp_path / "out"
    write_ply(out / "splat.ply", splats)
    scene.artgs.output_dir = str(out)
    assert bpy.ops.artgs.import_splat() == {"FINISHED"}
    obj = scene.artgs.splat_object
    mesh = obj.data
    assert len(mesh.vertices) == 2000 and obj["artgs_gaussians"] == 2000
    co = np.empty(3 * 2000, np.float32)
    mesh.vertices.foreach_get("co", co)
    np.testing.assert_allclose(co.reshape(-1, 3), splats.means, atol=1e-6)
    srgb = np.clip(0.5 + 0.28209479177387814 * splats.sh[:, 0], 0, 1)
    np.testing.assert_allclose(_attribute(mesh, "Col", 4)[:, :3], srgb_to_linear(srgb), atol=1e-5)
    radius = 2 * np.exp(splats.log_scales.mean(axis=1))
    np.testing.assert_allclose(_attribute(mesh, "radius", 1), radius, rtol=1e-5)
    assert scene.artgs.reconstruct.status == "DONE" and "2000 Gaussians" in scene.artgs.reconstruct.message

    # Capped: a deterministic subset of the same Gaussians; the old preview is replaced.
    preferences.get().preview_cap, scene.artgs.preview_density = 1000, 0.3
    assert bpy.ops.artgs.import_splat() == {"FINISHED"}
    assert len([o for o in bpy.data.objects if o.type == "MESH"]) == 1 == len(bpy.data.meshes)
    mesh = scene.artgs.splat_object.data
    assert len(mesh.vertices) == 300
    co = np.empty(900, np.float32)
    mesh.vertices.foreach_get("co", co)
    rows = {tuple(r) for r in np.round(splats.means, 5)}
    assert all(tuple(r) in rows for r in np.round(co.reshape(-1, 3), 5))


def test_sh_constant_matches_the_engine():
    code = "from artgs.core.render.sh import C0; print(repr(C0))"
    C0 = float(subprocess.run([engine_python(), "-c", code], capture_output=True, text=True,
                              check=True).stdout)
    assert SH_C0 == pytest.approx(C0, abs=1e-15)


def _scene_state() -> tuple:
    return (sorted(o.name for o in bpy.data.objects), sorted(c.name for c in bpy.data.collections),
            len(bpy.data.meshes))


def test_engine_failure_reports_and_leaves_scene(scene, tmp_path, capture):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "transforms.json").write_text(json.dumps({"fl_x": 50, "frames": []}))
    scene.artgs.capture_dir, scene.artgs.output_dir = str(capture), str(tmp_path / "out")
    bpy.ops.artgs.import_capture()
    scene.artgs.capture_dir = str(bad)
    before = _scene_state()
    with pytest.raises(RuntimeError) as err:
        bpy.ops.artgs.reconstruct(iterations=2)
    message = scene.artgs.reconstruct.message
    assert scene.artgs.reconstruct.status == "FAILED" and str(bad / "transforms.json") in message
    assert message in str(err.value) and "Traceback" not in str(err.value)
    assert scene.artgs.reconstruct.text == f"failed: {message}"
    assert _scene_state() == before and scene.artgs.splat_object is None


def _preview_dirs() -> set[str]:
    return {p.name for p in Path(tempfile.gettempdir()).glob("artgs-capture-*")}


def test_failing_capture_import_leaves_scene(scene, tmp_path, capture):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "transforms.json").write_text("{not json")
    scene.artgs.capture_dir = str(bad)
    before, temporary = _scene_state(), _preview_dirs()
    with pytest.raises(RuntimeError, match="transforms.json"):
        bpy.ops.artgs.import_capture()
    assert scene.artgs.capture.status == "FAILED" and _scene_state() == before

    # A bad field of one frame: the engine's message names the file, the frame and the field.
    tj = json.loads((capture / "transforms.json").read_text())
    tj["frames"][1]["fl_x"] = -5
    (bad / "transforms.json").write_text(json.dumps(tj))
    with pytest.raises(RuntimeError) as err:
        bpy.ops.artgs.import_capture()
    message = scene.artgs.capture.message
    assert message.startswith(f"{bad / 'transforms.json'}, frame 1 ")
    assert "field 'fl_x'" in message and message in str(err.value)
    assert "Traceback" not in str(err.value)
    assert scene.artgs.capture.status == "FAILED" and _scene_state() == before
    assert _preview_dirs() <= temporary  # ours is gone (others may come and go meanwhile)


def _run(op, **kwargs) -> None:
    assert op(**kwargs) == {"FINISHED"}


def test_two_objects_in_one_scene_get_two_armatures(scene, tmp_path, capture):
    """Each object's joints live in their own armature, tied to its output folder: Propose Bones
    rebuilds only that one, Save Joints writes only that one, the previews stay apart."""
    drawer = generate_object(tmp_path / "drawer", "drawer", 1, width=64, height=48,
                             static_views=4, steps=2)
    settings = scene.artgs
    outs = {"cabinet": tmp_path / "out_cabinet", "drawer": tmp_path / "out_drawer"}
    for name, cap in (("cabinet", capture), ("drawer", drawer)):
        settings.capture_dir, settings.output_dir = str(cap), str(outs[name])
        _run(bpy.ops.artgs.import_capture)
        _run(bpy.ops.artgs.reconstruct, iterations=2)
        _run(bpy.ops.artgs.propose_bones)
        assert settings.propose.status == "DONE"
    arms = {o.name: o for o in bpy.data.objects if o.type == "ARMATURE"}
    assert sorted(arms) == ["ArtGS Joints cabinet", "ArtGS Joints drawer"]
    for name, out in outs.items():
        arm = arms[f"ArtGS Joints {name}"]
        assert arm["artgs_output"] == str(out.resolve())
        joints = read_articulation(out / "proposals.json").joints
        assert joints and sorted(b.name for b in arm.data.bones) == sorted(j.name for j in joints)
        previews = [o for o in bpy.data.objects if o.type == "MESH" and o.parent == arm]
        assert [Path(o["artgs_splat"]) for o in previews] == [(out / "splat.ply").resolve()]
        assert previews[0].modifiers["ArtGS Joints"].object == arm

    # The current output folder picks the armature, whichever object is active.
    cabinet, drawer_arm = arms["ArtGS Joints cabinet"], arms["ArtGS Joints drawer"]
    settings.output_dir = str(outs["cabinet"])
    bpy.context.view_layer.objects.active = drawer_arm
    assert find_armature(bpy.context) == cabinet
    drawer_file = (outs["drawer"] / "proposals.json").read_bytes()
    bone_name = cabinet.data.bones[0].name     # a name, not the bone: RNA pointers go stale
    bone = cabinet.data.bones[bone_name]
    bone.artgs_joint.upper = bone.artgs_joint.upper * 0.5
    _run(bpy.ops.artgs.save_joints)
    saved = {j.name: j for j in read_articulation(outs["cabinet"] / "proposals.json").joints}
    assert saved[bone_name].source == "user"
    assert saved[bone_name].limit[1] == pytest.approx(
        cabinet.data.bones[bone_name].artgs_joint.upper, rel=1e-6)
    assert (outs["drawer"] / "proposals.json").read_bytes() == drawer_file

    # Proposing again for the drawer rebuilds the drawer's armature in place.
    settings.capture_dir, settings.output_dir = str(drawer), str(outs["drawer"])
    assert find_armature(bpy.context) == drawer_arm
    _run(bpy.ops.artgs.propose_bones)
    assert sorted(o.name for o in bpy.data.objects if o.type == "ARMATURE") == sorted(arms)
    assert saved[bone_name].limit[1] == pytest.approx(
        cabinet.data.bones[bone_name].artgs_joint.upper)

    # An output folder without an armature gets none of the others'.
    settings.output_dir = str(tmp_path / "out_new")
    assert find_armature(bpy.context) is None
    assert not bpy.ops.artgs.save_joints.poll()


def test_vlm_refused_without_online_access(scene, tmp_path, capture):
    assert not bpy.app.online_access  # bpy as a module runs offline
    preferences.get().vlm_endpoint = "http://127.0.0.1:9/v1"
    scene.artgs.capture_dir, scene.artgs.output_dir = str(capture), str(tmp_path / "out")
    scene.artgs.proposal_method = "vlm"
    before = _scene_state()
    with pytest.raises(RuntimeError, match="Allow Online Access"):
        bpy.ops.artgs.propose_bones()
    assert scene.artgs.propose.status == "FAILED" and "Motion" in scene.artgs.propose.message
    assert _scene_state() == before and not (tmp_path / "out").exists()


def test_wrong_engine_fails_cleanly(scene, tmp_path, capture):
    preferences.get().engine_python = str(tmp_path / "no-python")
    scene.artgs.capture_dir, scene.artgs.output_dir = str(capture), str(tmp_path / "out")
    with pytest.raises(RuntimeError, match="Engine Python"):
        bpy.ops.artgs.reconstruct()
    assert scene.artgs.reconstruct.status == "FAILED"


def test_check_engine_reports_what_it_found(scene, tmp_path):
    assert bpy.ops.artgs.check_engine() == {"FINISHED"}
    found = [line for line in preferences.last_check if line.startswith("Found: ")]
    assert found and "numpy " in found[0] and "torch " in found[0]
    # An interpreter without the engine: the error names it and stays in the preferences.
    engine = tmp_path / "python-no-site"
    engine.write_text(f'#!/bin/sh\nexec "{sys.executable}" -S "$@"\n')
    engine.chmod(0o755)
    preferences.get().engine_python = str(engine)
    with pytest.raises(RuntimeError, match="No module named artgs"):
        bpy.ops.artgs.check_engine()
    assert str(engine) in preferences.last_check[-1]


def test_stage_panels_show_the_last_runs_key_figures(tmp_path):
    from artgs.artgs_addon.last_run import key_figures
    from artgs.core.model import layout
    from artgs.core.model.joints import Articulation, Joint, write_articulation

    assert key_figures(tmp_path, "reconstruct") == [] and key_figures(None, "propose") == []
    layout.update_report(tmp_path, "reconstruct", gaussians=14843, holdout_psnr=27.254, seconds=165.2)
    layout.update_report(tmp_path, "propose", joints=2, seconds=3.0)
    write_articulation(tmp_path / "proposals.json", Articulation([
        Joint("door", "revolute", [0, 0, 1], [0.1, 0, 0], (0, 1.5), confidence=0.83),
        Joint("drawer", "prismatic", [0, -1, 0], [0, 0, 0.2], (0, 0.3))]))
    splat = key_figures(tmp_path, "reconstruct")
    assert splat[0].startswith("last run ") and splat[0].endswith("(165 s)")
    assert splat[1:] == ["14,843 Gaussians", "held-out PSNR 27.25 dB"]
    assert key_figures(tmp_path, "propose")[1:] == [
        "2 joints", "door: revolute, confidence 0.83", "drawer: prismatic"]
    # a new run replaces the figures (the file is read again when it changes)
    import os
    import time

    layout.update_report(tmp_path, "reconstruct", gaussians=100, seconds=1.0)
    later = time.time() + 5
    os.utime(tmp_path / "report.json", (later, later))
    assert key_figures(tmp_path, "reconstruct")[1:] == [
        "100 Gaussians", "no held-out views (PSNR not measured)"]
    layout.update_report(tmp_path, "optimise", loss=0.0123, joints=1)
    write_articulation(tmp_path / "articulation.json", Articulation([
        Joint("door", "revolute", [0, 0, 1], [0.1, 0, 0], (0, 1.5), confidence=0.9,
              extra={"residual": 0.0111}),
        Joint("lid", "revolute", [1, 0, 0], [0, 0, 0.5], (0, 0.2), confidence=0.3,
              extra={"warnings": ["little motion seen"]})]))
    layout.update_report(tmp_path, "export", links={
        "base": {"faces": 1200, "collision_hulls": 3, "mass_kg": 12.345}},
        validation={"fk": {"ok": True}, "collision": {"ok": False}, "ok": False})
    layout.update_report(tmp_path, "check", success_rate=0.5, joints={
        "door": {"success": True}, "drawer": {"success": False, "reason": "slipped"}})
    os.utime(tmp_path / "report.json", (later + 5, later + 5))
    assert key_figures(tmp_path, "optimise")[1:] == [
        "residual (mean loss) 0.0123", "door: revolute, residual 0.0111, confidence 0.90",
        "lid: revolute, confidence 0.30", "  lid: little motion seen"]
    assert key_figures(tmp_path, "export")[1:] == [
        "1 links; fk ok, collision FAILED", "base: 1200 faces, 3 hulls, 12.35 kg"]
    assert key_figures(tmp_path, "check")[1:] == [
        "opened 1 of 2 parts", "door: opened", "drawer: not opened: slipped"]


def test_bad_splat_is_reported_in_blender_as_on_the_command_line(scene, tmp_path, capture):
    """Issue 13: the engine's one-line refusal (file, element, field) reaches Blender's report
    area through the worker unchanged, and OUT keeps its earlier proposals."""
    from artgs.core.model.ply import SplatArrays, write_ply
    out = tmp_path / "out"
    n = 20
    rng = np.random.default_rng(0)
    splat = SplatArrays(means=rng.normal(size=(n, 3)).astype(np.float32),
                        quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                        log_scales=np.full((n, 3), -4, np.float32),
                        opacity_logits=np.zeros(n, np.float32), sh=np.zeros((n, 1, 3), np.float32))
    write_ply(out / "splat.ply", splat)
    data = bytearray((out / "splat.ply").read_bytes())   # z of Gaussian 11 := inf
    start = data.index(b"end_header\n") + len(b"end_header\n") + 4 * (11 * 17 + 2)
    data[start:start + 4] = np.float32(np.inf).tobytes()
    (out / "splat.ply").write_bytes(bytes(data))
    (out / "proposals.json").write_text('{"frame": "world", "joints": [], "source": "user"}\n')
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    scene.artgs.capture_dir, scene.artgs.output_dir = str(capture), str(out)
    with pytest.raises(RuntimeError) as err:
        bpy.ops.artgs.propose_bones()
    message = scene.artgs.propose.message
    assert scene.artgs.propose.status == "FAILED"
    assert str(out / "splat.ply") in message and "vertex[11]" in message and "field 'z'" in message
    assert message in str(err.value) and "Traceback" not in str(err.value)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_optimise_joints_rebuilds_bones_and_parts_from_the_engine(scene, tmp_path, capture):
    """Optimise Joints runs `artgs optimise`: the bones end on articulation.json's joints, the
    splat preview is bound and coloured by the optimisation's part labels; a failure puts the
    bones back where they were."""
    from artgs.operators.optimise import PART_COLORS

    settings = scene.artgs
    settings.capture_dir, settings.output_dir = str(capture), str(tmp_path / "out")
    _run(bpy.ops.artgs.import_capture)
    _run(bpy.ops.artgs.reconstruct, iterations=2)
    _run(bpy.ops.artgs.propose_bones)
    arm = find_armature(bpy.context)
    before = {b.name: (tuple(b.head_local), tuple(b.tail_local)) for b in arm.data.bones}

    # A failing run (a splat the engine refuses) leaves the bones as they were.
    out = tmp_path / "out"
    good = (out / "splat.ply").read_bytes()
    (out / "splat.ply").write_bytes(good[:len(good) // 2])
    with pytest.raises(RuntimeError):
        bpy.ops.artgs.optimise_joints(iterations=5)
    assert settings.optimise.status == "FAILED" and "splat.ply" in settings.optimise.message
    after = {b.name: (tuple(b.head_local), tuple(b.tail_local)) for b in arm.data.bones}
    for name, (head, tail) in before.items():
        assert np.allclose(after[name][0], head, atol=1e-6)
        assert np.allclose(after[name][1], tail, atol=1e-6)
    (out / "splat.ply").write_bytes(good)

    _run(bpy.ops.artgs.optimise_joints, iterations=5)
    assert settings.optimise.status == "DONE"
    art = read_articulation(out / "articulation.json")
    assert art.meta["optimised"] is True
    arm = find_armature(bpy.context)
    M = np.array(arm.matrix_world)
    for joint in art.joints:
        bone = arm.data.bones[joint.name]
        head = M[:3, :3] @ np.array(bone.head_local) + M[:3, 3]
        axis = M[:3, :3] @ (np.array(bone.tail_local) - np.array(bone.head_local))
        assert np.linalg.norm(head - joint.origin) < 1e-4
        assert abs(abs(np.dot(axis / np.linalg.norm(axis), joint.axis)) - 1) < 1e-5
    preview = next(o for o in bpy.data.objects if o.type == "MESH" and o.parent == arm)
    labels = np.load(out / "part_labels.npy")
    index = np.empty(len(preview.data.vertices), np.float32)
    preview.data.attributes["gaussian"].data.foreach_get("value", index)
    expect = labels[np.rint(index).astype(int)]
    for k, joint in enumerate(art.joints, start=1):
        group = preview.vertex_groups[joint.name].index
        members = {v.index for v in preview.data.vertices
                   if any(g.group == group for g in v.groups)}
        assert members == set(np.flatnonzero(expect == k).tolist())
    assert preview.data.color_attributes.active_color.name == PART_COLORS
