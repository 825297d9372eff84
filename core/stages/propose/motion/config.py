"""Settings of the motion route, and the time at which every part is closed."""

from __future__ import annotations

from dataclasses import dataclass


#: The interaction time at which every part is closed (a camera's frame at this time, if it has
#: one, is its closed state; other cameras render the static splat instead).
CLOSED_TIME = 0


@dataclass
class MotionConfig:
    """Tuning of the motion route (defaults suit 2 mm-class depth noise)."""

    noise_sigmas: float = 5.0         # change threshold = this many noise sigmas (of a difference)
    min_threshold: float = 0.006      # ... but at least this (m)
    pool: int = 0                     # depth = median of pool x pool pixels (odd, 1 = none); 0:
                                      # none, then per camera (cameras.pool_size) if no part
    max_pool: int = 7                 # ... at most this window
    render_sigmas: float = 3.0        # closed state rendered from the splat: this many sigmas of
    render_threshold: float = 0.03    # its error, or this (m) when that cannot be measured
    min_opacity: float = 0.5          # splat points used as closed-state geometry
    link_pixels: float = 3.0          # 3D connectivity radius, in static-point spacings
    min_part_points: int = 40         # smaller groups of vanished points are noise
    min_part_fraction: float = 0.01   # ... or smaller than this share of the splat points
    track_points: int = 1200          # part points used for tracking
    min_angle_deg: float = 8.0        # revolute when the part turns at least this much ...
    min_rms_ratio: float = 3.0        # ... and a slide fits that much worse (rigid.by_motion)
    icp_iterations: int = 30
    icp_candidates: int = 5           # best-scoring pose hypotheses refined by ICP per step
    jump_penalty: float = 0.5         # score cost of a pose far from the constant-velocity guess
    grow_score: float = 0.3           # steps tracked at least this well add points to the part
    grow_depth: float = 0.1           # ... from at most this far behind its closed front (m)
    type_margin: float = 0.05         # the other type wins when it places the part this much better
    refine_rounds: int = 10           # rounds of joint refinement on the measurements ...
    refine_point_weight: float = 0.2  # ... with this weight of point-to-point residuals
    front_snap_deg: float = 25.0      # a slide this close to the front's normal is taken along it
