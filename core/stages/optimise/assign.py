"""Part assignment by the frames' depth: each Gaussian to the part whose motion its measurements
support.

The soft skinning learns the assignment by gradients of the render, which reach a Gaussian only
where it is in front and differs from what is behind it; a part started from a wrong box keeps
most of its wrong Gaussians. The depth measurements decide directly. Moved by part ``l``'s
joint at time ``t``, a Gaussian lands at a pixel of each camera at some depth z; the frame
measures D there:
- |z − D| within the loss's depth scale, on the object's pixels, with the Gaussian's colour
  within ``COLOUR`` colour scales of the pixel's: the frame supports ``l`` (for; a floor or
  wall behind, or another surface that happens to lie there, supports nothing);
- z nearer than D by more than that, at the pixel and its 8 neighbours (a Gaussian on the
  object's outline falls on the background half the time), anywhere measured: the frame sees
  through where the Gaussian would be (against); so does a frame whose mask (as wide as it may
  be) leaves out the Gaussian's pixel;
- z > D: something hides it; no evidence.
Counted over the interaction frames, a Gaussian leaves its part only where at least ``MARGIN``
more frames see through it there than through it placed by another part (one frame may be a
flying pixel); of those parts it joins the one with the most support less contradiction. Being
hidden is no evidence, and support alone is not either (a surface that happens to lie where a
wrong part puts a Gaussian supports it): Gaussians the frames do not contradict stay. The
change is kept only when, refitted, it lowers the image loss over all frames
(:func:`reassign`).
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from ...render.sh import sh0_to_rgb
from .changes import colour_of, region_of
from .model import ArticulatedSplat, restore, snapshot
from .seen import project

#: Colour difference (x the loss's colour scale) within which a frame's pixel supports a Gaussian.
COLOUR = 2.0
#: Frames by which a part must be contradicted less than the current one for a Gaussian to move.
MARGIN = 2.0


@torch.no_grad()
def depth_votes(model: ArticulatedSplat, frames, cfg) -> tuple[torch.Tensor, torch.Tensor]:
    """Per Gaussian and part (column 0 the base), the frames that support it there and the frames
    that see through it (module doc): two (N, K+1) counts."""
    means = model.splat.means
    support = torch.zeros(model.splat.n, model.k + 1, device=means.device)
    against = torch.zeros_like(support)
    base = cfg.sigma_depth * 0.01 * model.size
    colour = sh0_to_rgb(model.splat.sh[:, 0]).clamp(0, 1)
    for i, ti in enumerate(frames.time_index):
        if frames.times[ti] == 0:
            continue
        v = frames.levels[0][i]
        tol = max(base, cfg.noise_sigmas * v.depth_noise)
        rgb = colour_of(v)
        outline = region_of(v)
        nearest = -F.max_pool2d(-torch.where(v.depth > 0, v.depth, torch.inf)[None, None], 3, 1,
                                1)[0, 0]
        R, t, _ = model.motions(ti)
        for label in range(model.k + 1):
            p = means if label == 0 else means @ R[label - 1].T + t[label - 1]
            (px, py), z, seen = project(v, p)
            d = v.depth[py, px]
            ok = seen & (d > 0)
            alike = (colour - rgb[py, px]).abs().mean(-1) < COLOUR * cfg.sigma_rgb
            support[:, label] += (ok & v.depth_valid[py, px] & alike
                                  & ((z - d).abs() < tol)).float()
            against[:, label] += ((ok & (z < nearest[py, px] - tol))
                                  | (seen & ~outline[py, px])).float()
    return support, against


def voted_labels(model: ArticulatedSplat, frames, cfg, locked: list[bool]) -> np.ndarray:
    """The hard labels with every Gaussian that the frames contradict where its part puts it
    moved to the part they contradict least (module doc); Gaussians of locked joints' parts,
    and moves to them, are left out."""
    current = torch.as_tensor(model.labels(), device=model.splat.means.device)
    support, against = depth_votes(model, frames, cfg)
    here = against.gather(1, current[:, None])
    allowed = against <= here - MARGIN
    for k, is_locked in enumerate(locked):
        if is_locked:
            allowed[:, k + 1] = False
    score = torch.where(allowed, support - against, torch.full_like(support, -torch.inf))
    best = score.argmax(1)
    fixed = torch.tensor([False] + list(locked), device=current.device)[current]
    return torch.where(allowed.any(1) & ~fixed, best, current).cpu().numpy()


def reassign(run, steps: int, share: float, locked: list[bool]) -> dict[str, list[int]]:
    """Give each Gaussian to the part its depth supports (:func:`voted_labels`) and refit the
    joints for ``steps`` steps; kept when the image loss over all frames is then lower than
    before, else everything (labels and logits too) is restored. Returns per part the Gaussians
    it gained and lost (``{name: [gained, lost]}``), empty when nothing changed or the change
    was not kept. The model must be hardened."""
    model, frames, cfg = run.model, run.frames, run.cfg
    before = model.labels()
    after = voted_labels(model, frames, cfg, locked)
    if (after == before).all():
        run.done += share
        return {}
    loss0 = float(run.evaluate().mean())
    snap, hard, logits = snapshot(model), model.hard.clone(), model.logits.clone()
    model.reassign_all(after)
    run.run_fit(steps, "parts by depth", share, lr_scale=0.1)
    loss1 = float(run.evaluate().mean())
    moved = {name: [int(((after == k + 1) & (before != k + 1)).sum()),
                    int(((before == k + 1) & (after != k + 1)).sum())]
             for k, name in enumerate(model.names)}
    if loss1 >= loss0:
        restore(model, snap)
        model.hard, model.logits = hard, logits
        run.progress.log(f"parts by depth: not kept (image loss {loss0:.5f} -> {loss1:.5f})")
        return {}
    run.progress.log("parts by depth: " + ", ".join(f"{n} +{g}/-{lo}" for n, (g, lo)
                                                    in moved.items())
                     + f" Gaussians (image loss {loss0:.5f} -> {loss1:.5f})")
    return moved
