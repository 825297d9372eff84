"""Cheap random surface textures for synthetic objects (multiplied with the panel colours)."""

from __future__ import annotations

import cv2
import numpy as np


def make_texture(rng: np.random.Generator, size: int = 128, kind: str | None = None
                 ) -> np.ndarray | None:
    """A cheap random texture (wood-like grain, speckle or floor tiles; grey levels 0.6..1) or None
    (plain). ``kind`` None draws plain, grain or speckle."""
    if kind is None:
        kind = rng.choice(["plain", "grain", "speckle"])
    if kind == "plain":
        return None
    if kind == "tiles":
        n = int(rng.integers(2, 6))
        i, j = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
        cell = ((i * n // size) + (j * n // size)) % 2
        value = np.where(cell, rng.uniform(0.6, 0.9), 1.0) * (0.9 + 0.1 * rng.random((size, size)))
        grout = ((i * n) % size < 2) | ((j * n) % size < 2)
        grey = np.where(grout, 0.55, 0.6 + 0.4 * np.clip(value, 0.0, 1.0))
        return np.repeat((255 * grey)[:, :, None], 3, axis=2).astype(np.uint8)
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
