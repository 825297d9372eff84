"""A capture in the scene: one camera per static frame and per fixed interaction camera, with the
capture's intrinsics, and a coloured point-cloud preview of the static frames' depth.

Built from the engine's capture preview file (``core.capture_preview``) with numpy only: the images
are decoded in the engine, never in Blender's process."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from ..core.model.cameras import Camera
from ..core.model.capture_preview import CapturePreview
from .pointcloud import point_cloud_object

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


def camera_rows(preview: CapturePreview) -> list[tuple[str, int]]:
    """(label, frame index) of the cameras to add: every static frame (labelled by its file
    name) and one per distinct fixed camera of the interaction sequence (same K, pose, size)."""
    phase = preview.phase
    rows = [(Path(str(preview.file_path[i])).stem, int(i))
            for i in np.flatnonzero(phase == "static")]
    inter = np.flatnonzero(phase == "interaction")
    if len(inter):
        # distinct rows of (c2w, K, width, height) rounded to 1e-6 (the file's order kept)
        key = np.concatenate([preview.c2w[inter].reshape(len(inter), -1),
                              preview.K[inter].reshape(len(inter), -1),
                              np.stack([preview.width[inter], preview.height[inter]], 1)], axis=1)
        _, first = np.unique(np.round(key, 6), axis=0, return_index=True)
        rows += [(f"interaction camera {k}", int(inter[i])) for k, i in enumerate(np.sort(first))]
    return rows


def build_capture(context: bpy.types.Context, preview: CapturePreview) -> CaptureScene:
    """Add the preview's cameras and coloured points in a new collection named after the capture
    folder; the render resolution follows the first static frame."""
    name = Path(preview.summary.get("capture", "")).name or "capture"
    t0 = time.perf_counter()
    collection = bpy.data.collections.new(name)
    context.scene.collection.children.link(collection)
    cameras = []
    for label, i in camera_rows(preview):
        camera = Camera(preview.K[i], preview.c2w[i], int(preview.width[i]), int(preview.height[i]))
        obj = camera_object(f"{name} {label}", camera, collection)
        obj["artgs_frame"] = str(preview.file_path[i])
        cameras.append(obj)
    static = np.flatnonzero(preview.phase == "static")
    first = int(static[0]) if len(static) else 0
    render = context.scene.render
    render.resolution_x, render.resolution_y = int(preview.width[first]), int(preview.height[first])
    render.resolution_percentage = 100
    render.pixel_aspect_x, render.pixel_aspect_y = pixel_aspect(preview.K[first])
    if cameras:
        context.scene.camera = cameras[0]
    points = None
    if len(preview.points):
        points = point_cloud_object(f"{name} points", preview.points,
                                    preview.colors.astype(np.float32) / 255.0, preview.radius,
                                    collection)
    return CaptureScene(collection, cameras, points, preview.points_total, len(preview.points),
                        time.perf_counter() - t0)
