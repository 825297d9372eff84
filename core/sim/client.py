"""A PyBullet ``DIRECT`` client holding a scene of URDF bodies, rendered through
:class:`core.model.cameras.Camera` with the CPU ``ER_TINY_RENDERER``.

:meth:`Scene.render` returns RGB, metric z-depth (0 = nothing) and per-pixel body and link ids from
the segmentation buffer. The projection matrix is built from the camera intrinsics, with the
half-pixel shift that makes PyBullet's pixel grid match the convention of ``core.model.cameras``
(pixel (i, j) has its centre at (j + 0.5, i + 0.5)).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from ..model.cameras import Camera

#: Joint types whose value moves a part.
MOVABLE = (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC)


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


@dataclass
class Frame:
    """One rendered view: RGB (H,W,3) uint8, z-depth (H,W) float32 metres (0 = nothing),
    ``body`` (H,W) int body id (-1 = nothing), ``link`` (H,W) int link index (-1 = base)."""

    rgb: np.ndarray
    depth: np.ndarray
    body: np.ndarray
    link: np.ndarray


@dataclass
class Body:
    """A loaded URDF: PyBullet id, its movable joints by name (name -> joint index) and its links
    by name (name -> link index, -1 = the root link)."""

    id: int
    joints: dict[str, int]
    links: dict[str, int]


class Scene:
    """A PyBullet ``DIRECT`` client; use as a context manager. Bodies are added with :meth:`load`."""

    def __init__(self) -> None:
        self.client = p.connect(p.DIRECT)

    def __enter__(self) -> "Scene":
        return self

    def __exit__(self, *exc) -> None:
        p.disconnect(self.client)

    def load(self, urdf_path: str | Path, *, base_pose: np.ndarray | None = None,
             fixed: bool = True, flags: int = 0, scale: float = 1.0) -> Body:
        """Load a URDF (at ``base_pose``, 4x4, identity by default) and return its :class:`Body`."""
        pos, orn = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]
        if base_pose is not None:
            pos = [float(v) for v in base_pose[:3, 3]]
            orn = list(quaternion_xyzw(base_pose[:3, :3]))
        body = p.loadURDF(str(urdf_path), pos, orn, useFixedBase=fixed, flags=flags,
                          globalScaling=scale, physicsClientId=self.client)
        joints = {}
        links = {p.getBodyInfo(body, physicsClientId=self.client)[0].decode(): -1}
        for j in range(p.getNumJoints(body, physicsClientId=self.client)):
            info = p.getJointInfo(body, j, physicsClientId=self.client)
            links[info[12].decode()] = j
            if info[2] in MOVABLE:
                joints[info[1].decode()] = j
        return Body(body, joints, links)

    def joint_info(self, body: Body, index: int) -> tuple:
        """PyBullet's ``getJointInfo`` tuple."""
        return p.getJointInfo(body.id, index, physicsClientId=self.client)

    def link_frame(self, body: Body, index: int) -> np.ndarray:
        """World pose (4x4) of link ``index``'s URDF frame (= its joint frame)."""
        pos, orn = p.getLinkState(body.id, index, computeForwardKinematics=True,
                                  physicsClientId=self.client)[4:6]
        T = np.eye(4)
        T[:3, :3] = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
        T[:3, 3] = pos
        return T

    def set_texture(self, body: Body, image: np.ndarray, links: list[int] | None = None) -> None:
        """Apply an RGB texture (uint8 HxWx3, multiplies the colours) to ``links`` (default all)."""
        fd, path = tempfile.mkstemp(suffix=".png")
        os.close(fd)
        try:
            cv2.imwrite(path, image[:, :, ::-1])
            tex = p.loadTexture(path, physicsClientId=self.client)
        finally:
            os.unlink(path)
        if links is None:
            links = list(range(-1, p.getNumJoints(body.id, physicsClientId=self.client)))
        for link in links:
            p.changeVisualShape(body.id, link, textureUniqueId=tex, physicsClientId=self.client)

    def set_states(self, body: Body, states: dict[str, float]) -> None:
        """Set the named joints to the given values (radians / metres)."""
        for name, value in states.items():
            p.resetJointState(body.id, body.joints[name], float(value), physicsClientId=self.client)

    def render(self, camera: Camera, near: float, far: float, *,
               light_direction=(0.4, -0.3, 1.0), shadow: bool = True) -> Frame:
        """Render ``camera``'s view of every body."""
        w, h = camera.width, camera.height
        _, _, rgba, zbuf, seg = p.getCameraImage(
            w, h, viewMatrix=view_matrix(camera),
            projectionMatrix=projection_matrix(camera, near, far),
            renderer=p.ER_TINY_RENDERER, shadow=int(shadow),
            lightDirection=[float(v) for v in light_direction],
            lightAmbientCoeff=0.55, lightDiffuseCoeff=0.45, lightSpecularCoeff=0.05,
            flags=p.ER_SEGMENTATION_MASK_OBJECT_AND_LINKINDEX, physicsClientId=self.client)
        rgb = np.asarray(rgba, np.uint8).reshape(h, w, 4)[:, :, :3].copy()
        zbuf = np.asarray(zbuf, np.float64).reshape(h, w)
        seg = np.asarray(seg, np.int64).reshape(h, w)
        hit = seg >= 0
        body = np.where(hit, seg & ((1 << 24) - 1), -1)
        link = np.where(hit, (seg >> 24) - 1, -1)
        ndc = 2.0 * zbuf - 1.0
        depth = 2.0 * far * near / ((far + near) - ndc * (far - near))
        depth = np.where(hit, depth, 0.0).astype(np.float32)
        return Frame(rgb, depth, body, link)


def quaternion_xyzw(R: np.ndarray) -> tuple[float, float, float, float]:
    """Rotation matrix -> PyBullet quaternion (x, y, z, w)."""
    q = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    return float(q[0]), float(q[1]), float(q[2]), float(q[3])
