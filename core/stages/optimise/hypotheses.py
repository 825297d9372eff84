"""Choosing, adding and dropping joints by evidence (the image loss), beyond the paper.

- Type: for each joint the alternative type is made from the fitted motion of its part
  (revolute -> prismatic: the principal direction of the part's mean displacements; prismatic ->
  revolute: every edge of the part's box as a hinge, each with the per-time angles that best
  reproduce the fitted part positions), the best few are scored by rendering, the winner is
  fitted, and the hypothesis with the lower image loss over the frames where the part moves is kept.
- Spurious parts: a part whose removal (its Gaussians to the base) does not raise the image loss
  over all frames is removed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from .fit import evaluate, search_states
from .kinematics import PRISMATIC, REVOLUTE
from .model import ArticulatedSplat

#: Relative loss increase below which a part's removal is taken (float noise of the evaluation).
REMOVE_TOL = 1e-3


def state_candidates(model: ArticulatedSplat, k: int) -> np.ndarray:
    """Values searched for a joint without states: ±90° in 15° steps, or ±40 % of the object size."""
    if model.types[k] == REVOLUTE:
        return np.radians(np.linspace(-90, 90, 13))
    return np.linspace(-0.4, 0.4, 17) * model.size
