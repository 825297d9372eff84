"""transforms.json of a capture folder: every key checked, each frame as a :class:`FrameSpec`
(paths, intrinsics, distortion, pose, phase, time, robot joints) before any image is decoded.

What is accepted is documented in core/model/capture.py (the reader's contract); every refusal is an
:class:`~.errors.InputError` naming transforms.json, the frame and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .cameras import intrinsics
from .errors import InputError
from .jsonio import read_json_object
from .robots import robot_model

PHASES = ("static", "interaction")
CAMERA_MODELS = ("PINHOLE", "OPENCV")
INTRINSIC_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3")  # OpenCV's order
UNSUPPORTED_DISTORTION_KEYS = ("k4", "k5", "k6")
DEFAULT_DEPTH_UNIT = 0.001
#: Largest |RᵀR - I| entry accepted for the rotation part of a pose.
ROTATION_TOLERANCE = 1e-3
TRANSFORMS = "transforms.json"


@dataclass
class FrameSpec:
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


def read_transforms(tj: Path) -> dict[str, Any]:
    return read_json_object(tj, "file not found: a capture folder needs a transforms.json")


def is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def is_integral(v: Any) -> bool:
    return is_number(v) and math.isfinite(v) and float(v).is_integer()


def parse_frame(i: int, raw: Any, top: dict, tj: Path, root: Path) -> FrameSpec:
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
        if not is_number(v) or not math.isfinite(v):
            raise InputError(tj, f"must be a finite number, not {v!r}", frame=label, field=key)
        if key in ("fl_x", "fl_y", "w", "h") and v <= 0:
            raise InputError(tj, f"must be positive, not {v!r}", frame=label, field=key)
        if key in ("w", "h") and not is_integral(v):
            raise InputError(tj, f"must be a whole number of pixels, not {v!r}", frame=label, field=key)
        values[key] = float(v)
    K = intrinsics(values["fl_x"], values["fl_y"], values["cx"], values["cy"])

    return FrameSpec(
        index=i, label=label, file_path=file_path,
        rgb_path=root / file_path,
        depth_path=_optional_path(raw, "depth_file_path", tj, label, root),
        mask_path=_optional_path(raw, "mask_path", tj, label, root),
        K=K, distortion=_distortion(lookup, tj, label),
        width=int(values["w"]), height=int(values["h"]),
        c2w=parse_pose(raw.get("transform_matrix"), tj, label),
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
        if not is_number(v) or not math.isfinite(v):
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


def parse_pose(value: Any, tj: Path, label: str | None, f: str = "transform_matrix") -> np.ndarray:
    if value is None:
        raise InputError(tj, "missing the 4x4 camera-to-world matrix", frame=label, field=f)
    if not (isinstance(value, list) and len(value) == 4
            and all(isinstance(r, list) and len(r) == 4 and all(is_number(x) for x in r)
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
    if not is_integral(t):
        raise InputError(tj, f"must be an integer interaction step, not {t!r}", frame=label,
                         field="time")
    if t < 0:
        raise InputError(tj, f"must not be negative, not {t!r}", frame=label, field="time")
    return int(t)


def _joint_positions(raw: dict, tj: Path, label: str) -> list[float] | None:
    q = raw.get("robot_joint_positions")
    if q is None:
        return None
    if not isinstance(q, list) or not all(is_number(x) and math.isfinite(x) for x in q):
        raise InputError(tj, "must be a list of finite numbers (radians/metres)", frame=label,
                         field="robot_joint_positions")
    return [float(x) for x in q]


def check_robot_joints(specs: list[FrameSpec], robot: str | None, tj: Path) -> None:
    """A known robot's joint vectors must have its length (core/model/robots.py)."""
    model = robot_model(robot)
    for s in specs:
        q = s.robot_joint_positions
        if model is not None and q is not None and len(q) not in model.accepted_lengths():
            raise InputError(tj, f"has {len(q)} values, but robot {robot!r} needs "
                             f"{len(model.joints)} ({', '.join(model.joints)}) or "
                             f"{model.arm_joints} (arm joints only)", frame=s.label,
                             field="robot_joint_positions")
