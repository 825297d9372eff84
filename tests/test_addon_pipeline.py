"""The whole pipeline through the add-on's operators, headless (scripts/headless_pipeline.py),
in a fresh Python with bpy as a module: outputs, armature, preview image, and none of the engine's
heavy dependencies in Blender's process (Blender's own Python has numpy only: the work, including
decoding the capture's images, stays in the worker)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from artgs.core.model.joints import read_articulation
from engine_env import engine_python
from engine_env import generate_capture as generate_object

pytest.importorskip("bpy")
ROOT = Path(__file__).resolve().parent.parent
#: Engine dependencies that must never load in Blender's process.
HEAVY = ("cv2", "torch", "scipy", "numba", "pybullet", "trimesh", "yourdfpy", "gsplat")

# Runs the headless script in this process, then reports what the checks need.
_DRIVER = """
import json, runpy, sys
sys.argv = ["headless_pipeline.py", *sys.argv[1:]]
try:
    runpy.run_path({script!r}, run_name="__main__")
except SystemExit as exc:
    code = exc.code
import addon_utils, bpy
addon_utils.enable("artgs", default_set=False, handle_error=None)
bpy.ops.wm.open_mainfile(filepath={blend!r})
arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
check = {{
    "code": code,
    "armatures": [(a.name, a.get("artgs_output")) for a in arms],
    "bones": sorted(b.name for a in arms for b in a.data.bones),
    "cameras": sum(o.type == "CAMERA" for o in bpy.data.objects),
    "splat": bpy.context.scene.artgs.splat_object is not None,
    "states": {{s: bpy.context.scene.artgs.stage(s).status for s in ("capture", "reconstruct", "propose")}},
}}
ops = bpy.ops.artgs  # the operators the pipeline does not run, in the same process
check["more"] = [sorted(op()) for op in (ops.import_splat, ops.add_joint, ops.save_joints,
                                         ops.check_engine)]
check["heavy"] = sorted(m for m in {heavy!r} if m in sys.modules)
print("CHECK " + json.dumps(check))
addon_utils.disable("artgs", default_set=False, handle_error=None)
"""


def test_headless_pipeline(tmp_path):
    capture = generate_object(tmp_path / "capture", "cabinet", 0, width=80, height=60,
                              static_views=6, steps=3)
    out = tmp_path / "out"
    driver = _DRIVER.format(script=str(ROOT / "scripts" / "headless_pipeline.py"),
                            blend=str(out / "scene.blend"), heavy=HEAVY)
    proc = subprocess.run([sys.executable, "-c", driver, str(capture), str(out),
                           "--iterations", "10", "--until", "propose", "--preview-size", "160", "--engine", engine_python(),
                           "--panels", str(out / "stages")],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("CHECK ")]
    assert lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    check = json.loads(lines[-1][6:])
    assert check["code"] in (0, None), proc.stderr[-3000:]
    assert check["heavy"] == []  # 'cv2' and 'torch' included: no engine work in Blender
    assert check["armatures"] == [["ArtGS Joints capture", str(out.resolve())]]
    for name in ("splat.ply", "proposals.json", "report.json", "scene.blend", "preview.png"):
        assert (out / name).is_file(), name
    assert check["more"] == [["FINISHED"]] * 4
    # proposals.json: the proposed joints (the armature's bones) and the joint added by hand
    joints = read_articulation(out / "proposals.json").joints
    assert len(joints) > 1 and sorted(check["bones"] + ["joint"]) == sorted(j.name for j in joints)
    assert [j.source for j in joints if j.name == "joint"] == ["user"]
    assert check["cameras"] >= 6 and check["splat"]
    assert check["states"] == {"capture": "DONE", "reconstruct": "DONE", "propose": "DONE"}

    # preview.png: the labelled contact sheet, 2x2 panels of 160x120 under 18-pixel labels
    sheet = read_png(out / "preview.png")
    tile_h, tile_w, gap = 18 + 120, 160, 4
    assert sheet.shape == (2 * tile_h + 3 * gap, 2 * tile_w + 3 * gap, 3)
    tiles = {}
    for k, name in enumerate(("capture", "splat", "joints", "posed")):
        r, c = divmod(k, 2)
        y, x = gap + r * (tile_h + gap), gap + c * (tile_w + gap)
        tiles[name] = sheet[y:y + tile_h, x:x + tile_w]
        assert np.array_equal(tiles[name], read_png(out / "stages" / f"{name}.png")), name
        label, image = tiles[name][:18], tiles[name][18:]
        assert (label.max(axis=2) > 150).mean() > 0.02, name  # the label's text is there
        background = np.median(image.reshape(-1, 3), axis=0)
        differs = np.abs(image.astype(int) - background).sum(axis=2) > 30
        assert 0.03 < differs.mean() < 0.95, name  # the object covers a real part of the panel
    # parts coloured: the joints panel has strongly saturated pixels, the plain splat far fewer
    saturation = {n: (t[18:].max(axis=2).astype(int) - t[18:].min(axis=2)) > 120
                  for n, t in tiles.items()}
    assert saturation["joints"].mean() > 3 * saturation["splat"].mean() + 0.005
    # posed open: parts moved, so the picture differs from the splat at rest
    assert np.abs(tiles["posed"].astype(int) - tiles["splat"]).sum(axis=2).mean() > 3


def read_png(path: Path) -> np.ndarray:
    """An 8-bit PNG as (H,W,3) uint8, top row first (read by Blender: no OpenCV here)."""
    import bpy

    img = bpy.data.images.load(str(path))
    try:
        w, h = img.size
        px = np.empty(w * h * img.channels, np.float32)
        img.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(img)
    rgb = px.reshape(h, w, -1)[::-1, :, :3]
    return (rgb * 255 + 0.5).astype(np.uint8)
