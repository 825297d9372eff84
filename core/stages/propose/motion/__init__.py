"""Joints from motion: the static splat and the interaction frames (the default proposal route).

Steps (all in the world frame, metres):

1. Interaction frames are grouped into fixed cameras (same pose and intrinsics). Each camera's
   closed-state depth is its frame at time 0 when it has one, else the static splat rendered
   from it.
2. Depth noise per camera comes from second differences of its depth maps on smooth surfaces; the
   change threshold is a multiple of it (for a rendered closed state, of the render's error).
   When single pixels show no moving part (a far camera's centimetres of noise hide it), depth is
   pooled per camera (median over k x k pixels, k from its noise: ``cameras.pooled_views``) and
   the steps below run again on the pooled depth.
3. A static splat point that the closed-state view sees and that a later step sees *through*
   (measured depth farther than the point by more than the threshold, or no object there) belongs
   to a moving part: rigid scenes cannot reveal what was behind a surface. Such points are grouped
   into parts by 3D connectivity and the step at which they first vanish.
4. Each part is tracked through the steps. Pose hypotheses (previous pose, constant velocity,
   earlier poses, turns about the part's box edges and slides along its normal) are scored by
   projecting the part into the step's depth maps (:func:`projective_score`), the best refined by
   robust point-to-plane ICP against the step's measured points and then by a pattern search on
   the projective score (silhouettes pin what flat faces leave free). The part's model grows with
   the measured points that moved in with it (a door's inner face, a drawer's sides).
5. One revolute and one prismatic joint are fitted to all the part's poses jointly
   (core.geometry.rigid.fit_both); by the motions (``by_motion``) the part is revolute if it
   turns and a slide explains it clearly worse. Both joints are then refined on the
   measurements of all steps at once (core.geometry.rigid.refine_joint) using the splat's own
   part points, and the other type replaces the rule's when it places the part on the depth maps
   clearly better (``type_margin`` of the projective score; far, noisy cameras make tracked poses
   drift so much that the rule calls doors slides); the type not taken is kept as the joint's
   ``alternative``, which the optimisation scores among its type hypotheses. A slide within
   ``front_snap_deg`` of the part front's normal is taken along that normal (a flat front measures
   only that component).
6. Joint values per step are ``states`` (positive = open), the observed range is ``limit``;
   extent (oriented box of the part in the closed state), handle, bbox and confidence follow.

Modules: ``config`` (settings), ``cameras`` (steps 1-2: fixed cameras, closed state, thresholds,
projection), ``change`` (step 3: change detection), ``parts`` (step 3: segmentation),
``track`` (step 4), ``assemble`` (steps 5-6 after the fit), ``route`` (:func:`propose_motion`,
the whole route).
"""
