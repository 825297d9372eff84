"""Physical plausibility of a part's motion: an opening part moves into space, not into the body,
and a hinge holds its part (:func:`off_part`).

The splat holds only what the static (closed) views saw, so a part rotated *into* the object
(a lid swung down inside its chest, a drawer pushed in) can render as well as the true opening: it
disappears where the frames show the object's unseen inside. The static depth maps tell the two
apart without any rendering: a part that opens moves its surface into space the static views saw
empty (they measured something farther away), one that moves into the body goes behind surfaces
they measured (:func:`~artgs.core.geometry.consistency.seen_behind`). The optimisation reports
it per joint and warns when a joint's widest state moves most of its part into the body.
(Refusing such states during the search was tried: it fixed a chest's lid and cost parts the
missed-part search finds, whose first clusters hold more than the part; see the README.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geometry.consistency import depth_views, seen_behind
from ...model.capture import Frame
from ...model.joints import joint_transform

#: motion below which the frames show a part barely moving: its Gaussians' largest displacement
#: under 5 % of the part's size (weak evidence in the report; a part the optimisation invents
#: must move more)
LITTLE_MOVE = 0.05


def little_motion(kind: str, span: float, points: np.ndarray, axis: np.ndarray,
                  origin: np.ndarray) -> bool:
    """Whether a ``kind`` joint's observed range ``span`` (rad / m) is barely any motion for its
    part (``points``, N×3): the part's largest displacement over that range, a slide's ``span``
    or a hinge's ``span`` times its reach (98th percentile of the part's distances from the line
    ``axis`` through ``origin``), under ``LITTLE_MOVE`` of the part's size (:func:`part_size`).
    One scale-free rule for both types, measured on the part: a PartNet dishwasher's rack
    sliding 7.7 cm is 5.3 % of the whole object but a quarter of the rack, and a door hinged at
    its edge is refused below about 3 degrees, not the 10 degrees a fixed angle asked (which
    refused a realistic dishwasher's door found turning 9.97 degrees, as far as it opened)."""
    size = part_size(points)
    if kind != "revolute":
        return span < LITTLE_MOVE * size
    if len(points) < 3:
        return True
    reach = float(np.percentile(line_distances(points, axis, origin), 98))
    return span * reach < LITTLE_MOVE * size


def line_distances(points: np.ndarray, axis: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Distance of each of ``points`` (N×3) from the line ``axis`` (any length) through
    ``origin``."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    d = np.asarray(points, float) - np.asarray(origin, float)
    return np.linalg.norm(d - np.outer(d @ a, a), axis=1)


def box_span(local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column of ``local`` (M,3), the box's low and high sides: the 2 and 98 % percentiles,
    so that a few stray Gaussians do not stretch it."""
    return np.percentile(local, 2, axis=0), np.percentile(local, 98, axis=0)


def part_size(points: np.ndarray) -> float:
    """Diagonal (m) of a part's box (:func:`box_span`) along its principal axes; 0 for under 3
    points."""
    if len(points) < 3:
        return 0.0
    c = np.asarray(points, float) - np.mean(points, 0)
    q = c @ np.linalg.svd(c, full_matrices=False)[2].T
    lo, hi = box_span(q)
    return float(np.linalg.norm(hi - lo))


#: distance from a hinge's line to its part, as a share of the part's size, beyond which the
#: line holds none of it (:func:`off_part`)
HINGE_REACH = 0.2


def off_part(axis: np.ndarray, origin: np.ndarray, points: np.ndarray) -> bool:
    """Whether a hinge's line (``axis``, ``origin``) passes off its part (``points``, N×3): its
    distance to the part (2nd percentile, so a stray Gaussian does not count) is more than
    ``HINGE_REACH`` × the part's size (diagonal of its 2–98 % box along its principal axes). A
    hinge holds its part at an edge: doors, lids and portholes measured 0.01–0.09. A rotation
    about a line farther off sweeps the part along a wide circle, which explains a slide or a
    piece of noise nearly as well as the true motion (a PartNet drawer's front turned 80 deg
    about a line 0.31 of its size away, invented parts of a tight microwave 0.49-0.56)."""
    if len(points) < 3:
        return False
    r = line_distances(points, axis, origin)
    return float(np.percentile(r, 2)) > HINGE_REACH * part_size(points)


#: share of a part's moved surface hidden behind measured surfaces above which a motion is
#: reported as going into the body (more of it goes in than stays out)
HIDDEN_SHARE = 0.5


@dataclass
class OpenSpace:
    """The static views' depth, asked where a moved part lands; ``margin`` (m) is the smallest
    displacement and depth gap that counts (the views' own noise widens it)."""

    views: list[tuple[Frame, np.ndarray, float]]     # :func:`depth_views`
    margin: float

    def hidden_share(self, kind: str, axis: np.ndarray, origin: np.ndarray, value: float,
                     points: np.ndarray) -> float:
        """Of ``points`` (a part's closed surface, N×3) that the joint at ``value`` (rad / m)
        moves by more than the margin, the share that then lie behind a surface some static view
        measured and in space none saw empty; points already hidden when closed do not count.
        0 when nothing moves that far."""
        if not self.views or not len(points) or value == 0:
            return 0.0
        T = joint_transform(kind, axis, origin, value)
        moved = points @ T[:3, :3].T + T[:3, 3]
        far = np.linalg.norm(moved - points, axis=1) > self.margin
        past0, behind0 = seen_behind(points[far], self.views)
        surface = ~((behind0 > 0) & (past0 == 0))
        if not surface.any():
            return 0.0
        past, behind = seen_behind(moved[far][surface], self.views)
        return float(((behind > 0) & (past == 0)).mean())


def open_space(static: list[Frame], size: float) -> OpenSpace | None:
    """The static views with depth as an :class:`OpenSpace` (margin 2 % of the object's
    ``size``); None without any."""
    views = depth_views(static, 0.02 * size)
    return OpenSpace(views, 0.02 * size) if views else None


def into_body(space: OpenSpace | None, kind: str, axis: np.ndarray, origin: np.ndarray,
              values: np.ndarray, points: np.ndarray, limit: int = 300) -> float:
    """Share of a part's surface (``points``, its closed Gaussians; an even subsample of at most
    ``limit``) that the joint's widest state among ``values`` (rad / m) moves behind surfaces the
    static views measured (:meth:`OpenSpace.hidden_share`), when the same state reversed hides
    less of it; 0 otherwise, and without ``space`` or values.

    A part closes into the body and opens into space: the body is where the motion goes and its
    reverse does not. Where both directions hide the part, the views do not tell the body from
    what it opens onto: a PartNet oven's door, hinged at floor level, opens flat onto the floor,
    and its fit, 2.5 cm low, put 0.85 of it behind the floor along the static views' grazing rays
    (its true motion 0.29); turned into the oven, 1.0. Judged alone, the door's every fit went
    "into the body" and the oven was lost (refused as a hinge, then dropped)."""
    if space is None or not len(values):
        return 0.0
    widest = float(values[int(np.argmax(np.abs(values)))])
    pts = points[:: max(1, len(points) // limit)]
    share = space.hidden_share(kind, axis, origin, widest, pts)
    if share > 0 and space.hidden_share(kind, axis, origin, -widest, pts) >= share:
        return 0.0
    return share
