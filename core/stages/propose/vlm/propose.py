"""Joint proposals from a vision-language model (ArtGS paper, "VLM-based Bones Reasoning").

1. Render a frontal RGB-D view of the static splat (:func:`frontal_camera`).
2. Ask the three questions of ``vlm.prompts`` (classification, bones reasoning, then the
   handle within each part's box) through ``vlm.client``; read them with ``vlm.parse``.
3. Lift each part's image answer to a 3D joint with the rendered depth (``core.geometry.lift``).

A part whose answer cannot be used is skipped with a logged reason; the others are kept.
"""

from __future__ import annotations

import math
import re
from typing import Any

import cv2
import numpy as np
import torch

from ....geometry import lift
from ....geometry.rectangle import smallest_rectangle
from . import prompts
from ....model.cameras import Camera, intrinsics, look_at
from ....model.capture import Capture
from ....render.device import resolve_device
from ....render.gaussians import Gaussians
from ....model.joints import Joint, opening_approach
from ....model.progress import Progress
from ....render.rasterize import render
from .client import VlmConfig, assistant_message, chat, user_message
from .parse import PartAnswer, parse_classification, parse_handle, parse_parts, to_grid1000

STAGE = "propose"
HFOV_DEG = 45.0        # horizontal field of view of the rendered view
FILL = 0.85            # fraction of the image the object's box may span
VIEW_SNAP_DEG = 35.0   # the rendered view's direction snaps to the object's face within this
ELEVATION_DEG = (-45.0, -10.0)  # the view looks down on the object by this much (clipped)
MIN_ALPHA = 0.5        # rendered pixels less opaque than this carry no depth
BACKGROUND = (1.0, 1.0, 1.0)
REVOLUTE_LIMIT = (0.0, math.pi / 2)
PRISMATIC_TRAVEL = 0.75  # proposed drawer travel, times the width of its front
HANDLE_REACH = 0.35    # a handle nearer the hinge than this share of the part halves confidence


def propose_vlm(capture: Capture, gaussians: Gaussians, progress: Progress, config: VlmConfig,
                device: str = "auto") -> tuple[list[Joint], dict[str, Any]]:
    """Joints (source ``vlm``) proposed by the VLM for the static splat ``gaussians``.

    ``meta``: ``view`` (the rendered camera: K, c2w, width, height), ``up`` (the world up it
    assumes, :func:`up_direction`), ``category``, ``parts_said``
    (the number of parts the model named), ``skipped`` (reasons), ``answers`` (the raw answers).
    """
    dev = resolve_device(device)
    g = gaussians.detach().to(dev)
    means = g.means.cpu().numpy().astype(float)
    opaque = torch.sigmoid(g.opacity_logits).cpu().numpy() > 0.3
    up = up_direction(capture)
    camera = frontal_camera(capture, means[opaque] if opaque.sum() >= 8 else means,
                            config.width, config.height, up)
    progress.update(STAGE, 0.05, "rendering the frontal view")
    with torch.no_grad():
        out = render(g, camera, background=torch.tensor(BACKGROUND, device=dev))
    rgb = (out.rgb.clamp(0, 1).cpu().numpy() * 255 + 0.5).astype(np.uint8)
    depth = np.where(out.alpha.cpu().numpy() >= MIN_ALPHA, out.depth.cpu().numpy(), 0.0)
    png = png_bytes(rgb)

    meta: dict[str, Any] = {"view": {"K": camera.K.tolist(), "c2w": camera.c2w.tolist(),
                                     "width": camera.width, "height": camera.height},
                            "up": up.tolist(),
                            "category": None, "parts_said": None, "skipped": [], "answers": {}}
    progress.update(STAGE, 0.15, "asking the VLM: classification")
    messages = [user_message(prompts.CLASSIFY, png)]
    answer = chat(config, messages)
    meta["answers"]["classification"] = answer
    meta["category"], meta["parts_said"] = parse_classification(answer)
    progress.update(STAGE, 0.3, "asking the VLM: bones reasoning")
    messages += [assistant_message(answer), user_message(prompts.BONES)]
    answer = chat(config, messages)
    meta["answers"]["bones"] = answer
    parts = parse_parts(answer, camera.width, camera.height, config.coords)
    usable = [p for p in parts if p.skip is None]
    if meta["parts_said"] is not None and meta["parts_said"] != len(parts):
        progress.log(f"the VLM named {meta['parts_said']} movable parts but described "
                     f"{len(parts)}", "info")

    joints: list[Joint] = []
    meta["answers"]["handles"] = {}
    for k, part in enumerate(parts):
        if part.skip is None:
            progress.update(STAGE, 0.4 + 0.55 * k / max(len(parts), 1),
                            f"asking the VLM: handle of part {part.index}")
            box = to_grid1000(part.bbox, camera.width, camera.height)
            answer = chat(config, [user_message(prompts.handle_prompt(box), png)])
            meta["answers"]["handles"][str(part.index)] = answer
            joint = part_joint(camera, depth, part, answer, config.coords, up, progress,
                               meta["skipped"], taken={j.name for j in joints})
            if joint is not None:
                joints.append(joint)
        else:
            _skip(progress, meta["skipped"], part.skip)
    if not joints:
        progress.log(f"the VLM gave no usable part ({len(usable)} of {len(parts)} answers "
                     "parsed)", "warning")
    progress.update(STAGE, 1.0, f"{len(joints)} joints from the VLM", joints=len(joints))
    return joints, meta


def part_joint(camera: Camera, depth: np.ndarray, part: PartAnswer, handle_answer: str | None,
               coords: str, up: np.ndarray, progress: Progress, skipped: list[str],
               taken: set[str]) -> Joint | None:
    """One parsed part lifted to a joint; None (reason logged and appended) if it cannot be."""
    plane = lift.fit_plane(camera, depth, part.bbox)
    if plane is None:
        return _skip(progress, skipped, f"part {part.index} ({part.label}): no rendered depth "
                     f"inside its box {_r(part.bbox)}")
    center, _, _, size = lift.box_frame(camera, part.bbox, plane)
    trusted = True
    if part.joint_type == "revolute":
        axis, origin, trusted = lift.revolute_axis(camera, depth, part.joint_points, plane)
        axis = lift.snap_axis(axis, plane.normal, up, "revolute")
        axis = lift.opening_sign(axis, origin, center, plane.normal)
        limit = REVOLUTE_LIMIT
    else:
        axis = lift.snap_axis(lift.prismatic_axis(camera, part.bbox, plane), plane.normal, up,
                              "prismatic")
        origin, limit = center, (0.0, float(PRISMATIC_TRAVEL * size[0]))
    handle = None
    if handle_answer is not None:
        hbox, reason = parse_handle(handle_answer, camera.width, camera.height, coords)
        if hbox is not None and not box_within(hbox, part.bbox):
            hbox, reason = None, f"its box {_r(hbox)} is not within the part's box {_r(part.bbox)}"
        if hbox is None:
            progress.log(f"part {part.index} ({part.label}): handle not used: {reason}", "info")
        else:
            handle = lift.handle(camera, depth, hbox, plane)
            approach = opening_approach(part.joint_type, axis, origin, np.array(handle["point"]),
                                        limit[1])
            if approach is not None:     # against the opening, as every route writes it
                handle["approach"] = [float(x) for x in approach]
    base = re.sub(r"\W+", "_", part.label).strip("_") or "part"
    name, n = f"{base}_{part.index}", part.index
    while name in taken:
        n += 1
        name = f"{base}_{n}"
    ext = lift.extent(camera, part.bbox, plane)
    geometry = np.concatenate([axis, origin, np.ravel(ext["axes"]), ext["center"],
                               ext["half_size"]])
    if not np.all(np.isfinite(geometry)):
        return _skip(progress, skipped, f"part {part.index} ({part.label}): degenerate geometry "
                     f"from its box {_r(part.bbox)}")
    confidence = plane.coverage * (1.0 if trusted else 0.6)
    if part.joint_type == "revolute" and handle is not None:
        reach = lift.handle_reach(camera, part.bbox, plane, axis, origin, np.array(handle["point"]))
        if reach < HANDLE_REACH:
            confidence *= 0.5
            progress.log(f"part {part.index} ({part.label}): the handle is beside the hinge line "
                         f"({reach:.0%} of the part's reach); the hinge may be on the other side",
                         "warning")
    extra: dict[str, Any] = {"label": part.label}
    if part.joint_points is not None:
        extra["joint_points"] = part.joint_points.round(2).tolist()
    return Joint(name=name, type=part.joint_type, axis=axis, origin=origin, limit=limit,
                 source="vlm", confidence=round(float(min(max(confidence, 0.0), 1.0)), 3),
                 bbox=[round(float(v), 2) for v in part.bbox], handle=handle, extent=ext,
                 extra=extra)


def up_direction(capture: Capture) -> np.ndarray:
    """World "up" from the capture's cameras, which are held level: the direction perpendicular to
    all their right (x) axes, signed like their up (y) axes. When the right axes do not span a plane
    (all cameras facing one way), a world axis perpendicular to them and within 45 degrees of the
    cameras' mean up axis (z-up and y-up worlds), else that mean up axis."""
    rot = np.array([f.camera.c2w[:3, :3] for f in capture.frames])
    rights, ups = rot[:, :, 0], rot[:, :, 1].sum(axis=0)
    ups = ups / np.linalg.norm(ups)
    s, vt = np.linalg.svd(rights, full_matrices=False)[1:]
    if s[1] > 0.15 * s[0]:
        up = vt[2]
    else:
        level = [a for a in np.eye(3) if abs(a @ vt[0]) < math.sin(math.radians(5))]
        up = max(level, key=lambda a: abs(a @ ups), default=ups)
        up = up if abs(up @ ups) > math.cos(math.radians(45)) else ups
    return -up if up @ ups < 0 else up


def frontal_camera(capture: Capture, points: np.ndarray, width: int, height: int,
                   up: np.ndarray | None = None) -> Camera:
    """A synthetic camera looking at the object's movable side, framing its points.

    Direction: the mean viewing direction of the interaction cameras (they watch the parts move),
    else of the static cameras; snapped to the nearest face of the object's footprint rectangle
    (minimum-area rectangle of the points seen from above, ``up`` from :func:`up_direction`) when
    within :data:`VIEW_SNAP_DEG`, looking down by the cameras' mean elevation clipped to
    :data:`ELEVATION_DEG`.
    """
    up = up_direction(capture) if up is None else up / np.linalg.norm(up)
    side = np.cross(up, [1.0, 0, 0] if abs(up[0]) < 0.9 else [0, 1.0, 0])
    basis = np.stack([side / np.linalg.norm(side), np.cross(up, side / np.linalg.norm(side)), up])
    frames = capture.interaction or capture.static or capture.frames
    m = np.mean([f.camera.forward for f in frames], axis=0)
    if np.linalg.norm(m) < 0.3:  # cameras all around: take the first view's side
        m = frames[0].camera.forward
    m = basis @ (m / np.linalg.norm(m))  # in the up frame from here on
    angle, center, half = footprint(points @ basis.T)
    horiz = np.array([m[0], m[1], 0.0])
    if np.linalg.norm(horiz) > 1e-6:
        horiz /= np.linalg.norm(horiz)
        faces = [np.array([math.cos(a), math.sin(a), 0.0])
                 for a in angle + np.arange(4) * math.pi / 2]
        best = max(faces, key=lambda f: f @ horiz)
        if best @ horiz >= math.cos(math.radians(VIEW_SNAP_DEG)):
            horiz = best
    else:
        horiz = np.array([math.cos(angle), math.sin(angle), 0.0])
    el = math.radians(float(np.clip(math.degrees(math.asin(np.clip(m[2], -1, 1))),
                                    *ELEVATION_DEG)))
    d = math.cos(el) * horiz + np.array([0.0, 0.0, math.sin(el)])
    R = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0],
                  [0, 0, 1.0]])
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    q = (signs * half) @ R.T @ basis  # box corners relative to the centre, world axes
    d, center = d @ basis, center @ basis
    f = width / 2 / math.tan(math.radians(HFOV_DEG) / 2)
    probe = look_at(center - d, center, up)
    r, u = probe[:3, 0], probe[:3, 1]
    sx, sy = FILL * (width / 2) / f, FILL * (height / 2) / f
    dist = max(float(np.max(np.abs(q @ r) / sx - q @ d)), float(np.max(np.abs(q @ u) / sy - q @ d)),
               float(np.max(-(q @ d))) + 0.05)
    return Camera(intrinsics(f, f, width / 2, height / 2), look_at(center - dist * d, center, up),
                  width, height)


def footprint(points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Minimum-area rectangle of the points seen from above (along -z; 1-99 percentiles, 1 degree
    steps): its angle (radians, of its first side), the centre and half sizes of the box it
    bounds."""
    a, lo, hi = smallest_rectangle(points[:, :2])
    c, s = math.cos(a), math.sin(a)
    mid = np.array([[c, -s], [s, c]]) @ ((lo + hi) / 2)
    zlo, zhi = np.percentile(points[:, 2], [1, 99])
    return a, np.array([mid[0], mid[1], (zlo + zhi) / 2]), np.array(
        [(hi - lo)[0] / 2, (hi - lo)[1] / 2, (zhi - zlo) / 2])


def png_bytes(rgb: np.ndarray) -> bytes:
    """An RGB uint8 image (H,W,3) as PNG file bytes."""
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]))
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def _skip(progress: Progress, skipped: list[str], reason: str) -> None:
    """Log why a part's answer is not used and record it in the proposal's ``skipped`` list."""
    progress.log(f"VLM answer skipped: {reason}", "warning")
    skipped.append(reason)


def box_within(inner: np.ndarray, outer: np.ndarray, margin: float = 0.1) -> bool:
    """True if the centre of box ``inner`` lies in box ``outer`` grown by ``margin`` of its size."""
    cx, cy = (inner[0] + inner[2]) / 2, (inner[1] + inner[3]) / 2
    mx, my = margin * (outer[2] - outer[0]), margin * (outer[3] - outer[1])
    return bool(outer[0] - mx <= cx <= outer[2] + mx and outer[1] - my <= cy <= outer[3] + my)


def _r(box: np.ndarray) -> list[float]:
    return [round(float(v), 1) for v in box]
