"""A watertight, coloured mesh per part from the splat: depth from many views -> TSDF -> marching cubes.

As 2DGS and GOF extract meshes: each part's Gaussians alone are rendered (the project's
``rasterize()``) from ``views`` directions spread over the sphere around the part; the depths are
fused into a truncated signed distance volume; marching cubes gives the surface.

Unseen space is closed plausibly: a voxel that no view saw in front of a surface (behind every
observed surface, or never in a view) counts as inside (space carving), and the volume is padded
with one empty layer, so the surface is always closed — inside a cabinet, the back of a door, the
underside of a base become flat closing faces. The fraction of the surface made that way is reported
as ``unseen_fraction`` (vertices far from every Gaussian).

Libraries, compared on this job:
- marching cubes: scikit-image's ``marching_cubes`` (Lewiner's topology-consistent variant: a padded
  volume gives a closed, manifold surface; maintained) rather than PyMCubes (classic cases, no
  spacing/origin, no ambiguity resolution) or trimesh's wrapper (itself scikit-image);
- simplification: ``fast-simplification`` (quadric edge collapse, a face budget, ~50 ms for 100 k
  faces) rather than trimesh's ``simplify_quadric_decimation`` (which calls it anyway in trimesh 4+)
  or open3d (a 100 MB dependency for one function). Where decimation pinches thin walls into
  non-manifold edges, marching cubes on a coarser resampling of the TSDF replaces it when that
  keeps the volume; else the budget wins over watertightness (reported per link).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from scipy.spatial import cKDTree

from ...model.cameras import Camera, intrinsics, look_at
from ...model.ply import SplatArrays
from ...render.gaussians import Gaussians
from ...render.rasterize import render
from ...render.sh import sh0_to_rgb


TRUNC_VOXELS = 2.5      # TSDF truncation, in voxels
FREE_ALPHA = 0.05       # a pixel this transparent shows free space; 0.05..0.5 tells nothing


@dataclass
class PartMesh:
    """A closed surface in world coordinates with vertex colours, and how much of it is guessed."""

    mesh: trimesh.Trimesh
    unseen_fraction: float
    voxel: float
    tsdf: np.ndarray
    lo: np.ndarray


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere, (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def splat_colors(splat: SplatArrays) -> np.ndarray:
    """View-independent RGB (N, 3) in 0..1 of each Gaussian (its SH DC term)."""
    return np.clip(sh0_to_rgb(splat.sh[:, 0]), 0.0, 1.0)


def opaque(splat: SplatArrays, min_opacity: float = 0.1) -> np.ndarray:
    """Gaussians opaque enough to form a surface."""
    return 1.0 / (1.0 + np.exp(-splat.opacity_logits)) > min_opacity


def part_mesh(splat: SplatArrays, voxel: float | None = None, views: int = 32,
              resolution: int = 96, max_voxels: int = 64) -> PartMesh:
    """Closed mesh (world frame, vertex colours) of the Gaussians ``splat`` (one part).

    ``voxel``: TSDF voxel size in metres (None: the part's largest extent / ``max_voxels``).
    """
    keep = opaque(splat)
    if keep.sum() < 4:
        raise ValueError("fewer than 4 opaque Gaussians: nothing to mesh")
    pts = splat.means[keep].astype(float)
    lo, hi = np.percentile(pts, 0.5, axis=0), np.percentile(pts, 99.5, axis=0)
    extent = float(np.max(hi - lo))
    voxel = float(voxel) if voxel else max(extent / max_voxels, 1e-3)
    lo, hi = lo - 3 * voxel, hi + 3 * voxel
    depths, cams = _render_depths(splat, lo, hi, views, resolution)
    tsdf = _fuse(depths, cams, lo, hi, voxel, trunc=TRUNC_VOXELS * voxel)
    mesh = _marching_cubes(tsdf, lo, voxel)
    tree = cKDTree(pts)
    dist, _ = tree.query(mesh.vertices)
    unseen = float(np.mean(dist > 2.0 * voxel))
    colour_vertices(mesh, splat)
    return PartMesh(mesh, unseen, voxel, tsdf, lo)


def colour_vertices(mesh: trimesh.Trimesh, splat: SplatArrays, k: int = 4) -> None:
    """Vertex colours from the ``k`` nearest opaque Gaussians (inverse-distance weights)."""
    keep = opaque(splat)
    pts, rgb = splat.means[keep].astype(float), splat_colors(splat)[keep]
    k = min(k, len(pts))
    dist, idx = cKDTree(pts).query(mesh.vertices, k=k)
    dist, idx = dist.reshape(len(mesh.vertices), k), idx.reshape(len(mesh.vertices), k)
    w = 1.0 / np.maximum(dist, 1e-6)
    colour = (rgb[idx] * w[..., None]).sum(1) / w.sum(1, keepdims=True)
    rgba = np.concatenate([colour, np.ones((len(colour), 1))], axis=1)
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=(255 * rgba).round().astype(np.uint8))


def decimate(part: PartMesh, max_faces: int) -> trimesh.Trimesh:
    """The part's surface in about ``max_faces`` faces (world frame), watertight when possible.

    Quadric decimation to the budget (and up to twice it); where it leaves non-manifold edges
    (thin walls pinched together), marching cubes on a coarser resampling of the same TSDF, closed
    by construction, if it keeps at least half the volume; else the decimated surface as it is
    (the export reports each visual mesh's watertightness; mass comes from the full surface).
    """
    import fast_simplification
    from scipy.ndimage import zoom

    mesh = part.mesh
    if len(mesh.faces) <= max_faces:
        return mesh
    first = None
    for budget in (max_faces, int(1.5 * max_faces), 2 * max_faces):
        if budget >= len(mesh.faces):
            break
        v, f = fast_simplification.simplify(np.asarray(mesh.vertices, np.float64),
                                            np.asarray(mesh.faces, np.int64),
                                            1.0 - budget / len(mesh.faces))
        out = trimesh.Trimesh(v, f, process=True)
        first = first if first is not None else out
        if out.is_watertight and out.volume > 0.5 * mesh.volume:
            return out
    factor = np.sqrt(max_faces / len(mesh.faces))
    while factor > 0.1:
        coarse = zoom(part.tsdf, factor, order=1, mode="nearest")
        if min(coarse.shape) < 2:       # no voxels left across a side to hold a surface
            break
        voxel = part.voxel * (np.array(part.tsdf.shape) - 1) / (np.array(coarse.shape) - 1)
        # grow the surface by half the coarser voxel (at most one fine voxel) so thin walls stay
        level = min(1.0 / TRUNC_VOXELS, 0.5 * (float(voxel.max()) - part.voxel) / (TRUNC_VOXELS * part.voxel))
        try:
            out = _marching_cubes(coarse, part.lo, voxel, level)
        except ValueError:
            break
        if out.volume < 0.5 * mesh.volume:
            break
        if len(out.faces) <= max_faces:
            return out
        factor *= 0.8
    return first if first is not None else mesh


def _render_depths(splat: SplatArrays, lo: np.ndarray, hi: np.ndarray, views: int,
                   resolution: int) -> tuple[list[np.ndarray], list[Camera]]:
    """Depth maps (0 = nothing) of the Gaussians from ``views`` cameras around the box lo..hi."""
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2
    fov = np.deg2rad(40.0)
    dist = radius / np.sin(fov / 2) * 1.05
    f = resolution / 2 / np.tan(fov / 2)
    K = intrinsics(f, f, resolution / 2, resolution / 2)
    g = Gaussians.from_arrays(splat)
    depths, cams = [], []
    with torch.no_grad():
        for d in fibonacci_directions(views):
            up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.95 else np.array([0.0, 1.0, 0.0])
            cam = Camera(K, look_at(centre + dist * d, centre, up), resolution, resolution)
            out = render(g, cam, backend="cpu")
            depth = out.depth.numpy().astype(float)
            alpha = out.alpha.numpy()
            depth[alpha < 0.5] = 0.0
            depth[(alpha >= FREE_ALPHA) & (alpha < 0.5)] = -1.0     # partly covered: no evidence
            depths.append(depth)
            cams.append(cam)
    return depths, cams


def _fuse(depths: list[np.ndarray], cams: list[Camera], lo: np.ndarray, hi: np.ndarray,
          voxel: float, trunc: float) -> np.ndarray:
    """TSDF volume (positive outside): mean truncated distance over the views that saw a voxel.

    A view sees a voxel when the voxel projects into it and is not behind the observed depth by
    more than ``trunc``; a nearly transparent pixel (depth 0) means free space along its whole
    ray; a partly covered one (depth -1, gaps between sparse Gaussians) tells nothing, so it does
    not carve through a thin part. Voxels seen
    by no view are inside (-1).
    """
    shape = np.maximum(np.ceil((hi - lo) / voxel).astype(int) + 1, 2)
    axes = [lo[i] + voxel * np.arange(shape[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    total = np.zeros(len(grid))
    weight = np.zeros(len(grid))
    for depth, cam in zip(depths, cams):
        uv, z = cam.project(grid)
        col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
        inside = (z > 0) & (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
        d = np.zeros(len(grid))
        d[inside] = depth[row[inside], col[inside]]
        sdf = np.where(d > 0, d - z, trunc)       # nothing on the ray: free space
        seen = inside & (sdf > -trunc) & (d >= 0)
        total[seen] += np.clip(sdf[seen] / trunc, -1.0, 1.0)
        weight[seen] += 1.0
    tsdf = np.where(weight > 0, total / np.maximum(weight, 1), -1.0)
    return tsdf.reshape(shape)


def _marching_cubes(tsdf: np.ndarray, lo: np.ndarray, voxel, level: float = 0.0
                    ) -> trimesh.Trimesh:
    """Closed surface of ``tsdf < level`` (padded with one outside layer), outward normals."""
    from skimage.measure import marching_cubes

    padded = np.pad(tsdf, 1, constant_values=1.0)
    spacing = np.broadcast_to(np.asarray(voxel, float), (3,))
    verts, faces, _, _ = marching_cubes(padded, level=level, spacing=tuple(spacing))
    verts = verts - spacing + lo
    mesh = trimesh.Trimesh(verts, faces, process=True)
    parts = mesh.split(only_watertight=True)
    if len(parts) == 0:
        raise ValueError("marching cubes gave no closed surface")
    volumes = np.array([abs(p.volume) for p in parts])
    parts = [p for p, v in zip(parts, volumes) if v >= 0.01 * volumes.max()]
    mesh = trimesh.util.concatenate(parts) if len(parts) > 1 else parts[0]
    if mesh.volume < 0:
        mesh.invert()
    return mesh
