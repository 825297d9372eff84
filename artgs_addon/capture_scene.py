"""A capture in the scene: one camera per static frame and per fixed interaction camera, with the
capture's intrinsics, and a coloured point-cloud preview of the static frames' depth."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..core.capture import Capture, Frame
from ..core.cameras import Camera
from .pointcloud import point_cloud_object, subsample

#: Sensor width of the imported cameras, millimetres (any value works; the focal length follows).
SENSOR_WIDTH = 36.0


@dataclass
class CaptureScene:
    """What ``build_capture`` made, with its key figures."""

    collection: bpy.types.Collection
    cameras: list[bpy.types.Object]
    preview: bpy.types.Object | None
    points_total: int
    points_kept: int
    build_seconds: float


def pixel_aspect(K: np.ndarray) -> tuple[float, float]:
    """Blender's render pixel aspect (x, y) for intrinsics with fl_x != fl_y (both >= 1)."""
    ratio = float(K[0, 0] / K[1, 1])  # = aspect_y / aspect_x
    return (1.0, ratio) if ratio >= 1.0 else (1.0 / ratio, 1.0)


def set_intrinsics(cam: bpy.types.Camera, K: np.ndarray, width: int, height: int) -> None:
    """Set a Blender camera so that, at ``width`` x ``height`` and ``pixel_aspect(K)``, it
    projects like ``K`` (horizontal sensor fit; shift from the principal point)."""
    ax, ay = pixel_aspect(K)
    ycor = ay / ax
    cam.type = "PERSP"
    cam.sensor_fit = "HORIZONTAL"
    cam.sensor_width = SENSOR_WIDTH
    cam.lens = float(K[0, 0]) * SENSOR_WIDTH / width
    cam.shift_x = 0.5 - float(K[0, 2]) / width
    cam.shift_y = ycor * (float(K[1, 2]) - 0.5 * height) / width


def camera_object(name: str, camera: Camera, collection: bpy.types.Collection) -> bpy.types.Object:
    """A camera object with ``camera``'s intrinsics and pose (OpenGL axes = Blender camera axes)."""
    data = bpy.data.cameras.new(name)
    set_intrinsics(data, camera.K, camera.width, camera.height)
    data.clip_end = max(100.0, 10.0 * float(np.linalg.norm(camera.center)))
    obj = bpy.data.objects.new(name, data)
    obj.matrix_world = Matrix(camera.c2w.tolist())
    collection.objects.link(obj)
    return obj


def _interaction_cameras(frames: list[Frame]) -> list[Frame]:
    """One frame per distinct fixed camera of the interaction sequence (same K, pose and size)."""
    seen: list[Frame] = []
    for f in frames:
        c = f.camera
        if not any(np.allclose(c.c2w, s.camera.c2w, atol=1e-6) and np.allclose(c.K, s.camera.K)
                   and (c.width, c.height) == (s.camera.width, s.camera.height) for s in seen):
            seen.append(f)
    return seen


def capture_points(capture: Capture, cap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Static frames' depth back-projected, at most ``cap`` points (a deterministic random subset,
    chosen before back-projecting so memory stays bounded): world points (N,3), sRGB colours (N,3)
    in 0..1, radius (N,) metres (half a pixel's footprint, grown by the square root of the
    thinning), and the number of points available before the cap."""
    frames = [f for f in capture.static if f.depth is not None]
    valid = []
    for f in frames:
        ok = np.isfinite(f.depth) & (f.depth > 0)
        valid.append(np.flatnonzero(ok if f.mask is None else ok & f.mask))
    counts = np.array([len(v) for v in valid], dtype=np.int64)
    total = int(counts.sum())
    keep = subsample(total, cap)
    thinning = 1.0 if keep is None else float(np.sqrt(total / max(len(keep), 1)))
    starts = np.concatenate([[0], np.cumsum(counts)])
    pts, cols, rads = [], [], []
    for k, f in enumerate(frames):
        chosen = valid[k] if keep is None else \
            valid[k][keep[(keep >= starts[k]) & (keep < starts[k + 1])] - starts[k]]
        selected = np.zeros(f.depth.size, bool)
        selected[chosen] = True
        world, idx = f.camera.backproject(f.depth, selected.reshape(f.depth.shape))
        pts.append(world)
        cols.append(f.rgb.reshape(-1, 3)[idx].astype(np.float32) / 255.0)
        rads.append(thinning * 0.5 * f.depth.reshape(-1)[idx] / float(f.camera.K[0, 0]))
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.float32), np.zeros(0, np.float32), 0
    return np.concatenate(pts), np.concatenate(cols), np.concatenate(rads), total


def build_capture(context: bpy.types.Context, capture: Capture, cap: int) -> CaptureScene:
    """Add the capture's cameras and point preview (at most ``cap`` points) in a new collection
    named after the capture folder; the render resolution follows the first static frame."""
    name = Path(capture.root).name or "capture"
    collection = bpy.data.collections.new(name)
    context.scene.collection.children.link(collection)
    named = [(Path(f.file_path).stem, f) for f in capture.static]
    named += [(f"interaction camera {k}", f)
              for k, f in enumerate(_interaction_cameras(capture.interaction))]
    cameras = []
    for label, f in named:
        obj = camera_object(f"{name} {label}", f.camera, collection)
        obj["artgs_frame"] = f.file_path
        cameras.append(obj)
    first = (capture.static or capture.frames)[0].camera
    render = context.scene.render
    render.resolution_x, render.resolution_y = first.width, first.height
    render.resolution_percentage = 100
    render.pixel_aspect_x, render.pixel_aspect_y = pixel_aspect(first.K)
    context.scene.camera = cameras[0]

    t0 = time.perf_counter()
    points, colors, radius, total = capture_points(capture, cap)
    preview = None
    if len(points):
        preview = point_cloud_object(f"{name} points", points, colors, radius, collection)
    seconds = time.perf_counter() - t0
    return CaptureScene(collection, cameras, preview, total, len(points), seconds)
