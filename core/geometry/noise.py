"""Depth noise of a sensor, measured from its own depth maps (numpy only).

Used wherever a threshold or a loss scale must follow the capture's noise instead of a constant:
the motion route's change thresholds and the optimisation's robust depth scale. A far RGB-D
camera (several metres) measures with centimetres of noise, a near one with millimetres.
"""

from __future__ import annotations

import math

import numpy as np


def noise_sigma(depths: list[np.ndarray]) -> float:
    """Depth noise (m, one sigma) from second differences along image rows on smooth surfaces
    (median over the images; a robust spread, so edges do not count). 0 where no image has
    enough measured pixels."""
    sigmas = []
    for d in depths:
        a, b, c = d[:, :-2], d[:, 1:-1], d[:, 2:]
        ok = (a > 0) & (b > 0) & (c > 0)
        if ok.sum() > 20:
            sigmas.append(1.4826 * float(np.median(np.abs(a + c - 2 * b)[ok])) / math.sqrt(6.0))
    return float(np.median(sigmas)) if sigmas else 0.0
