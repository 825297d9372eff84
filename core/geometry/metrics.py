"""Joint accuracy metrics of shared/spec/metrics.md: axis error, origin error, matching."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..model.joints import Joint

UNMATCHED_AE = 90.0
UNMATCHED_OE = 100.0


def axis_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Sign-invariant angle between two axis directions, degrees: min(θ, 180° − θ)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    theta = math.degrees(math.acos(float(np.clip(abs(a @ b), 0.0, 1.0))))
    return min(theta, 180.0 - theta)


def line_distance(p1: np.ndarray, d1: np.ndarray, p2: np.ndarray, d2: np.ndarray) -> float:
    """Shortest distance between two lines (point, direction); parallel lines: point-to-line."""
    d1 = np.asarray(d1, float) / np.linalg.norm(d1)
    d2 = np.asarray(d2, float) / np.linalg.norm(d2)
    w = np.asarray(p2, float) - np.asarray(p1, float)
    n = np.cross(d1, d2)
    nn = np.linalg.norm(n)
    if nn < 1e-8:
        return float(np.linalg.norm(w - (w @ d1) * d1))
    return float(abs(w @ n) / nn)


@dataclass
class JointScore:
    """Errors of one true joint against its matched prediction (or the unmatched penalties)."""

    true_name: str
    pred_name: str | None
    axis_error_deg: float
    origin_error_cm: float | None   # revolute joints only
    type_correct: bool


def score_pair(pred: Joint, true: Joint) -> JointScore:
    """AE and (revolute) OE of ``pred`` against ``true``."""
    ae = axis_error_deg(pred.axis, true.axis)
    oe = None
    if true.type == "revolute":
        oe = 100.0 * line_distance(pred.origin, pred.axis, true.origin, true.axis)
    return JointScore(true.name, pred.name, ae, oe, pred.type == true.type)


def match_joints(pred: list[Joint], true: list[Joint]) -> list[JointScore]:
    """Match predictions to true joints one-to-one by lowest total AE (deg) + OE (cm).

    Unmatched true joints score AE 90°, OE 100 cm (revolute), type wrong.
    """
    best: list[JointScore] | None = None
    best_cost = math.inf
    slots: list[int | None] = list(range(len(pred))) + [None] * len(true)
    for perm in itertools.permutations(slots, len(true)):
        scores = []
        cost = 0.0
        for t, p in zip(true, perm):
            if p is None:
                s = JointScore(t.name, None, UNMATCHED_AE,
                               UNMATCHED_OE if t.type == "revolute" else None, False)
            else:
                s = score_pair(pred[p], t)
            cost += s.axis_error_deg + (s.origin_error_cm or 0.0)
            scores.append(s)
        if cost < best_cost:
            best, best_cost = scores, cost
    return best or []
