"""Test helper: an output folder holding a splat sampled on a synthetic object's boxes and its
ground-truth joints as ``articulation.json`` (and ``proposals.json``) (no reconstruction, so export/check tests are fast)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from artgs.core.model import layout
from artgs.core.model.joints import Articulation, write_articulation
from artgs.core.model.ply import SplatArrays, write_ply
from artgs.core.render.sh import C0
from artgs.core.synth.generate import ground_truth
from artgs.core.synth.layouts import random_spec
from artgs.core.synth.objects import ObjectSpec


def box_surface(T: np.ndarray, half: np.ndarray, spacing: float, rng) -> np.ndarray:
    """Points on the surface of a posed box, about one per ``spacing``^2."""
    areas = 4 * np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]]).repeat(2)
    n = max(int(areas.sum() / spacing ** 2), 12)
    face = rng.choice(6, n, p=areas / areas.sum())
    local = rng.uniform(-1, 1, (n, 3))
    local[np.arange(n), face // 2] = np.where(face % 2 == 0, -1.0, 1.0)
    local *= half
    return local @ T[:3, :3].T + T[:3, 3]


def splat_of(spec: ObjectSpec, spacing: float = 0.012, seed: int = 0) -> SplatArrays:
    """Small opaque isotropic Gaussians on every box surface of the closed object, box colours."""
    rng = np.random.default_rng(seed)
    colours = [b.rgba[:3] for b in spec.body] + [b.rgba[:3] for q in spec.parts for b in q.boxes]
    pts, rgb = [], []
    for (T, half, _), c in zip(spec.boxes_at(), colours):
        p = box_surface(T, half, spacing, rng)
        pts.append(p)
        rgb.append(np.tile(c, (len(p), 1)))
    pts, rgb = np.concatenate(pts), np.concatenate(rgb)
    n = len(pts)
    sh = ((rgb - 0.5) / C0).astype(np.float32)[:, None, :]
    return SplatArrays(pts.astype(np.float32), np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                       np.full((n, 3), np.log(0.7 * spacing), np.float32),
                       np.full(n, 4.0, np.float32), sh)


def make_out(out: Path, category: str = "cabinet", seed: int = 0) -> tuple[ObjectSpec, Articulation]:
    """Write OUT/splat.ply, OUT/articulation.json and proposals.json (ground truth with extents,
    handles) and OUT/gt.urdf; returns the spec and the articulation."""
    spec = random_spec(category, seed)
    out.mkdir(parents=True, exist_ok=True)
    write_ply(out / layout.SPLAT, splat_of(spec))
    art = ground_truth(spec, [{q.name: 0.0 for q in spec.parts}])
    write_articulation(out / layout.ARTICULATION, art)
    write_articulation(out / layout.PROPOSALS, art)
    (out / "gt.urdf").write_text(spec.to_urdf())
    return spec, art
