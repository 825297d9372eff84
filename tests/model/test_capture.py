"""Capture reader (core/model/capture.py): valid captures load exactly, every bad input is refused
naming the file, the frame and the field."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from artgs.core.model.capture import Capture, load_capture
from artgs.core.model.cameras import look_at
from artgs.core.model.errors import InputError

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")  # before the first EXR is written
import cv2  # noqa: E402

W, H = 8, 6
FL, CX, CY = 10.0, 4.0, 3.0


def pose(k: int) -> np.ndarray:
    angle = 0.4 * k
    return look_at(np.array([2.0 * np.cos(angle), 2.0 * np.sin(angle), 1.0]), np.zeros(3))


def depth_m(k: int, w: int = W, h: int = H) -> np.ndarray:
    """Ground-truth depth of frame k in metres, whole millimetres (exact in 16-bit PNG)."""
    return (1.0 + 0.001 * (np.arange(w * h).reshape(h, w) + 7 * k)).astype(np.float32)


def rgb_of(k: int, w: int = W, h: int = H) -> np.ndarray:
    return np.random.default_rng(k).integers(0, 256, (h, w, 3), dtype=np.uint8)


def mask_of(k: int, w: int = W, h: int = H) -> np.ndarray:
    m = np.zeros((h, w), bool)
    m[1:h - 1, 1 + k % 2:w - 1] = True
    return m


def write_rgb(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))


def write_depth(path: Path, depth: np.ndarray, unit: float = 0.001) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".png":
        assert cv2.imwrite(str(path), np.round(depth / unit).astype(np.uint16))
    elif path.suffix == ".npy":
        np.save(path, depth.astype(np.float32))
    else:
        assert cv2.imwrite(str(path), depth.astype(np.float32))


def make_capture(root: Path, n_static: int = 3, n_interaction: int = 2, depth_ext: str = "png",
                 unit: float | None = None, w: int = W, h: int = H, **top) -> Path:
    """A valid capture: static then interaction frames, depth and masks on every frame."""
    frames = []
    for k in range(n_static + n_interaction):
        name = f"{k:04d}"
        write_rgb(root / "images" / f"{name}.png", rgb_of(k, w, h))
        write_depth(root / "depth" / f"{name}.{depth_ext}", depth_m(k, w, h), unit or 0.001)
        (root / "masks").mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(root / "masks" / f"{name}.png"), mask_of(k, w, h).astype(np.uint8) * 255)
        frame = {"file_path": f"images/{name}.png", "depth_file_path": f"depth/{name}.{depth_ext}",
                 "mask_path": f"masks/{name}.png", "transform_matrix": pose(k).tolist()}
        if k >= n_static:
            frame.update(phase="interaction", time=k - n_static,
                         robot_joint_positions=[0.1 * k, -0.2])
        frames.append(frame)
    meta = {"fl_x": FL, "fl_y": FL + 1, "cx": CX, "cy": CY, "w": w, "h": h, "frames": frames, **top}
    if unit is not None:
        meta["depth_unit_scale_factor"] = unit
    (root / "transforms.json").write_text(json.dumps(meta))
    return root


def edit(root: Path, change) -> None:
    """Apply ``change(meta)`` to transforms.json."""
    tj = root / "transforms.json"
    meta = json.loads(tj.read_text())
    change(meta)
    tj.write_text(json.dumps(meta))


@pytest.fixture
def cap(tmp_path: Path) -> Path:
    return make_capture(tmp_path / "cap")


def refused(root: Path, file: str, frame: int | None, field: str | None) -> InputError:
    """Assert load_capture refuses with a message naming ``file``, ``frame`` and ``field``."""
    with pytest.raises(InputError) as info:
        load_capture(root)
    err = info.value
    msg = str(err)
    assert err.file.endswith(file) and file in msg, msg
    if frame is None:
        assert err.frame is None, msg
    else:
        assert str(err.frame).startswith(str(frame)) and f"frame {frame}" in msg, msg
        fr = json.loads((root / "transforms.json").read_text())["frames"][frame]
        fp = fr.get("file_path") if isinstance(fr, dict) else None
        if fp:
            assert fp in msg, msg
    assert err.field == field, msg
    if field is not None:
        assert f"'{field}'" in msg, msg
    return err


# --- transforms.json as a whole ----------------------------------------------------------------

def test_transforms_missing(tmp_path):
    (tmp_path / "empty").mkdir()
    err = refused(tmp_path / "empty", "transforms.json", None, None)
    assert "not found" in str(err)


def test_capture_folder_missing(tmp_path):
    with pytest.raises(InputError, match="capture folder not found") as info:
        load_capture(tmp_path / "nowhere")
    assert info.value.file == str(tmp_path / "nowhere")


def test_transforms_not_json(cap):
    (cap / "transforms.json").write_text("{ frames: ")
    assert "not valid JSON" in str(refused(cap, "transforms.json", None, None))


def test_transforms_not_object(cap):
    (cap / "transforms.json").write_text("[1, 2]")
    assert "JSON object" in str(refused(cap, "transforms.json", None, None))


def test_frames_missing(cap):
    edit(cap, lambda m: m.pop("frames"))
    refused(cap, "transforms.json", None, "frames")


def test_frames_empty(cap):
    edit(cap, lambda m: m.update(frames=[]))
    refused(cap, "transforms.json", None, "frames")


@pytest.mark.parametrize("key", ["fl_x", "fl_y", "cx", "cy", "w", "h"])
def test_intrinsic_missing_at_both_levels(cap, key):
    edit(cap, lambda m: m.pop(key))
    err = refused(cap, "transforms.json", 0, key)
    assert "missing" in str(err)


@pytest.mark.parametrize("key,value", [("fl_x", 0), ("fl_y", -5.0), ("w", 0), ("h", -6)])
def test_intrinsic_not_positive(cap, key, value):
    edit(cap, lambda m: m.update({key: value}))
    assert "positive" in str(refused(cap, "transforms.json", 0, key))


def test_intrinsic_per_frame_bad_value(cap):
    edit(cap, lambda m: m["frames"][2].update(cx="4"))
    refused(cap, "transforms.json", 2, "cx")


def test_file_path_missing(cap):
    edit(cap, lambda m: m["frames"][1].pop("file_path"))
    refused(cap, "transforms.json", 1, "file_path")


@pytest.mark.parametrize("key,sub", [("file_path", "images/0003.png"),
                                     ("depth_file_path", "depth/0003.png"),
                                     ("mask_path", "masks/0003.png")])
def test_referenced_file_missing(cap, key, sub):
    (cap / sub).unlink()
    assert "not found" in str(refused(cap, sub, 3, key))


@pytest.mark.parametrize("key,sub", [("file_path", "images/0003.png"),
                                     ("depth_file_path", "depth/0003.png"),
                                     ("mask_path", "masks/0003.png")])
def test_referenced_file_unreadable(cap, key, sub):
    (cap / sub).write_bytes(b"not an image at all")
    assert "cannot be read" in str(refused(cap, sub, 3, key))


def test_depth_npy_unreadable(tmp_path):
    cap = make_capture(tmp_path / "c", depth_ext="npy")
    (cap / "depth/0001.npy").write_bytes(b"garbage")
    assert "cannot be read" in str(refused(cap, "depth/0001.npy", 1, "depth_file_path"))


@pytest.mark.parametrize("key,sub", [("file_path", "images/0001.png"),
                                     ("depth_file_path", "depth/0001.png"),
                                     ("mask_path", "masks/0001.png")])
def test_image_size_mismatch(cap, key, sub):
    img = cv2.imread(str(cap / sub), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(cap / sub), np.concatenate([img, img[:1]], axis=0))  # one row more
    err = refused(cap, sub, 1, key)
    assert f"{W}x{H + 1}" in str(err) and f"w={W}, h={H}" in str(err)


@pytest.mark.parametrize("matrix,words", [
    (None, "missing"),
    ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "4x4"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, "x"], [0, 0, 0, 1]], "4x4"),
    ([[1, 0, 0, float("nan")], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "non-finite"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 0], [0, 0, 0, 1]], "not invertible"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "bottom row"),
    ([[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]], "scaled"),
    ([[1, 0.01, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "not orthonormal"),
    ([[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "reflection"),
], ids=["missing", "3x3", "not-number", "nan", "singular", "bottom-row", "scaled", "sheared",
        "reflection"])
def test_bad_transform_matrix(cap, matrix, words):
    def change(m):
        if matrix is None:
            m["frames"][2].pop("transform_matrix")
        else:
            m["frames"][2]["transform_matrix"] = matrix
    edit(cap, change)
    assert words in str(refused(cap, "transforms.json", 2, "transform_matrix"))


def test_pose_within_tolerance_accepted_as_given(cap):
    c2w = pose(2)
    c2w[:3, :3] *= 1.0002  # rounding from a 4-decimal export
    edit(cap, lambda m: m["frames"][2].update(transform_matrix=c2w.tolist()))
    np.testing.assert_array_equal(load_capture(cap).frames[2].camera.c2w, c2w)


def test_depth_all_zero(cap):
    cv2.imwrite(str(cap / "depth/0002.png"), np.zeros((H, W), np.uint16))
    assert "no depth" in str(refused(cap, "depth/0002.png", 2, "depth_file_path"))


def test_depth_all_nan_npy(tmp_path):
    cap = make_capture(tmp_path / "c", depth_ext="npy")
    np.save(cap / "depth/0000.npy", np.full((H, W), np.nan, np.float32))
    refused(cap, "depth/0000.npy", 0, "depth_file_path")


def test_unknown_phase(cap):
    edit(cap, lambda m: m["frames"][4].update(phase="moving"))
    assert "moving" in str(refused(cap, "transforms.json", 4, "phase"))


def test_interaction_without_time(cap):
    edit(cap, lambda m: m["frames"][3].pop("time"))
    refused(cap, "transforms.json", 3, "time")


@pytest.mark.parametrize("value", [1.5, "1", True])
def test_interaction_time_not_integer(cap, value):
    edit(cap, lambda m: m["frames"][3].update(time=value))
    assert "integer" in str(refused(cap, "transforms.json", 3, "time"))


def test_negative_time(cap):
    edit(cap, lambda m: m["frames"][4].update(time=-1))
    assert "negative" in str(refused(cap, "transforms.json", 4, "time"))


def test_no_static_frame_with_depth(cap):
    def change(m):
        for f in m["frames"]:
            if f.get("phase", "static") == "static":
                f.pop("depth_file_path")
    edit(cap, change)
    assert "static" in str(refused(cap, "transforms.json", None, "frames"))


def test_no_static_frame_at_all(tmp_path):
    cap = make_capture(tmp_path / "c", n_static=0, n_interaction=2)
    refused(cap, "transforms.json", None, "frames")


@pytest.mark.parametrize("value", [0, -0.001, "0.001", None])
def test_bad_depth_unit_scale_factor(cap, value):
    edit(cap, lambda m: m.update(depth_unit_scale_factor=value))
    refused(cap, "transforms.json", None, "depth_unit_scale_factor")


def test_depth_png_8bit_refused(cap):
    cv2.imwrite(str(cap / "depth/0001.png"), np.full((H, W), 200, np.uint8))
    assert "16-bit" in str(refused(cap, "depth/0001.png", 1, "depth_file_path"))


def test_depth_npy_integer_refused(tmp_path):
    cap = make_capture(tmp_path / "c", depth_ext="npy")
    np.save(cap / "depth/0001.npy", np.full((H, W), 1000, np.uint16))
    assert "float" in str(refused(cap, "depth/0001.npy", 1, "depth_file_path"))


def test_depth_unsupported_suffix(cap):
    (cap / "depth/0001.tiff").write_bytes((cap / "depth/0001.png").read_bytes())
    edit(cap, lambda m: m["frames"][1].update(depth_file_path="depth/0001.tiff"))
    refused(cap, "depth/0001.tiff", 1, "depth_file_path")


def test_rgb_16bit_refused(cap):
    cv2.imwrite(str(cap / "images/0000.png"), np.full((H, W, 3), 1000, np.uint16))
    assert "8-bit" in str(refused(cap, "images/0000.png", 0, "file_path"))


def test_unsupported_camera_model(cap):
    edit(cap, lambda m: m.update(camera_model="OPENCV_FISHEYE"))
    refused(cap, "transforms.json", 0, "camera_model")


def test_pinhole_with_distortion_refused(cap):
    edit(cap, lambda m: m.update(camera_model="PINHOLE", k2=0.05))
    assert "PINHOLE" in str(refused(cap, "transforms.json", 0, "k2"))


def test_unsupported_distortion_coefficient_refused(cap):
    edit(cap, lambda m: m.update(camera_model="OPENCV", k1=0.1, k4=0.01))
    refused(cap, "transforms.json", 0, "k4")


def test_bad_robot_joint_positions(cap):
    edit(cap, lambda m: m["frames"][3].update(robot_joint_positions=[0.1, "a"]))
    refused(cap, "transforms.json", 3, "robot_joint_positions")


@pytest.mark.parametrize("robot,bad", [("franka_panda", [0.0] * 9), ("xarm6", [0.0] * 5),
                                       ("franka_panda", [0.0] * 6 + [float("nan"), 0.0])])
def test_robot_joint_positions_checked_against_the_robot(cap, robot, bad):
    """A known robot's vectors need its length (arm-only or with gripper) and finite values."""
    good = [0.1] * 7
    edit(cap, lambda m: (m.update(robot=robot), m["frames"][3].update(robot_joint_positions=good),
                         m["frames"][4].update(robot_joint_positions=bad)))
    refused(cap, "transforms.json", 4, "robot_joint_positions")
    edit(cap, lambda m: m["frames"][4].update(robot_joint_positions=good))
    assert load_capture(cap).frames[4].robot_joint_positions == pytest.approx(good)


def test_robot_base_pose(cap):
    edit(cap, lambda m: m.update(robot_base_pose=(2 * np.eye(4)).tolist()))
    refused(cap, "transforms.json", None, "robot_base_pose")
    edit(cap, lambda m: m.update(robot_base_pose=pose(1).tolist()))
    np.testing.assert_allclose(load_capture(cap).robot_base_pose, pose(1))


def test_frame_not_object(cap):
    edit(cap, lambda m: m["frames"].append("images/0000.png"))
    refused(cap, "transforms.json", 5, "frames")


def test_json_errors_come_before_image_decoding(cap):
    """A bad last frame is reported even though an earlier image is unreadable: no decoding yet."""
    (cap / "images/0000.png").write_bytes(b"broken")
    edit(cap, lambda m: m["frames"][4].update(phase="bogus"))
    refused(cap, "transforms.json", 4, "phase")


def test_loading_writes_nothing(cap):
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in cap.rglob("*") if p.is_file()}
    load_capture(cap)
    edit(cap, lambda m: m["frames"][4].update(phase="bogus"))
    before[cap / "transforms.json"] = ((cap / "transforms.json").stat().st_mtime_ns,
                                       (cap / "transforms.json").read_bytes())
    with pytest.raises(InputError):
        load_capture(cap)
    after = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in cap.rglob("*") if p.is_file()}
    assert after == before


# --- valid captures ----------------------------------------------------------------------------

def test_valid_capture(cap):
    edit(cap, lambda m: m.update(robot="custom_arm"))   # unknown robots: vectors not checked
    c = load_capture(cap)
    assert isinstance(c, Capture) and c.root == cap and c.robot == "custom_arm"
    assert len(c.frames) == 5 and [f.index for f in c.frames] == list(range(5))
    assert [f.phase for f in c.frames] == ["static"] * 3 + ["interaction"] * 2
    assert [f.time for f in c.frames] == [None, None, None, 0, 1] and c.times == [0, 1]
    assert len(c.static) == 3 and len(c.interaction) == 2
    assert c.frames[3].robot_joint_positions == pytest.approx([0.3, -0.2])
    assert c.frames[0].robot_joint_positions is None
    assert c.meta["depth_unit_scale_factor"] == 0.001 and c.meta["undistorted"] == []
    for k, f in enumerate(c.frames):
        assert f.file_path == f"images/{k:04d}.png"
        np.testing.assert_array_equal(f.camera.K, [[FL, 0, CX], [0, FL + 1, CY], [0, 0, 1]])
        np.testing.assert_allclose(f.camera.c2w, pose(k), atol=1e-12)
        assert (f.camera.width, f.camera.height) == (W, H)
        assert f.rgb.dtype == np.uint8 and f.rgb.shape == (H, W, 3)
        np.testing.assert_array_equal(f.rgb, rgb_of(k))  # RGB order, not BGR
        assert f.depth.dtype == np.float32
        np.testing.assert_allclose(f.depth, depth_m(k), rtol=0, atol=1e-6)
        assert f.mask.dtype == bool
        np.testing.assert_array_equal(f.mask, mask_of(k))


def test_unknown_keys_ignored(cap):
    plain = load_capture(cap)
    edit(cap, lambda m: m.update(unknown_key={"x": 1}, applied_transform=[1], k7="?")
         or m["frames"][0].update(colmap_im_id=3, some_other=None, depth="nonsense"))
    c = load_capture(cap)
    assert c.meta["transforms"]["unknown_key"] == {"x": 1}
    for a, b in zip(plain.frames, c.frames):
        np.testing.assert_array_equal(a.camera.K, b.camera.K)
        np.testing.assert_array_equal(a.camera.c2w, b.camera.c2w)
        np.testing.assert_array_equal(a.rgb, b.rgb)
        np.testing.assert_array_equal(a.depth, b.depth)
        assert (a.phase, a.time) == (b.phase, b.time)


def test_exr_reads_in_fresh_process_even_if_cv2_imported_first(tmp_path):
    """load_capture enables OpenCV's EXR codec itself (no variable set by the caller)."""
    cap = make_capture(tmp_path / "c", depth_ext="exr")
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_IO_ENABLE_OPENEXR"}
    code = ("import sys, cv2\nfrom artgs.core.model.capture import load_capture\n"
            "print(float(load_capture(sys.argv[1]).frames[2].depth[1, 3]))")
    r = subprocess.run([sys.executable, "-c", code, str(cap)], capture_output=True, text=True,
                       env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    assert float(r.stdout) == pytest.approx(float(depth_m(2)[1, 3]), abs=1e-7)


def test_accepts_transforms_json_path(cap):
    assert len(load_capture(cap / "transforms.json").frames) == 5


def test_depth_png_unit_scale_factor(tmp_path):
    cap = make_capture(tmp_path / "c", unit=0.0005)
    c = load_capture(cap)
    raw = cv2.imread(str(cap / "depth/0000.png"), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and raw[0, 0] == 2000  # 1.0 m in half-millimetres
    np.testing.assert_allclose(c.frames[0].depth, depth_m(0), atol=1e-6)
    np.testing.assert_allclose(c.frames[1].depth, depth_m(1), atol=1e-6)


@pytest.mark.parametrize("ext", ["npy", "exr"])
def test_depth_float_files_in_metres(tmp_path, ext):
    cap = make_capture(tmp_path / "c", depth_ext=ext)
    d = depth_m(0) + np.float32(0.00037)  # not whole millimetres: must be kept exactly
    bad = d.copy()
    bad[0, 0], bad[0, 1], bad[0, 2], bad[0, 3] = np.nan, np.inf, -np.inf, -2.0
    write_depth(cap / f"depth/0000.{ext}", bad)
    c = load_capture(cap)
    depth = c.frames[0].depth
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth[0, :4], 0.0)  # non-finite and negative -> no measurement
    np.testing.assert_array_equal(depth[1:], d[1:])
    np.testing.assert_allclose(c.frames[2].depth, depth_m(2), atol=1e-7)


def test_exr_with_three_equal_channels(tmp_path):
    cap = make_capture(tmp_path / "c", depth_ext="exr")
    cv2.imwrite(str(cap / "depth/0001.exr"), np.repeat(depth_m(1)[:, :, None], 3, axis=2))
    np.testing.assert_array_equal(load_capture(cap).frames[1].depth, depth_m(1))


def test_per_frame_intrinsics_win(tmp_path):
    cap = make_capture(tmp_path / "c")
    # frame 1 is a different, larger camera: its own intrinsics and images
    write_rgb(cap / "images/0001.png", rgb_of(1, 10, 7))
    write_depth(cap / "depth/0001.png", depth_m(1, 10, 7))
    cv2.imwrite(str(cap / "masks/0001.png"), mask_of(1, 10, 7).astype(np.uint8))
    edit(cap, lambda m: m["frames"][1].update(fl_x=20.0, fl_y=21.0, cx=5.0, cy=3.5, w=10, h=7))
    c = load_capture(cap)
    f1 = c.frames[1].camera
    np.testing.assert_array_equal(f1.K, [[20, 0, 5], [0, 21, 3.5], [0, 0, 1]])
    assert (f1.width, f1.height) == (10, 7) and c.frames[1].rgb.shape == (7, 10, 3)
    np.testing.assert_array_equal(c.frames[0].camera.K, [[FL, 0, CX], [0, FL + 1, CY], [0, 0, 1]])


def test_rgba_and_grey_images(cap):
    rgb = rgb_of(0)
    rgba = np.concatenate([rgb, np.full((H, W, 1), 17, np.uint8)], axis=2)
    cv2.imwrite(str(cap / "images/0000.png"), cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGRA))
    grey = rgb[:, :, 0]
    cv2.imwrite(str(cap / "images/0001.png"), grey)
    c = load_capture(cap)
    np.testing.assert_array_equal(c.frames[0].rgb, rgb)
    np.testing.assert_array_equal(c.frames[1].rgb, np.repeat(grey[:, :, None], 3, axis=2))


def test_optional_depth_and_mask_and_default_phase(cap):
    def change(m):
        m["frames"][1].pop("depth_file_path")
        m["frames"][1].pop("mask_path")
        m["frames"][2]["phase"] = "static"
        m["frames"][2]["time"] = 4.0  # integral JSON number accepted
    edit(cap, change)
    c = load_capture(cap)
    assert c.frames[1].depth is None and c.frames[1].mask is None
    assert c.frames[2].phase == "static" and c.frames[2].time == 4
    assert c.times == [0, 1]


def test_mask_any_non_zero_is_object(cap):
    m = np.zeros((H, W), np.uint8)
    m[2, 3], m[4, 5] = 1, 255
    cv2.imwrite(str(cap / "masks/0000.png"), m)
    assert np.flatnonzero(load_capture(cap).frames[0].mask).tolist() == [2 * W + 3, 4 * W + 5]


# --- distortion --------------------------------------------------------------------------------

DIST = {"k1": 0.3, "k2": -0.05, "p1": 0.01, "p2": -0.008}


def test_distorted_frames_are_undistorted(tmp_path):
    w, h, fl = 40, 30, 30.0
    cap = make_capture(tmp_path / "c", w=w, h=h)
    edit(cap, lambda m: m.update(fl_x=fl, fl_y=fl, cx=20.0, cy=15.0, camera_model="OPENCV", **DIST))
    c = load_capture(cap)
    assert c.meta["undistorted"] == [0, 1, 2, 3, 4]
    K_cv = np.array([[fl, 0, 19.5], [0, fl, 14.5], [0, 0, 1]])  # OpenCV: pixel centres at integers
    dist = np.array([DIST["k1"], DIST["k2"], DIST["p1"], DIST["p2"]])
    f = c.frames[1]
    np.testing.assert_array_equal(f.camera.K, [[fl, 0, 20], [0, fl, 15], [0, 0, 1]])
    rays = f.camera.pixel_rays().reshape(-1, 3)
    src, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), K_cv, dist)
    src = src.reshape(-1, 2)  # where each output pixel looks in the distorted source image
    seen = ((src[:, 0] >= -0.5) & (src[:, 0] <= w - 0.5) & (src[:, 1] >= -0.5)
            & (src[:, 1] <= h - 0.5))
    interior = (src[:, 0] >= 0) & (src[:, 0] <= w - 1) & (src[:, 1] >= 0) & (src[:, 1] <= h - 1)
    assert 0 < (~seen).sum() < seen.sum()  # pincushion: corners see outside the source

    # RGB: as cv2.undistort (bilinear) inside; black where the source has nothing.
    expected = cv2.undistort(rgb_of(1, w, h), K_cv, dist).reshape(-1, 3)
    rgb = f.rgb.reshape(-1, 3).astype(int)
    assert np.abs(rgb[interior] - expected[interior]).max() <= 1
    assert not rgb[~seen].any()

    # depth and mask: nearest neighbour (the source pixel nearest to the projected ray).
    ij = np.clip(np.round(src[seen]).astype(int), 0, [w - 1, h - 1])
    truth = depth_m(1, w, h)[ij[:, 1], ij[:, 0]]
    got = f.depth.reshape(-1)[seen]
    assert np.mean(np.isclose(got, truth, rtol=0, atol=1e-6)) > 0.97  # rounding ties may differ
    step = np.abs(got[:, None] - depth_m(1, w, h).reshape(1, -1)).min(axis=1)
    assert step.max() < 1e-6  # every value is a source value: copied, never interpolated
    np.testing.assert_array_equal(f.depth.reshape(-1)[~seen], 0)
    mask_truth = mask_of(1, w, h)[ij[:, 1], ij[:, 0]]
    assert np.mean(f.mask.reshape(-1)[seen] == mask_truth) > 0.97
    assert not f.mask.reshape(-1)[~seen].any()


def test_undistortion_creates_mask_of_seen_pixels(tmp_path):
    w, h = 40, 30
    cap = make_capture(tmp_path / "c", w=w, h=h)
    edit(cap, lambda m: [fr.pop("mask_path") for fr in m["frames"]] and m.update(
        fl_x=30.0, fl_y=30.0, cx=20.0, cy=15.0, **DIST))  # no camera_model: OPENCV inferred
    f = load_capture(cap).frames[0]
    assert f.mask is not None and f.mask.dtype == bool
    assert not f.mask[0, 0] and not f.mask[-1, -1] and f.mask[h // 2, w // 2]


def test_zero_distortion_is_pinhole(cap):
    edit(cap, lambda m: m.update(camera_model="OPENCV", k1=0.0, k2=0, p1=0, p2=0))
    c = load_capture(cap)
    assert c.meta["undistorted"] == []
    np.testing.assert_array_equal(c.frames[0].rgb, rgb_of(0))


# --- `artgs validate` --------------------------------------------------------------------------

def run_validate(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "artgs", "validate", *args], capture_output=True,
                          text=True, timeout=120)


def test_cli_validate(cap):
    r = run_validate(str(cap))
    assert r.returncode == 0, r.stderr
    assert "3 static, 2 interaction" in r.stdout and f"{W}x{H}" in r.stdout
    r = run_validate(str(cap), "--json")
    assert r.returncode == 0, r.stderr
    last = json.loads(r.stdout.strip().splitlines()[-1])
    assert last["event"] == "finished"
    out = last["outputs"]
    assert (out["static_frames"], out["interaction_frames"]) == (3, 2)
    assert out["image_sizes"] == [[W, H]] and out["interaction_times"] == [0, 1]
    assert out["frames_with_mask"] == 5 and out["frames_with_depth"] == 5
    assert out["depth_min_m"] == pytest.approx(1.0) and out["depth_max_m"] == pytest.approx(
        float(depth_m(4).max()), abs=1e-6)

    edit(cap, lambda m: m["frames"][3].pop("time"))
    r = run_validate(str(cap))
    assert r.returncode == 2
    assert "transforms.json" in r.stderr and "frame 3 ('images/0003.png')" in r.stderr
    assert "'time'" in r.stderr
    r = run_validate(str(cap), "--json")
    assert r.returncode == 2
    err = json.loads(r.stdout.strip().splitlines()[-1])
    assert err["event"] == "error" and "'time'" in err["message"]


def test_first_bad_frame_in_file_order_is_reported(cap):
    (cap / "images/0004.png").write_bytes(b"broken")
    (cap / "depth/0001.png").write_bytes(b"broken")
    refused(cap, "depth/0001.png", 1, "depth_file_path")


def test_synthetic_capture_loads(tmp_path):
    """The synthetic generator's captures (core/synth/generate.py) load with this reader."""
    synth = pytest.importorskip("artgs.core.synth.generate")
    root = synth.generate_object(tmp_path / "cab", "cabinet", 0, width=64, height=48,
                                 static_views=4, steps=2)
    meta = json.loads((root / "transforms.json").read_text())
    c = load_capture(root)
    assert len(c.frames) == len(meta["frames"]) and len(c.static) == 4
    assert c.interaction and c.times == sorted({f["time"] for f in meta["frames"]
                                                if f.get("phase") == "interaction"})
    for f in c.frames:
        assert f.rgb.shape == (48, 64, 3) and f.depth is not None and (f.depth > 0).any()
