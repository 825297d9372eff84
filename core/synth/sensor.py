"""Imperfections of real sensors applied to exact renderings: RGB-D depth noise, quantisation,
missing depth, flying pixels, exposure changes, and imperfect segmentation masks.

All functions are vectorised numpy/cv2 on one frame and draw from the ``rng`` they are given, so a
capture is deterministic for its seed. See core.synth.regime for the ranges the presets use.
"""

from __future__ import annotations

import cv2
import numpy as np

from ..model.cameras import Camera

#: A depth jump larger than max(EDGE_ABS, EDGE_REL * z) between neighbours is a depth edge.
EDGE_ABS, EDGE_REL = 0.02, 0.03
#: Probabilities: edge pixel missing, dark pixel missing, grazing pixel missing, silhouette flying.
P_EDGE, P_DARK, P_GRAZING, P_FLYING = 0.6, 0.8, 0.7, 0.15
DARK_LUMINANCE, GRAZING_DEG = 0.1, 78.0
RGB_NOISE = 1.5


def depth_sigma(z: np.ndarray, a: float, b: float) -> np.ndarray:
    """Noise standard deviation (metres) at depth ``z``: ``a z + b z^2``."""
    return a * z + b * z * z


def noisy_depth(depth: np.ndarray, a: float, b: float, quantum: float,
                rng: np.random.Generator) -> np.ndarray:
    """Depth with Gaussian noise of :func:`depth_sigma` and quantised to ``quantum`` (0 stays 0)."""
    valid = depth > 0
    z = depth.astype(np.float64)
    if a > 0 or b > 0:
        z = z + rng.standard_normal(z.shape) * depth_sigma(z, a, b)
    if quantum > 0:
        z = np.round(z / quantum) * quantum
    return np.where(valid, np.maximum(z, quantum or 1e-3), 0.0).astype(np.float32)


def depth_edges(depth: np.ndarray) -> np.ndarray:
    """Pixels (bool) next to a depth discontinuity, including the border of valid depth."""
    z = depth.astype(np.float64)
    pad = np.pad(z, 1, mode="edge")
    edge = np.zeros(z.shape, bool)
    for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
        nb = pad[dy:dy + z.shape[0], dx:dx + z.shape[1]]
        jump = np.abs(nb - z) > np.maximum(EDGE_ABS, EDGE_REL * np.maximum(z, nb))
        edge |= jump
    return edge & (z > 0)


def grazing(depth: np.ndarray, camera: Camera, max_deg: float = GRAZING_DEG) -> np.ndarray:
    """Pixels whose surface (normal from depth gradients) is seen at more than ``max_deg``."""
    pts = camera.pixel_rays() * depth[:, :, None].astype(np.float64)
    gx = np.gradient(pts, axis=1)
    gy = np.gradient(pts, axis=0)
    n = np.cross(gx, gy)
    norm = np.linalg.norm(n, axis=2)
    rays = camera.pixel_rays()
    cos = np.abs(np.sum(n * rays, axis=2)) / np.maximum(norm * np.linalg.norm(rays, axis=2), 1e-12)
    return (depth > 0) & (norm > 0) & (cos < np.cos(np.radians(max_deg))) & ~depth_edges(depth)


def dropout(depth: np.ndarray, rgb: np.ndarray, camera: Camera, rng: np.random.Generator
            ) -> np.ndarray:
    """Missing depth (0) on depth edges (1 px band), dark and grazing surfaces."""
    edge = depth_edges(depth)
    band = cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & (depth > 0)
    lum = rgb.astype(np.float32).mean(axis=2) / 255.0
    drop = (band & (rng.random(depth.shape) < P_EDGE))
    drop |= (lum < DARK_LUMINANCE) & (rng.random(depth.shape) < P_DARK)
    drop |= grazing(depth, camera) & (rng.random(depth.shape) < P_GRAZING)
    return np.where(drop, 0.0, depth).astype(np.float32)


def flying_pixels(depth: np.ndarray, silhouette: np.ndarray, rng: np.random.Generator,
                  p: float = P_FLYING) -> np.ndarray:
    """Pixels just outside ``silhouette`` (the object) get a depth between the object and what is
    behind it (or up to 30 % farther when nothing is), as time-of-flight and stereo sensors do."""
    ring = cv2.dilate(silhouette.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    ring &= ~silhouette
    fg = cv2.dilate(np.where(silhouette, -depth, -np.inf).astype(np.float32),
                    np.ones((3, 3), np.uint8))          # nearest object depth around each pixel
    fg = np.where(np.isfinite(fg), -fg, 0.0)
    pick = ring & (fg > 0) & (rng.random(depth.shape) < p)
    u = rng.uniform(0.2, 0.8, depth.shape)
    behind = np.where(depth > 0, depth, fg * rng.uniform(1.05, 1.3, depth.shape))
    return np.where(pick, fg + u * (behind - fg), depth).astype(np.float32)


def exposure(rgb: np.ndarray, gain: float, rng: np.random.Generator) -> np.ndarray:
    """RGB scaled by ``gain`` with Gaussian sensor noise, clipped to uint8."""
    out = rgb.astype(np.float32) * gain + rng.normal(0.0, RGB_NOISE, rgb.shape)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


def jitter_mask(mask: np.ndarray, max_px: int, rng: np.random.Generator) -> np.ndarray:
    """The mask eroded or dilated by 1..``max_px`` pixels (a segmentation model's boundary)."""
    if max_px <= 0:
        return mask
    k = int(rng.integers(1, max_px + 1))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))
    op = cv2.erode if rng.random() < 0.5 else cv2.dilate
    return op(mask.astype(np.uint8), kernel).astype(bool)
