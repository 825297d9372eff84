"""PyBullet CPU rendering (``ER_TINY_RENDERER``) of a URDF scene through :class:`core.cameras.Camera`.

One :class:`Scene` per object: a ``p.DIRECT`` client with the URDF loaded at the identity base pose.
:meth:`Scene.render` returns RGB, metric z-depth (0 = background) and the object mask from the
segmentation buffer. The projection matrix is built from the camera intrinsics, with the half-pixel
shift that makes PyBullet's pixel grid match the convention of ``core.cameras`` (pixel (i, j) has its
centre at (j + 0.5, i + 0.5)).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pybullet as p

from ..model.cameras import Camera


def view_matrix(camera: Camera) -> list[float]:
    """PyBullet view matrix (OpenGL world-to-camera, column-major) of ``camera``."""
    return [float(v) for v in np.linalg.inv(camera.c2w).T.reshape(-1)]


def projection_matrix(camera: Camera, near: float, far: float) -> list[float]:
    """PyBullet projection matrix (OpenGL, column-major) reproducing the pinhole intrinsics.

    TinyRenderer samples pixels at their corners, not their centres, so the principal point is
    shifted by half a pixel (measured: back-projected depth then lies on the geometry to float
    precision, also for an off-centre principal point).
    """
    K, w, h = camera.K, camera.width, camera.height
    cx, cy = K[0, 2] - 0.5, K[1, 2] + 0.5
    P = np.zeros((4, 4))
    P[0, 0] = 2.0 * K[0, 0] / w
    P[1, 1] = 2.0 * K[1, 1] / h
    P[0, 2] = 1.0 - 2.0 * cx / w
    P[1, 2] = 2.0 * cy / h - 1.0
    P[2, 2] = -(far + near) / (far - near)
    P[2, 3] = -2.0 * far * near / (far - near)
    P[3, 2] = -1.0
    return [float(v) for v in P.T.reshape(-1)]


class Scene:
    """A PyBullet ``DIRECT`` client holding one fixed-base URDF; use as a context manager."""

    def __init__(self, urdf_path: str | Path) -> None:
        self.client = p.connect(p.DIRECT)
        try:
            self.body = p.loadURDF(str(urdf_path), useFixedBase=True, physicsClientId=self.client)
            self.joint_index: dict[str, int] = {}
            for j in range(p.getNumJoints(self.body, physicsClientId=self.client)):
                info = p.getJointInfo(self.body, j, physicsClientId=self.client)
                if info[2] in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC):
                    self.joint_index[info[1].decode()] = j
        except BaseException:
            p.disconnect(self.client)
            raise

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc) -> None:
        p.disconnect(self.client)

    def set_texture(self, image: np.ndarray) -> None:
        """Apply an RGB texture (uint8 HxWx3, multiplies the panel colours) to every link."""
        fd, path = tempfile.mkstemp(suffix=".png")
        os.close(fd)
        try:
            cv2.imwrite(path, image[:, :, ::-1])
            tex = p.loadTexture(path, physicsClientId=self.client)
        finally:
            os.unlink(path)
        for link in range(-1, p.getNumJoints(self.body, physicsClientId=self.client)):
            p.changeVisualShape(self.body, link, textureUniqueId=tex, physicsClientId=self.client)

    def set_states(self, states: dict[str, float]) -> None:
        """Set the named joints to the given values (radians / metres)."""
        for name, value in states.items():
            p.resetJointState(self.body, self.joint_index[name], float(value),
                              physicsClientId=self.client)

    def render(self, camera: Camera, near: float, far: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RGB (H,W,3) uint8, z-depth (H,W) float32 metres of every body (0 = background), mask
        (H,W) bool of the object's body."""
        w, h = camera.width, camera.height
        _, _, rgba, zbuf, seg = p.getCameraImage(
            w, h, viewMatrix=view_matrix(camera),
            projectionMatrix=projection_matrix(camera, near, far),
            renderer=p.ER_TINY_RENDERER, shadow=1, lightDirection=[0.4, -0.3, 1.0],
            lightAmbientCoeff=0.55, lightDiffuseCoeff=0.45, lightSpecularCoeff=0.05,
            physicsClientId=self.client)
        rgb = np.asarray(rgba, np.uint8).reshape(h, w, 4)[:, :, :3].copy()
        zbuf = np.asarray(zbuf, np.float64).reshape(h, w)
        seg = np.asarray(seg).reshape(h, w)
        mask = seg == self.body
        ndc = 2.0 * zbuf - 1.0
        depth = 2.0 * far * near / ((far + near) - ndc * (far - near))
        depth = np.where(seg >= 0, depth, 0.0).astype(np.float32)   # every body (e.g. a robot)
        return rgb, depth, mask


def make_texture(rng: np.random.Generator, size: int = 128) -> np.ndarray | None:
    """A cheap random texture (wood-like grain or speckle, grey levels 0.6..1) or None (plain)."""
    kind = rng.choice(["plain", "grain", "speckle"])
    if kind == "plain":
        return None
    noise = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), 1.5)
    noise = (noise - noise.min()) / max(float(np.ptp(noise)), 1e-6)
    if kind == "grain":
        y = np.arange(size, dtype=np.float32)[:, None]
        freq = rng.uniform(0.15, 0.4)
        phase = 6.0 * cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), 8)
        value = 0.5 + 0.5 * np.sin(freq * y + 4.0 * phase) * (0.6 + 0.4 * noise)
    else:
        value = noise
    grey = 0.6 + 0.4 * np.clip(value, 0.0, 1.0)
    return np.repeat((255 * grey)[:, :, None], 3, axis=2).astype(np.uint8)
