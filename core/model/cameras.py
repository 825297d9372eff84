"""Pinhole cameras: the capture's OpenGL camera-to-world poses and the OpenCV view the renderer uses.

Conventions (one place for all stages):
- ``c2w`` is the capture's 4x4 camera-to-world matrix with OpenGL/Blender camera axes
  (x right, y up, looking along -z), in metres.
- ``w2c`` is the 4x4 world-to-camera matrix with OpenCV axes (x right, y down, z forward); the
  rasterizer and all projections use it.
- Pixel (row i, column j) has its centre at image coordinates (j + 0.5, i + 0.5), the same
  coordinates as the intrinsics ``cx``, ``cy``.
- Depth is z-depth along the camera's viewing axis in metres; 0 means no measurement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Flips the y and z camera axes: OpenGL camera frame <-> OpenCV camera frame.
GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Camera:
    """A pinhole camera: intrinsics ``K`` (3x3, pixels), pose ``c2w`` (OpenGL axes), image size."""

    K: np.ndarray
    c2w: np.ndarray
    width: int
    height: int

    @property
    def w2c(self) -> np.ndarray:
        """World-to-camera, OpenCV axes (x right, y down, z forward)."""
        return GL_TO_CV @ np.linalg.inv(self.c2w)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates."""
        return self.c2w[:3, 3].copy()

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction in world coordinates."""
        return -self.c2w[:3, 2] / np.linalg.norm(self.c2w[:3, 2])

    def scaled(self, factor: float) -> "Camera":
        """The same camera at ``factor`` times the resolution."""
        S = np.diag([factor, factor, 1.0])
        return Camera(S @ self.K, self.c2w, int(round(self.width * factor)),
                      int(round(self.height * factor)))

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N,3) -> pixel coordinates (N,2) and z-depth (N,)."""
        w2c = self.w2c
        cam = points @ w2c[:3, :3].T + w2c[:3, 3]
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (cam[:, :2] / z[:, None]) * np.array([self.K[0, 0], self.K[1, 1]]) + self.K[:2, 2]
        return uv, z

    def pixel_rays(self) -> np.ndarray:
        """Per-pixel camera-frame (OpenCV) directions with z = 1, shape (H, W, 3)."""
        j, i = np.meshgrid(np.arange(self.width) + 0.5, np.arange(self.height) + 0.5)
        x = (j - self.K[0, 2]) / self.K[0, 0]
        y = (i - self.K[1, 2]) / self.K[1, 1]
        return np.stack([x, y, np.ones_like(x)], axis=-1)

    def backproject(self, depth: np.ndarray, mask: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Depth map (H,W) -> world points (M,3) and their flat pixel indices (M,).

        Pixels with depth <= 0, non-finite depth, or ``mask`` False are skipped.
        """
        valid = np.isfinite(depth) & (depth > 0)
        if mask is not None:
            valid &= mask.astype(bool)
        idx = np.flatnonzero(valid)
        rays = self.pixel_rays().reshape(-1, 3)[idx]
        cam = rays * depth.reshape(-1)[idx, None]
        c2w_cv = np.linalg.inv(self.w2c)
        world = cam @ c2w_cv[:3, :3].T + c2w_cv[:3, 3]
        return world, idx


def intrinsics(fl_x: float, fl_y: float, cx: float, cy: float) -> np.ndarray:
    """3x3 pinhole intrinsics matrix."""
    return np.array([[fl_x, 0.0, cx], [0.0, fl_y, cy], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = np.array([0.0, 0.0, 1.0])
            ) -> np.ndarray:
    """Camera-to-world (OpenGL axes) for a camera at ``eye`` looking at ``target``."""
    eye = np.asarray(eye, float)
    f = np.asarray(target, float) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:
        r = np.cross(f, np.array([0.0, 1.0, 0.0]))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = r, u, -f, eye
    return c2w
