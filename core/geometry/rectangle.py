"""The smallest-area box of planar points over rotations: a footprint's or a face's sides."""

from __future__ import annotations

import numpy as np


def smallest_rectangle(xy: np.ndarray, percentiles: tuple[float, float] = (1.0, 99.0),
                       limit: int | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """Of the ``percentiles`` boxes of the points ``xy`` (N,2) turned in 1 deg steps (robust
    to a few stray points; an even subsample of at most ``limit`` of them), the one of smallest
    area: its angle (radians, of its first side (cos, sin); the second is (-sin, cos)) and its
    low and high corners (2,) in that frame."""
    if limit is not None:
        xy = xy[:: max(1, len(xy) // limit)]
    t = np.radians(np.arange(0.0, 90.0, 1.0))
    c, s = np.cos(t)[:, None], np.sin(t)[:, None]
    first, second = c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]    # (90, N)
    lo1, hi1 = np.percentile(first, percentiles, axis=1)
    lo2, hi2 = np.percentile(second, percentiles, axis=1)
    best = int(np.argmin((hi1 - lo1) * (hi2 - lo2)))
    return float(t[best]), np.array([lo1[best], lo2[best]]), np.array([hi1[best], hi2[best]])
