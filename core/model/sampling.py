"""Deterministic random subsets (preview caps), the same in the engine and in Blender."""

from __future__ import annotations

import numpy as np


def subsample(count: int, cap: int, seed: int = 0) -> np.ndarray | None:
    """Sorted indices of a deterministic random subset of ``cap`` out of ``count``, or None (all)."""
    if count <= cap:
        return None
    return np.sort(np.random.default_rng(seed).choice(count, size=cap, replace=False))
