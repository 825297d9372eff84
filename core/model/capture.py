"""Capture folders (shared/spec/capture-format.md) read into typed data, validated up front.

``load_capture(path)`` either returns a fully valid :class:`Capture` or raises
:class:`~.errors.InputError` naming the file (``transforms.json`` or the image), the frame
(``index ('file_path')``) and the field. It checks everything in ``transforms.json`` for every
frame and that every referenced file exists before it decodes any image, and it writes nothing.

Decisions where the format leaves room (also the documentation of what is accepted):

- Intrinsics ``fl_x fl_y cx cy w h``, ``camera_model`` and the distortion ``k1 k2 p1 p2 k3`` may be
  at the top level or per frame; the frame's value wins. ``cx``, ``cy`` use the project's pixel
  convention (pixel (i, j) has its centre at (j + 0.5, i + 0.5)), as nerfstudio and COLMAP do.
- ``camera_model`` is ``PINHOLE`` or ``OPENCV`` (case-insensitive); without it, the model is
  ``OPENCV`` when a distortion coefficient is non-zero. ``PINHOLE`` with non-zero distortion and
  non-zero ``k4``..``k6`` are refused. Distorted frames are undistorted on load to a pinhole camera
  with the same ``K`` and size (cv2: RGB bilinear, depth and mask nearest-neighbour), which
  matches ``cv2.undistort`` with ``cx - 0.5, cy - 0.5`` (OpenCV's pixel convention) except that
  the half-pixel band at the image border is not blended with black. Pixels that see outside the
  source image get RGB 0, depth 0 and mask False (a mask is created if there was none).
- RGB must be 8-bit. Greyscale is converted to RGB; alpha is dropped. EXIF orientation is ignored
  (pixels are used as stored, which is what the intrinsics describe).
- Depth: 16-bit single-channel PNG times ``depth_unit_scale_factor`` (default 0.001 m; 8-bit PNG is
  refused), or floating-point ``.npy``/``.exr`` in metres (an EXR with several equal channels is
  accepted). Non-finite or negative depth becomes 0 (no measurement). A frame whose depth is all 0
  is refused.
- Masks: any 8/16-bit image; a pixel is object where any colour channel is non-zero (alpha ignored).
- ``time`` is required for ``interaction`` frames and must be a non-negative integer (an integral
  JSON number such as ``3.0`` is accepted); it is kept, and checked the same way, on static frames.
- A capture must have at least one ``static`` frame with depth (reconstruction needs them); this
  is checked here so every command refuses such a capture before any work.
- Poses: ``transform_matrix`` must be a finite 4x4 rigid transform: bottom row ``[0, 0, 0, 1]``,
  rotation part orthonormal within 1e-3 with determinant +1 (scaled or mirrored poses are refused).
- Unknown keys are ignored.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .cameras import Camera, intrinsics
from .errors import InputError
from .jsonio import read_json_object

PHASES = ("static", "interaction")
CAMERA_MODELS = ("PINHOLE", "OPENCV")
INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3")  # OpenCV's order
UNSUPPORTED_DISTORTION_KEYS = ("k4", "k5", "k6")
DEFAULT_DEPTH_UNIT = 0.001
DEPTH_SUFFIXES = (".png", ".npy", ".exr")
#: Largest |RᵀR - I| entry accepted for the rotation part of a pose.
ROTATION_TOLERANCE = 1e-3
TRANSFORMS = "transforms.json"


@dataclass
class Frame:
    """One RGB-D frame, loaded and validated.

    ``rgb`` (H,W,3) uint8; ``depth`` (H,W) float32 metres, 0 where there is no measurement;
    ``mask`` (H,W) bool or None (None: every pixel is object).
    """

    index: int
    file_path: str
    camera: Camera
    rgb: np.ndarray
    depth: np.ndarray | None
    mask: np.ndarray | None
    phase: str = "static"
    time: int | None = None
    robot_joint_positions: list[float] | None = None


@dataclass
class Capture:
    """A whole capture: frames in file order, plus the optional robot model name.

    ``meta`` from :func:`load_capture`: ``transforms`` (the top-level keys of transforms.json except
    ``frames``, as read), ``depth_unit_scale_factor`` and ``undistorted`` (indices of the frames
    that were undistorted on load).
    """

    root: Path
    frames: list[Frame]
    robot: str | None = None
    meta: dict = field(default_factory=dict)

    @property
    def static(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "static"]

    @property
    def interaction(self) -> list[Frame]:
        return [f for f in self.frames if f.phase == "interaction"]

    @property
    def times(self) -> list[int]:
        """Sorted distinct interaction steps."""
        return sorted({f.time for f in self.interaction if f.time is not None})


@dataclass
class _FrameSpec:
    """A frame as described by transforms.json, checked but not yet decoded."""

    index: int
    label: str
    file_path: str
    rgb_path: Path
    depth_path: Path | None
    mask_path: Path | None
    K: np.ndarray
    distortion: np.ndarray | None  # OpenCV (k1, k2, p1, p2, k3), None when there is none
    width: int
    height: int
    c2w: np.ndarray
    phase: str
    time: int | None
    robot_joint_positions: list[float] | None


def load_capture(path: str | Path) -> Capture:
    """Read and validate the capture folder ``path`` (or its transforms.json); see the module doc."""
    path = Path(path)
    root = path.parent if path.name == TRANSFORMS and path.is_file() else path
    if not root.is_dir():
        raise InputError(root, "capture folder not found")
    tj = root / TRANSFORMS
    top = _read_transforms(tj)
    frames_raw = top.get("frames")
    if not isinstance(frames_raw, list) or not frames_raw:
        raise InputError(tj, "needs a non-empty list of frames", field="frames")
    scale = top.get("depth_unit_scale_factor", DEFAULT_DEPTH_UNIT)
    if not _is_number(scale) or not math.isfinite(scale) or scale <= 0:
        raise InputError(tj, f"must be a positive number of metres per depth-PNG unit, not {scale!r}",
                         field="depth_unit_scale_factor")
    robot = top.get("robot")
    if robot is not None and not isinstance(robot, str):
        raise InputError(tj, f"must be a robot model name (a string), not {robot!r}", field="robot")

    specs = [_parse_frame(i, raw, top, tj, root) for i, raw in enumerate(frames_raw)]
    if not any(s.phase == "static" and s.depth_path is not None for s in specs):
        raise InputError(tj, "no static frame with depth: reconstruction needs static RGB-D views "
                         "(phase 'static' and a depth_file_path)", field="frames")
    for s in specs:
        for key, p in (("file_path", s.rgb_path), ("depth_file_path", s.depth_path),
                       ("mask_path", s.mask_path)):
            if p is not None and not p.is_file():
                raise InputError(p, "file not found", frame=s.label, field=key)

    maps: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    for s in specs:  # undistortion tables first, so the decoding threads only read the cache
        if s.distortion is not None:
            _undistort_maps(s, maps)
    # cv2 decodes without the GIL; map() yields in order, so the first bad frame is reported.
    pool = ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1))
    try:
        frames = list(pool.map(lambda s: _load_frame(s, float(scale), maps), specs))
    finally:
        pool.shutdown(cancel_futures=True)
    meta = {"transforms": {k: v for k, v in top.items() if k != "frames"},
            "depth_unit_scale_factor": float(scale),
            "undistorted": [s.index for s in specs if s.distortion is not None]}
    return Capture(root=root, frames=frames, robot=robot, meta=meta)


# --- transforms.json ---------------------------------------------------------------------------

def _read_transforms(tj: Path) -> dict[str, Any]:
    return read_json_object(tj, "file not found: a capture folder needs a transforms.json")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_integral(v: Any) -> bool:
    return _is_number(v) and math.isfinite(v) and float(v).is_integer()


def _parse_frame(i: int, raw: Any, top: dict, tj: Path, root: Path) -> _FrameSpec:
    if not isinstance(raw, dict):
        raise InputError(tj, "each frame must be a JSON object", frame=i, field="frames")
    file_path = raw.get("file_path")
    if not isinstance(file_path, str) or not file_path:
        raise InputError(tj, "missing the RGB image path", frame=i, field="file_path")
    label = f"{i} ('{file_path}')"

    def lookup(key: str) -> Any:
        return raw[key] if key in raw else top.get(key)

    values: dict[str, float] = {}
    for key in INTRINSIC_KEYS:
        v = lookup(key)
        if v is None:
            raise InputError(tj, f"missing intrinsic '{key}' (needed at the top level or in the "
                             "frame)", frame=label, field=key)
        if not _is_number(v) or not math.isfinite(v):
            raise InputError(tj, f"must be a finite number, not {v!r}", frame=label, field=key)
        if key in ("fl_x", "fl_y", "w", "h") and v <= 0:
            raise InputError(tj, f"must be positive, not {v!r}", frame=label, field=key)
        if key in ("w", "h") and not _is_integral(v):
            raise InputError(tj, f"must be a whole number of pixels, not {v!r}", frame=label, field=key)
        values[key] = float(v)
    K = intrinsics(values["fl_x"], values["fl_y"], values["cx"], values["cy"])

    return _FrameSpec(
        index=i, label=label, file_path=file_path,
        rgb_path=root / file_path,
        depth_path=_optional_path(raw, "depth_file_path", tj, label, root),
        mask_path=_optional_path(raw, "mask_path", tj, label, root),
        K=K, distortion=_distortion(lookup, tj, label),
        width=int(values["w"]), height=int(values["h"]),
        c2w=_pose(raw.get("transform_matrix"), tj, label),
        phase=_phase(raw, tj, label), time=_time(raw, tj, label),
        robot_joint_positions=_joint_positions(raw, tj, label))


def _optional_path(raw: dict, key: str, tj: Path, label: str, root: Path) -> Path | None:
    v = raw.get(key)
    if v is None:
        return None
    if not isinstance(v, str) or not v:
        raise InputError(tj, f"must be a path relative to the capture folder, not {v!r}",
                         frame=label, field=key)
    return root / v


def _distortion(lookup, tj: Path, label: str) -> np.ndarray | None:
    """OpenCV distortion vector, or None when the camera is a plain pinhole."""
    model = lookup("camera_model")
    if model is not None and (not isinstance(model, str) or model.upper() not in CAMERA_MODELS):
        raise InputError(tj, f"unsupported camera model {model!r}; supported: "
                         f"{', '.join(CAMERA_MODELS)}", frame=label, field="camera_model")
    coeffs = []
    for key in DISTORTION_KEYS + UNSUPPORTED_DISTORTION_KEYS:
        v = lookup(key)
        v = 0.0 if v is None else v
        if not _is_number(v) or not math.isfinite(v):
            raise InputError(tj, f"must be a finite number, not {v!r}", frame=label, field=key)
        if key in UNSUPPORTED_DISTORTION_KEYS and v != 0:
            raise InputError(tj, f"is {v}, but only {' '.join(DISTORTION_KEYS)} distortion is "
                             "supported", frame=label, field=key)
        coeffs.append(float(v))
    dist = np.array(coeffs[:len(DISTORTION_KEYS)])
    if not dist.any():
        return None
    if model is not None and model.upper() == "PINHOLE":
        key = DISTORTION_KEYS[int(np.flatnonzero(dist)[0])]
        raise InputError(tj, "camera_model is PINHOLE but the distortion coefficients are not zero; "
                         "set camera_model to OPENCV or remove the coefficients",
                         frame=label, field=key)
    return dist


def _pose(value: Any, tj: Path, label: str) -> np.ndarray:
    f = "transform_matrix"
    if value is None:
        raise InputError(tj, "missing the 4x4 camera-to-world matrix", frame=label, field=f)
    if not (isinstance(value, list) and len(value) == 4
            and all(isinstance(r, list) and len(r) == 4 and all(_is_number(x) for x in r)
                    for r in value)):
        raise InputError(tj, "must be a 4x4 matrix of numbers (a list of 4 rows of 4)",
                         frame=label, field=f)
    M = np.array(value, dtype=np.float64)
    if not np.isfinite(M).all():
        raise InputError(tj, "contains non-finite values", frame=label, field=f)
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise InputError(tj, f"bottom row must be [0, 0, 0, 1], not {M[3].tolist()}",
                         frame=label, field=f)
    R = M[:3, :3]
    det = float(np.linalg.det(R))
    if abs(det) < 1e-9:
        raise InputError(tj, "is not invertible (its rotation part is singular)", frame=label, field=f)
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > ROTATION_TOLERANCE:
        norms = ", ".join(f"{n:.4g}" for n in np.linalg.norm(R, axis=0))
        raise InputError(tj, f"rotation part is not orthonormal (column lengths {norms}, max "
                         f"|RᵀR - I| = {err:.3g} > {ROTATION_TOLERANCE}); a scaled or sheared pose "
                         "is a common export bug: export rigid camera poses in metres",
                         frame=label, field=f)
    if det < 0:
        raise InputError(tj, "rotation part is a reflection (determinant -1); camera poses must be "
                         "rotations", frame=label, field=f)
    return M


def _phase(raw: dict, tj: Path, label: str) -> str:
    phase = raw.get("phase", "static")
    if phase not in PHASES:
        raise InputError(tj, f"unknown phase {phase!r}; expected one of {', '.join(PHASES)}",
                         frame=label, field="phase")
    return phase


def _time(raw: dict, tj: Path, label: str) -> int | None:
    t = raw.get("time")
    if t is None:
        if raw.get("phase") == "interaction":
            raise InputError(tj, "interaction frames need an integer 'time' (the interaction step)",
                             frame=label, field="time")
        return None
    if not _is_integral(t):
        raise InputError(tj, f"must be an integer interaction step, not {t!r}", frame=label,
                         field="time")
    if t < 0:
        raise InputError(tj, f"must not be negative, not {t!r}", frame=label, field="time")
    return int(t)


def _joint_positions(raw: dict, tj: Path, label: str) -> list[float] | None:
    q = raw.get("robot_joint_positions")
    if q is None:
        return None
    if not isinstance(q, list) or not all(_is_number(x) and math.isfinite(x) for x in q):
        raise InputError(tj, "must be a list of finite numbers (radians/metres)", frame=label,
                         field="robot_joint_positions")
    return [float(x) for x in q]


# --- images ------------------------------------------------------------------------------------

def _cv2():
    """OpenCV, with its EXR codec enabled (it reads the variable at the first EXR it meets)."""
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
    import cv2

    return cv2


def _decode(path: Path, flags: int) -> np.ndarray | None:
    """cv2 decode from bytes (works for non-ASCII paths on Windows too); None if unreadable."""
    cv2 = _cv2()
    try:
        data = np.fromfile(path, dtype=np.uint8)
        return cv2.imdecode(data, flags) if data.size else None
    except (OSError, cv2.error):
        return None


def _check_size(img: np.ndarray, s: _FrameSpec, path: Path, key: str) -> None:
    h, w = img.shape[:2]
    if (w, h) != (s.width, s.height):
        raise InputError(path, f"is {w}x{h} pixels but the intrinsics say w={s.width}, h={s.height}",
                         frame=s.label, field=key)


def _read_rgb(s: _FrameSpec) -> np.ndarray:
    cv2 = _cv2()
    img = _decode(s.rgb_path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(s.rgb_path, "cannot be read as an image", frame=s.label, field="file_path")
    if img.dtype != np.uint8:
        raise InputError(s.rgb_path, f"RGB images must be 8-bit, this one is {img.dtype}",
                         frame=s.label, field="file_path")
    _check_size(img, s, s.rgb_path, "file_path")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 2:
        return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    if img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    raise InputError(s.rgb_path, f"has {img.shape[2]} channels; expected RGB, RGBA or grey",
                     frame=s.label, field="file_path")


def _read_depth(s: _FrameSpec, scale: float) -> np.ndarray:
    path, key = s.depth_path, "depth_file_path"
    assert path is not None
    suffix = path.suffix.lower()
    if suffix not in DEPTH_SUFFIXES:
        raise InputError(path, "depth must be a 16-bit .png or a float .npy/.exr", frame=s.label,
                         field=key)
    if suffix == ".npy":
        try:
            raw = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise InputError(path, f"cannot be read as a .npy array ({exc})", frame=s.label,
                             field=key) from exc
        if not np.issubdtype(raw.dtype, np.floating):
            raise InputError(path, f"depth .npy must be float metres, this one is {raw.dtype}",
                             frame=s.label, field=key)
    else:
        cv2 = _cv2()
        raw = _decode(path, cv2.IMREAD_UNCHANGED)
        if raw is None:
            hint = (" (OpenCV's EXR codec is enabled only if OPENCV_IO_ENABLE_OPENEXR=1 is set "
                    "before the first EXR is read in the process)" if suffix == ".exr" else "")
            raise InputError(path, "cannot be read as an image" + hint, frame=s.label, field=key)
        if suffix == ".png" and raw.dtype != np.uint16:
            raise InputError(path, f"depth PNG must be 16-bit (units of depth_unit_scale_factor), "
                             f"this one is {raw.dtype}; or give float metres as .npy/.exr",
                             frame=s.label, field=key)
    if raw.ndim == 3 and np.array_equal(raw, np.repeat(raw[:, :, :1], raw.shape[2], axis=2),
                                        equal_nan=raw.dtype.kind == "f"):
        raw = raw[:, :, 0]
    if raw.ndim != 2:
        raise InputError(path, f"depth must be a single-channel image, this one has shape "
                         f"{raw.shape}", frame=s.label, field=key)
    _check_size(raw, s, path, key)
    if raw.dtype == np.uint16:
        depth = raw.astype(np.float32) * np.float32(scale)
    else:
        depth = raw.astype(np.float32, copy=False)
        depth = np.where(np.isfinite(depth) & (depth > 0), depth, np.float32(0))
    if not depth.any():
        raise InputError(path, "has no depth measurement (every pixel is 0 or not finite)",
                         frame=s.label, field=key)
    return depth


def _read_mask(s: _FrameSpec) -> np.ndarray:
    path = s.mask_path
    assert path is not None
    cv2 = _cv2()
    img = _decode(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, "cannot be read as an image", frame=s.label, field="mask_path")
    _check_size(img, s, path, "mask_path")
    return (img[:, :, :3] != 0).any(axis=2) if img.ndim == 3 else img != 0


def _undistort_maps(s: _FrameSpec, cache: dict) -> tuple[np.ndarray, np.ndarray]:
    """Float remap tables from the pinhole image (same K and size) into the distorted image."""
    key = (s.K.tobytes(), s.distortion.tobytes(), s.width, s.height)
    if key not in cache:
        cv2 = _cv2()
        K_cv = s.K.copy()
        K_cv[:2, 2] -= 0.5  # OpenCV puts pixel centres at integer coordinates
        cache[key] = cv2.initUndistortRectifyMap(K_cv, s.distortion, None, K_cv,
                                                 (s.width, s.height), cv2.CV_32FC1)
    return cache[key]


def _load_frame(s: _FrameSpec, scale: float, maps: dict) -> Frame:
    rgb = _read_rgb(s)
    depth = _read_depth(s, scale) if s.depth_path is not None else None
    mask = _read_mask(s) if s.mask_path is not None else None
    if s.distortion is not None:
        cv2 = _cv2()
        mx, my = _undistort_maps(s, maps)
        # The source image covers [-0.5, size - 0.5] in OpenCV pixel coordinates.
        seen = (mx >= -0.5) & (mx <= s.width - 0.5) & (my >= -0.5) & (my <= s.height - 0.5)
        rgb = cv2.remap(rgb, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        rgb[~seen] = 0
        if depth is not None:
            depth = cv2.remap(depth, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
            depth[~seen] = 0
        if mask is not None:
            mask = cv2.remap(mask.view(np.uint8), mx, my, cv2.INTER_NEAREST,
                             borderMode=cv2.BORDER_CONSTANT).astype(bool) & seen
        elif not seen.all():
            mask = seen
    return Frame(index=s.index, file_path=s.file_path,
                 camera=Camera(s.K, s.c2w, s.width, s.height), rgb=rgb, depth=depth, mask=mask,
                 phase=s.phase, time=s.time, robot_joint_positions=s.robot_joint_positions)


# --- `artgs validate` --------------------------------------------------------------------------

def summarize(capture: Capture) -> dict[str, Any]:
    """Plain-JSON summary of a loaded capture (what ``artgs validate`` prints)."""
    depths = [f.depth[f.depth > 0] for f in capture.frames if f.depth is not None]
    valid = np.concatenate(depths) if depths else np.zeros(0, np.float32)
    return {
        "capture": str(capture.root),
        "frames": len(capture.frames),
        "static_frames": len(capture.static),
        "interaction_frames": len(capture.interaction),
        "image_sizes": [list(wh) for wh in sorted({(f.camera.width, f.camera.height)
                                                   for f in capture.frames})],
        "interaction_times": capture.times,
        "frames_with_depth": len(depths),
        "depth_min_m": float(valid.min()) if valid.size else None,
        "depth_max_m": float(valid.max()) if valid.size else None,
        "frames_with_mask": sum(f.mask is not None for f in capture.frames),
        "undistorted_frames": len(capture.meta.get("undistorted", [])),
        "robot": capture.robot,
    }
