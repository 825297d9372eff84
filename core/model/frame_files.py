"""A frame's files decoded into arrays (RGB, depth, mask), checked against its :class:`FrameSpec`;
undistortion tables and the working resolution. OpenCV is imported lazily (:func:`cv2_module`), so
the numpy-only modules that import this one stay light in Blender's process.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np

from .errors import InputError
from .transforms import FrameSpec

DEPTH_SUFFIXES = (".png", ".npy", ".exr")


def cv2_module():
    """OpenCV, with its EXR codec enabled (it reads the variable at the first EXR it meets)."""
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")
    import cv2

    return cv2


def _decode(path: Path, flags: int) -> np.ndarray | None:
    """cv2 decode from bytes (works for non-ASCII paths on Windows too); None if unreadable."""
    cv2 = cv2_module()
    try:
        data = np.fromfile(path, dtype=np.uint8)
        return cv2.imdecode(data, flags) if data.size else None
    except (OSError, cv2.error):
        return None


def _check_size(img: np.ndarray, s: FrameSpec, path: Path, key: str) -> None:
    h, w = img.shape[:2]
    if (w, h) != (s.width, s.height):
        raise InputError(path, f"is {w}x{h} pixels but the intrinsics say w={s.width}, h={s.height}",
                         frame=s.label, field=key)


def read_rgb(s: FrameSpec) -> np.ndarray:
    cv2 = cv2_module()
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


#: np.load parses a .npy header with ast.literal_eval, which CPython 3.11 (up to 3.11.7 here)
#: can fail in two threads at once ("SystemError: AST constructor recursion depth mismatch",
#: seen once in the suite while a capture's frames loaded in a thread pool): one at a time.
_NPY_HEADER = threading.Lock()


def read_depth(s: FrameSpec, scale: float) -> np.ndarray:
    path, key = s.depth_path, "depth_file_path"
    assert path is not None
    suffix = path.suffix.lower()
    if suffix not in DEPTH_SUFFIXES:
        raise InputError(path, "depth must be a 16-bit .png or a float .npy/.exr", frame=s.label,
                         field=key)
    if suffix == ".npy":
        try:
            with _NPY_HEADER:
                raw = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise InputError(path, f"cannot be read as a .npy array ({exc})", frame=s.label,
                             field=key) from exc
        if not np.issubdtype(raw.dtype, np.floating):
            raise InputError(path, f"depth .npy must be float metres, this one is {raw.dtype}",
                             frame=s.label, field=key)
    else:
        cv2 = cv2_module()
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


def read_mask(s: FrameSpec) -> np.ndarray:
    path = s.mask_path
    assert path is not None
    cv2 = cv2_module()
    img = _decode(path, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(path, "cannot be read as an image", frame=s.label, field="mask_path")
    _check_size(img, s, path, "mask_path")
    return (img[:, :, :3] != 0).any(axis=2) if img.ndim == 3 else img != 0


def undistort_maps(s: FrameSpec, cache: dict) -> tuple[np.ndarray, np.ndarray]:
    """Float remap tables from the pinhole image (same K and size) into the distorted image."""
    key = (s.K.tobytes(), s.distortion.tobytes(), s.width, s.height)
    if key not in cache:
        cv2 = cv2_module()
        K_cv = s.K.copy()
        K_cv[:2, 2] -= 0.5  # OpenCV puts pixel centres at integer coordinates
        cache[key] = cv2.initUndistortRectifyMap(K_cv, s.distortion, None, K_cv,
                                                 (s.width, s.height), cv2.CV_32FC1)
    return cache[key]


def working_size(K: np.ndarray, width: int, height: int, max_side: int
                 ) -> tuple[np.ndarray, int, int]:
    """Intrinsics and size of a ``width`` x ``height`` camera shrunk so its longer side is
    ``max_side``; pixel centres at (j + 0.5, i + 0.5) scale with the image, and so do cx, cy."""
    factor = max_side / max(width, height)
    w, h = max(1, round(width * factor)), max(1, round(height * factor))
    K = K.copy()
    K[0] *= w / width
    K[1] *= h / height
    return K, w, h
