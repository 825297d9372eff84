"""``artgs export OUT``: part meshes, collision geometry, inertials and ``model.urdf`` from the splat.

Reads splat.ply, articulation.json (proposals.json before the optimisation has run) and the part of every Gaussian (``part_labels.npy`` from the
optimisation; without it, the joints' ``extent`` boxes assign them, core/geometry/parts.py). For a
capture without masks the object is first separated from the room (core/geometry/separate.py) and
the per-Gaussian mask is written to ``object_mask.npy``.

Link frames: ``base`` is the world frame; a part's link frame sits at its joint's ``origin`` with
the world's orientation in the closed state (all joints 0, the splat's state), so a joint's URDF
origin is the offset from its parent's frame and its axis is the world axis: forward kinematics
reproduces ``articulation.json`` exactly (checked after writing, core/sim/validate.py).

Writes ``parts/<link>.obj`` (+ ``<link>.mtl``, vertex colours), ``parts/<link>_collision.obj``
(convex pieces), ``model.urdf``; figures per link (faces, volume, mass, unseen fraction) and the
validation go to report.json.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ...geometry.parts import assign_parts
from ...geometry.crop_capture import SEPARATION
from ...geometry.separate import separate_object
from ...model import atomic, layout
from ...model.capture import Capture
from ...model.crop import CropBox, read_crop
from ...model.errors import InputError
from ...model.joints import Joint, read_articulation
from ...model.ply import SplatArrays, read_ply
from ...model.progress import Progress
from ...model.registry import ExportOptions
from ...sim.urdf import Geometry, Inertial, Link, Mesh, UrdfJoint, joint_in_parent, sanitize_name, \
    translation, write_urdf
from .collision import convex_parts, write_mtl, write_obj
from .meshing import PartMesh, colour_vertices, decimate, part_mesh


@dataclass
class LinkMesh:
    """One link's geometry in its link frame."""

    name: str
    frame: np.ndarray                 # link frame -> world, closed state
    visual: trimesh.Trimesh
    solid: trimesh.Trimesh            # watertight, full resolution: mass properties
    hulls: list[trimesh.Trimesh]
    unseen_fraction: float
    closed_by: str                    # "tsdf" or "extent box" (no Gaussians)


def run(out: Path, capture: Capture | None, options: ExportOptions, progress: Progress
        ) -> dict[str, Any]:
    """Export the articulated object of OUT as meshes + URDF; validate it; return figures."""
    splat = read_ply(out / layout.SPLAT)
    joints_path = layout.joints_file(out)
    articulation = read_articulation(joints_path)
    joints = ordered_joints(articulation.joints, joints_path)
    crop = read_crop(out)
    labels, label_source = part_labels(out, splat, joints)
    separation = object_mask(out, splat, joints, capture, options, crop)
    if crop is not None:
        separation = crop_mask(out, splat, crop, separation)
    labels = np.where(separation["mask"], labels, -1)

    frames = link_frames(joints)
    names = ["base"] + [j.child for j in joints]
    meshes = []
    for k, name in enumerate(names):
        progress.check_cancel()
        progress.update("export", k / (len(names) + 1), f"meshing {name}")
        meshes.append(link_mesh(name, frames[name], splat, labels == k,
                                joints[k - 1] if k else None, options))
    parts_dir = out / layout.PARTS_DIR
    links = [write_link(parts_dir, m, options.density) for m in meshes]
    urdf_joints = [urdf_joint(j, frames, options) for j in joints]
    text = write_urdf(sanitize_name(out.name or "object"), links, urdf_joints,
                      extensions=MUJOCO_COMPILER)
    atomic.write_text(out / layout.URDF, text)

    progress.update("export", len(names) / (len(names) + 1), "validating the URDF")
    from ...sim.validate import problems, validate_urdf
    validation = validate_urdf(out / layout.URDF, articulation.joints)
    for line in problems(validation):
        progress.log(f"export: {layout.URDF} is written but fails its validation: {line}",
                     "warning")
    return {
        "joints_file": joints_path.name,
        "links": {m.name: link_figures(m, options.density) for m in meshes},
        "part_labels": label_source,
        "separation": separation["report"],
        "validation": validation,
        "valid": bool(validation["ok"]),
        "unseen_surfaces": "closed by TSDF space carving: space no rendered view saw in front of a "
                           "surface counts as inside, so hidden sides become flat closing faces; "
                           "unseen_fraction per link = share of vertices > 2 voxels from any Gaussian",
    }


#: Most faces of the mesh handed to the convex decomposition (CoACD's time grows with it).
COLLISION_FACES = 2000

#: Lets MuJoCo resolve ``parts/…`` mesh paths relative to the URDF (it strips paths by default).
MUJOCO_COMPILER = '<mujoco><compiler strippath="false" discardvisual="true" balanceinertia="true"/></mujoco>'


def ordered_joints(joints: list[Joint], path: Path) -> list[Joint]:
    """Joints with every parent link before its children; parents must be ``base`` or a child."""
    children = {j.child for j in joints}
    for j in joints:
        if j.parent != "base" and j.parent not in children:
            raise InputError(path, f"parent link {j.parent!r} is neither 'base' nor a joint's child",
                             frame=j.name, field="parent")
    done, order = {"base"}, []
    pending = list(joints)
    while pending:
        ready = [j for j in pending if j.parent in done]
        if not ready:
            raise InputError(path, "joints form a cycle", field="parent")
        for j in ready:
            order.append(j)
            done.add(j.child)
            pending.remove(j)
    return order


def link_frames(joints: list[Joint]) -> dict[str, np.ndarray]:
    """Link frame -> world in the closed state: base = world, a part at its joint's origin."""
    frames = {"base": np.eye(4)}
    for j in joints:
        frames[j.child] = translation(j.origin)
    return frames


def urdf_joint(j: Joint, frames: dict[str, np.ndarray], options: ExportOptions) -> UrdfJoint:
    """The URDF joint reproducing world-frame joint ``j`` between its parent and child frames."""
    origin, axis = joint_in_parent(frames[j.parent], j.axis, j.origin)
    return UrdfJoint(j.name, j.type, j.parent, j.child, origin, axis, j.limit,
                     effort=options.effort, velocity=options.velocity,
                     damping=options.damping, friction=options.friction)


def part_labels(out: Path, splat: SplatArrays, joints: list[Joint]) -> tuple[np.ndarray, str]:
    """Part of every Gaussian (0 base, k = joint k-1 of the file's order) and where it came from."""
    path = out / layout.PART_LABELS
    if path.is_file():
        labels = np.load(path)
        if labels.shape != (len(splat),):
            raise InputError(path, f"has {labels.shape} labels for {len(splat)} Gaussians of "
                             f"{layout.SPLAT}; re-run `artgs optimise`")
        order = read_articulation(layout.joints_file(out)).joints
        remap = np.array([0] + [1 + [j.name for j in joints].index(o.name) for o in order])
        return remap[np.clip(labels, 0, len(order))], layout.PART_LABELS
    return assign_parts(splat.means, joints), "joint extent boxes (no part_labels.npy)"


def object_mask(out: Path, splat: SplatArrays, joints: list[Joint], capture: Capture | None,
                options: ExportOptions, crop: CropBox | None = None) -> dict[str, Any]:
    """Per-Gaussian object mask (written to object_mask.npy) and how it was found. A capture
    whose masks come from reconstruct's separation (crop.json's source) is separated again, now
    with the moving parts as seeds."""
    masked = (capture is None or all(f.mask is not None for f in capture.frames)) and \
        (crop is None or crop.source != SEPARATION)
    if options.separate == "none" or (options.separate == "auto" and masked):
        mask = np.ones(len(splat), bool)
        how = ("none: the capture has masks, the splat holds the object only" if masked
               else "none (--separate none)")
        return {"mask": mask, "report": {"method": how, "object_gaussians": int(mask.sum())}}
    if capture is None:
        raise InputError(out, "separating the object needs the capture's cameras; pass --capture",
                         field="separate")
    c2ws = np.array([f.camera.c2w for f in capture.static])
    inter = np.array([f.camera.c2w for f in capture.interaction]).reshape(-1, 4, 4)
    boxes = [(np.asarray(j.extent["center"], float), np.asarray(j.extent["axes"], float),
              np.asarray(j.extent["half_size"], float)) for j in joints if j.extent]
    sep = separate_object(splat.means, c2ws, inter, boxes)
    atomic.write_bytes(out / layout.OBJECT_MASK, _npy(sep.mask))
    report = {"method": "floor plane by RANSAC (normal near the cameras' up), large walls reaching "
                        "away from where the interaction cameras look, then the voxel-connected "
                        "pieces touching the moving parts / the interaction cameras' focus",
              "mask_file": layout.OBJECT_MASK, "object_gaussians": int(sep.mask.sum()),
              "removed": sep.removed,
              "floor": None if sep.floor is None else {"normal": sep.floor[0].tolist(),
                                                       "offset": sep.floor[1]}}
    return {"mask": sep.mask, "report": report}


def crop_mask(out: Path, splat: SplatArrays, crop: CropBox, separation: dict[str, Any]
              ) -> dict[str, Any]:
    """The separation restricted to the user's crop box (OUT/crop.json); the combined mask is
    written to object_mask.npy."""
    inside = crop.contains(splat.means)
    mask = separation["mask"] & inside
    if not mask.any():
        raise InputError(out / layout.CROP, f"no Gaussian of {layout.SPLAT} lies inside the crop box",
                         field="center")
    atomic.write_bytes(out / layout.OBJECT_MASK, _npy(mask))
    report = dict(separation["report"], crop={**crop.to_dict(), "file": layout.CROP,
                                              "outside": int((~inside).sum())},
                  mask_file=layout.OBJECT_MASK, object_gaussians=int(mask.sum()))
    return {"mask": mask, "report": report}


def link_mesh(name: str, frame: np.ndarray, splat: SplatArrays, members: np.ndarray,
              joint: Joint | None, options: ExportOptions) -> LinkMesh:
    """Closed visual + solid + convex pieces of one link, in its link frame."""
    sub = SplatArrays(*(a[members] for a in (splat.means, splat.quats, splat.log_scales,
                                               splat.opacity_logits, splat.sh)))
    try:
        pm: PartMesh = part_mesh(sub, voxel=options.voxel, views=options.views)
        solid, unseen, how = pm.mesh, pm.unseen_fraction, "tsdf"
        visual = decimate(pm, options.face_budget)
        coarse = decimate(pm, min(options.face_budget, COLLISION_FACES))
        if visual is not solid:
            colour_vertices(visual, sub)
    except ValueError:
        solid, unseen, how = _fallback_box(joint, splat), 1.0, "extent box (no Gaussians)"
        visual = coarse = solid
    inv = np.linalg.inv(frame)
    for mesh in {id(m): m for m in (solid, visual, coarse)}.values():
        mesh.apply_transform(inv)
    hulls = convex_parts(coarse, options.collision_threshold, options.max_hulls)
    return LinkMesh(name, frame, visual, solid, hulls, unseen, how)


def _fallback_box(joint: Joint | None, splat: SplatArrays) -> trimesh.Trimesh:
    """A part without Gaussians: its joint's extent box (else a 2 cm cube at its origin)."""
    if joint is not None and joint.extent:
        T = np.eye(4)
        T[:3, :3] = np.asarray(joint.extent["axes"], float).T
        T[:3, 3] = joint.extent["center"]
        return trimesh.creation.box(2 * np.maximum(np.asarray(joint.extent["half_size"]), 0.005), T)
    centre = joint.origin if joint is not None else np.median(splat.means, 0)
    return trimesh.creation.box([0.02] * 3, translation(centre))


def write_link(parts_dir: Path, m: LinkMesh, density: float) -> Link:
    """Write the link's OBJ/MTL files; its URDF link (paths relative to the URDF)."""
    stem = sanitize_name(m.name)
    colour = _mean_colour(m.visual)
    write_mtl(parts_dir / f"{stem}.mtl", colour)
    write_obj(parts_dir / f"{stem}.obj", [m.visual], mtl=f"{stem}.mtl")
    write_obj(parts_dir / f"{stem}_collision.obj", m.hulls, colours=False)
    rel = f"{layout.PARTS_DIR}/{stem}"
    return Link(m.name,
                visuals=[Geometry(Mesh(f"{rel}.obj"), rgba=(*colour, 1.0))],
                collisions=[Geometry(Mesh(f"{rel}_collision.obj"))],
                inertial=inertial(m.solid, density))


def inertial(solid: trimesh.Trimesh, density: float) -> Inertial:
    """Mass, centre of mass and inertia about it of the closed ``solid`` at ``density`` (kg/m^3)."""
    mesh = solid.copy()
    mesh.density = float(density)
    I = np.asarray(mesh.moment_inertia, float)
    I = (I + I.T) / 2
    w, V = np.linalg.eigh(I)
    I = V @ np.diag(np.maximum(w, 1e-9 * max(w.max(), 1e-12))) @ V.T   # positive definite
    return Inertial(float(mesh.mass), tuple(float(v) for v in mesh.center_mass), I)


def link_figures(m: LinkMesh, density: float) -> dict[str, Any]:
    """Report entry of one link."""
    inert = inertial(m.solid, density)
    return {"faces": int(len(m.visual.faces)), "solid_faces": int(len(m.solid.faces)),
            "watertight": bool(m.visual.is_watertight), "volume_m3": float(m.solid.volume),
            "mass_kg": inert.mass, "com": list(inert.com), "collision_hulls": len(m.hulls),
            "unseen_fraction": round(m.unseen_fraction, 4), "closed_by": m.closed_by}


def _mean_colour(mesh: trimesh.Trimesh) -> tuple[float, float, float]:
    vc = getattr(mesh.visual, "vertex_colors", None)
    if getattr(mesh.visual, "kind", None) != "vertex" or vc is None or len(vc) == 0:
        return (0.7, 0.7, 0.7)
    rgb = np.asarray(vc, float)[:, :3].mean(0) / 255.0
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


def _npy(array: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, array)
    return buf.getvalue()
