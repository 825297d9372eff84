"""Property tests: a mutated capture or splat file is either read or refused with an InputError.

Hypothesis mutates a small valid capture (transforms.json fields, image sizes, bit depths and
channels, depth units, truncated files) and a small valid splat PLY (property types, counts,
NaN/Inf, truncation, flipped bytes). Whatever it makes, the readers either succeed with usable
data or raise :class:`InputError` with a message; never another exception.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from artgs.core.model.capture import load_capture
from artgs.core.model.errors import InputError
from artgs.core.model.ply import SplatArrays, read_ply, write_ply
from artgs.core.model.registry import ReconstructOptions
from artgs.core.stages.reconstruct import check as check_reconstruct
from ply_poke import poke_ply  # tests/ is on sys.path under pytest

W, H = 12, 9
SETTINGS = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


# --- a small valid capture -----------------------------------------------------------------------

def _pose(k: int) -> list[list[float]]:
    a = 0.4 * k
    c, s = math.cos(a), math.sin(a)
    return [[c, 0.0, s, 2 * s], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, 2 * c], [0.0, 0.0, 0.0, 1.0]]


def write_capture(root: Path) -> dict:
    """Two static RGB-D frames and two interaction frames; returns transforms.json's content."""
    for sub in ("images", "depth", "masks"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    frames = []
    for k, (phase, time) in enumerate([("static", None), ("static", None),
                                       ("interaction", 0), ("interaction", 1)]):
        rgb = np.full((H, W, 3), 40 * k + 20, np.uint8)
        depth = np.full((H, W), 2000, np.uint16)
        mask = np.zeros((H, W), np.uint8)
        mask[2:7, 3:9] = 255
        cv2.imwrite(str(root / f"images/{k}.png"), rgb)
        cv2.imwrite(str(root / f"depth/{k}.png"), depth)
        cv2.imwrite(str(root / f"masks/{k}.png"), mask)
        frame = {"file_path": f"images/{k}.png", "depth_file_path": f"depth/{k}.png",
                 "mask_path": f"masks/{k}.png", "transform_matrix": _pose(k), "phase": phase}
        if time is not None:
            frame["time"] = time
        frames.append(frame)
    tj = {"fl_x": 10.0, "fl_y": 10.0, "cx": W / 2, "cy": H / 2, "w": W, "h": H,
          "depth_unit_scale_factor": 0.001, "frames": frames}
    (root / "transforms.json").write_text(json.dumps(tj))
    return tj


TOP_KEYS = ["fl_x", "fl_y", "cx", "cy", "w", "h", "camera_model", "k1", "p2", "k4",
            "depth_unit_scale_factor", "frames", "robot"]
FRAME_KEYS = ["file_path", "depth_file_path", "mask_path", "transform_matrix", "phase", "time",
              "fl_x", "w", "h", "robot_joint_positions"]
FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)
VALUES = st.one_of(
    st.none(), st.booleans(), st.integers(-3, 70000), FLOATS,
    st.sampled_from(["", "static", "interaction", "OPENCV", "PINHOLE", "FISHEYE",
                     "images/0.png", "depth/1.png", "../x.png", "nope/none.png"]),
    st.lists(FLOATS, max_size=5),
    st.lists(st.lists(st.one_of(FLOATS, st.integers(-2, 2)), min_size=4, max_size=4),
             min_size=3, max_size=5),
    st.dictionaries(st.sampled_from(["a", "w"]), st.integers(0, 3), max_size=2))
MISSING = object()
edit_json = st.one_of(
    st.tuples(st.just("top"), st.sampled_from(TOP_KEYS), st.one_of(st.just(MISSING), VALUES)),
    st.tuples(st.integers(0, 3), st.sampled_from(FRAME_KEYS), st.one_of(st.just(MISSING), VALUES)))
edit_file = st.tuples(
    st.integers(0, 3), st.sampled_from(["images", "depth", "masks"]),
    st.one_of(
        st.tuples(st.just("image"), st.integers(1, 20), st.integers(1, 20),
                  st.sampled_from([np.uint8, np.uint16]), st.sampled_from([1, 3, 4]),
                  st.integers(0, 65535)),
        st.tuples(st.just("truncate"), st.integers(0, 200)),
        st.tuples(st.just("npy"), st.sampled_from([np.float32, np.float64, np.int32]),
                  st.sampled_from([-1.0, 0.0, 1.5, np.nan, np.inf]))))


def _apply_json(tj: dict, edit) -> None:
    where, key, value = edit
    holder = tj if where == "top" else tj["frames"][where]
    if value is MISSING:
        holder.pop(key, None)
    else:
        holder[key] = value


def _apply_file(root: Path, tj: dict, edit) -> None:
    k, sub, change = edit
    key = {"images": "file_path", "depth": "depth_file_path", "masks": "mask_path"}[sub]
    path = root / sub / f"{k}.png"
    if change[0] == "image":
        _, w, h, dtype, channels, value = change
        img = np.full((h, w, channels) if channels > 1 else (h, w),
                      value % (np.iinfo(dtype).max + 1), dtype)
        cv2.imwrite(str(path), img)
    elif change[0] == "truncate":
        path.write_bytes(path.read_bytes()[:change[1]])
    else:   # a float .npy instead (depth in metres; for images an unreadable format)
        _, dtype, value = change
        arr = np.full((H, W), 2.0, dtype)
        arr[0, 0] = value if np.issubdtype(dtype, np.floating) else 1
        np.save(root / sub / f"{k}.npy", arr)
        tj["frames"][k][key] = f"{sub}/{k}.npy"


@SETTINGS
@given(st.lists(edit_json, max_size=3), st.lists(edit_file, max_size=2))
def test_a_mutated_capture_is_read_or_refused_with_a_message(json_edits, file_edits):
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        tj = write_capture(root)
        for edit in file_edits:
            _apply_file(root, tj, edit)
        for edit in json_edits:
            _apply_json(tj, edit)
        (root / "transforms.json").write_text(json.dumps(tj))
        try:
            capture = load_capture(root)
            check_reconstruct(capture, ReconstructOptions(iterations=1))
        except InputError as exc:
            assert str(exc).strip()
            return
        for f in capture.frames:
            assert f.rgb.dtype == np.uint8 and f.rgb.shape == (f.camera.height, f.camera.width, 3)
            assert f.depth is None or (np.isfinite(f.depth).all() and (f.depth >= 0).all())
            assert np.isfinite(f.camera.K).all() and np.isfinite(f.camera.c2w).all()


def test_the_unmutated_capture_is_read(tmp_path):
    write_capture(tmp_path)
    capture = load_capture(tmp_path)
    assert len(capture.static) == 2 and capture.times == [0, 1]


# --- a small valid splat -------------------------------------------------------------------------

def _splat(n: int, degree: int) -> SplatArrays:
    rng = np.random.default_rng(n)
    quats = rng.normal(size=(n, 4)).astype(np.float32)
    return SplatArrays(means=rng.normal(size=(n, 3)).astype(np.float32), quats=quats,
                       log_scales=rng.normal(-4, 1, (n, 3)).astype(np.float32),
                       opacity_logits=rng.normal(size=n).astype(np.float32),
                       sh=rng.normal(size=(n, (degree + 1) ** 2, 3)).astype(np.float32))


PLY_TYPES = ["float", "double", "uchar", "char", "short", "int", "uint", "float32", "list uchar int",
             "half", "flot"]
edit_ply = st.one_of(
    st.tuples(st.just("value"), st.integers(0, 10_000), st.sampled_from(
        [np.nan, np.inf, -np.inf, 1e30, -0.0, 3.4e38])),
    st.tuples(st.just("type"), st.integers(0, 40), st.sampled_from(PLY_TYPES)),
    st.tuples(st.just("count"), st.sampled_from([0, 1, 2, 7, 10**9, -1])),
    st.tuples(st.just("truncate"), st.integers(0, 2000)),
    st.tuples(st.just("flip"), st.integers(0, 2000), st.integers(1, 255)),
    st.tuples(st.just("rename"), st.integers(0, 40), st.sampled_from(["x", "rot_0", "f_rest_0", ""])),
    st.tuples(st.just("ascii"),))


def _mutate_ply(data: bytes, splat: SplatArrays, edit) -> bytes:
    """``data`` with ``edit`` applied (unchanged when an earlier edit left nothing to edit)."""
    try:
        return _edit_ply(data, splat, edit)
    except (ValueError, UnicodeDecodeError, IndexError, ZeroDivisionError):
        return data


def _edit_ply(data: bytes, splat: SplatArrays, edit) -> bytes:
    head, _, body = data.partition(b"end_header\n")
    lines = head.decode().splitlines()
    props = [i for i, line in enumerate(lines) if line.startswith("property")]
    kind = edit[0]
    if kind == "value":
        values = np.frombuffer(body, "<f4").copy()
        values[edit[1] % len(values)] = edit[2]
        body = values.tobytes()
    elif kind == "type":
        i = props[edit[1] % len(props)]
        lines[i] = f"property {edit[2]} {lines[i].split()[-1]}"
    elif kind == "count":
        lines = [f"element vertex {edit[1]}" if line.startswith("element vertex") else line
                 for line in lines]
    elif kind == "rename":
        i = props[edit[1] % len(props)]
        lines[i] = f"property float {edit[2]}".rstrip()
    elif kind == "ascii":
        lines = [line.replace("binary_little_endian", "ascii") for line in lines]
        table = np.frombuffer(body, "<f4").reshape(len(splat), len(props))
        body = "".join(" ".join(f"{v:.9g}" for v in row) + "\n" for row in table).encode()
    out = ("\n".join(lines) + "\n").encode() + b"end_header\n" + body
    if kind == "truncate":
        out = out[:edit[1]]
    elif kind == "flip":
        b = bytearray(out)
        b[edit[1] % len(b)] ^= edit[2]
        out = bytes(b)
    return out


@SETTINGS
@given(st.integers(1, 6), st.sampled_from([0, 1]), st.lists(edit_ply, min_size=1, max_size=3))
def test_a_mutated_splat_is_read_or_refused_with_a_message(n, degree, edits):
    splat = _splat(n, degree)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "splat.ply"
        write_ply(path, splat)
        data = path.read_bytes()
        for edit in edits:
            data = _mutate_ply(data, splat, edit)
        path.write_bytes(data)
        try:
            got = read_ply(path)
        except InputError as exc:
            assert str(exc).startswith(str(path)) and str(exc).strip()
            return
    got.validate()
    assert len(got) > 0
    for a in (got.means, got.quats, got.log_scales, got.opacity_logits, got.sh):
        assert np.isfinite(a).all()
    assert (np.abs(got.quats) > 0).any(axis=1).all()


@pytest.mark.parametrize("value, field", [(np.nan, "x"), (np.inf, "opacity"), (-np.inf, "rot_2"),
                                          (np.nan, "f_dc_1"), (np.inf, "f_rest_7")])
def test_non_finite_values_name_the_element_and_field(tmp_path, value, field):
    write_ply(tmp_path / "s.ply", _splat(5, 1))
    poke_ply(tmp_path / "s.ply", 3, field, value)
    with pytest.raises(InputError, match=rf"field '{field}': element vertex\[3\] is"):
        read_ply(tmp_path / "s.ply")


def test_writer_refuses_what_the_reader_would_refuse(tmp_path):
    splat = _splat(5, 1)
    splat.quats[2] = 0
    with pytest.raises(ValueError, match=r"quats\[2, 0\] is the zero quaternion"):
        write_ply(tmp_path / "s.ply", splat)
    assert not list(tmp_path.iterdir())
