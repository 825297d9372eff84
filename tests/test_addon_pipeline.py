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
    "states": {{s: bpy.context.scene.artgs.stage(s).status for s in ("capture", "splat", "bones")}},
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
                           "--iterations", "10", "--preview-size", "160"],
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
    assert check["states"] == {"capture": "DONE", "splat": "DONE", "bones": "DONE"}

    import cv2

    img = cv2.imread(str(out / "preview.png"))
    assert img.shape[:2] == (120, 160)
    background = np.median(img.reshape(-1, 3), axis=0)
    # The object covers a real part of the image and is not background-coloured.
    differs = np.abs(img.astype(int) - background).sum(axis=2) > 30
    assert 0.03 < differs.mean() < 0.9
