"""The contact sheet (``artgs contact-sheet``): one labelled picture of what every stage made, from one capture view.

Panels, each present when its inputs are in OUT: a capture frame; the reconstructed splat;
the proposed joints drawn over the splat with each part's Gaussians coloured; the object posed
open by the joints (every part moved to the end of its range); the optimised joints
(``articulation.json``, parts from ``part_labels.npy``) when optimisation has run; and the
manipulation check's frames (``check.png``) when the check has run. The splat is rendered with ``rasterize()``
from the first static camera of the capture; joint axes are projected with the same camera.
OpenCV draws the lines and the labels (it is an engine dependency already).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.parts import assign_parts
from ..model import atomic, layout
from ..model.cameras import Camera
from ..model.capture import load_capture
from ..model.errors import InputError
from ..model.joints import Joint, read_articulation
from ..model.ply import SplatArrays, read_ply
from .sh import rgb_to_sh0

#: Part colours (RGB 0..1): base grey, then one colour per joint.
BASE_COLOUR = (0.62, 0.62, 0.62)
PART_COLOURS = ((0.90, 0.30, 0.25), (0.25, 0.55, 0.95), (0.30, 0.80, 0.35),
                (0.95, 0.70, 0.20), (0.70, 0.35, 0.85), (0.20, 0.80, 0.80))
BACKGROUND = (0.08, 0.08, 0.08)
LABEL_HEIGHT = 18  # pixels of the label strip above each panel


@dataclass(frozen=True)
class Panel:
    """One labelled picture of the sheet: ``image`` (H,W,3) uint8 RGB."""

    name: str      # file stem for the per-stage pictures
    label: str
    image: np.ndarray


def render_splat(splats: SplatArrays, camera: Camera) -> np.ndarray:
    """The splat seen by ``camera`` over the background, (H,W,3) uint8 RGB."""
    import torch

    from .rasterize import rasterize

    t = {k: torch.from_numpy(np.ascontiguousarray(getattr(splats, k), np.float32))
         for k in ("means", "quats", "log_scales", "opacity_logits", "sh")}
    with torch.no_grad():
        out = rasterize(t["means"], t["quats"], t["log_scales"], t["opacity_logits"], t["sh"],
                        camera.K, camera.w2c, camera.width, camera.height,
                        background=torch.tensor(BACKGROUND))
    return (np.clip(out.rgb.numpy(), 0.0, 1.0) * 255 + 0.5).astype(np.uint8)


def coloured_by_part(splats: SplatArrays, labels: np.ndarray) -> SplatArrays:
    """The splat with every Gaussian in its part's flat colour (label 0 = base)."""
    palette = np.array([BASE_COLOUR, *PART_COLOURS], np.float32)
    colours = palette[np.where(labels == 0, 0, (labels - 1) % len(PART_COLOURS) + 1)]
    sh = np.zeros_like(splats.sh)
    sh[:, 0] = rgb_to_sh0(colours)
    return SplatArrays(splats.means, splats.quats, splats.log_scales, splats.opacity_logits, sh)


def posed(splats: SplatArrays, joints: list[Joint], labels: np.ndarray,
          fraction: float = 1.0) -> SplatArrays:
    """Each part moved by its joint to ``fraction`` of the way from the rest value (0, or the
    nearest limit) to the limit farthest from it."""
    means, quats = splats.means.astype(np.float64), splats.quats.astype(np.float64)
    for i, joint in enumerate(joints):
        sel = labels == i + 1
        lo, hi = joint.limit
        rest = min(max(0.0, lo), hi)
        value = rest + fraction * ((hi if abs(hi - rest) >= abs(lo - rest) else lo) - rest)
        if joint.type == "prismatic":
            means[sel] += value * joint.axis
            continue
        R, q = _rotation(joint.axis, value)
        means[sel] = (means[sel] - joint.origin) @ R.T + joint.origin
        quats[sel] = _quat_mul(q, quats[sel])
    return SplatArrays(means.astype(np.float32), quats.astype(np.float32), splats.log_scales,
                       splats.opacity_logits, splats.sh)


def _rotation(axis: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotation matrix and unit quaternion (w x y z) of ``angle`` about unit ``axis``."""
    x, y, z = axis
    K = np.array([[0, -z, y], [z, 0, -x], [-y, x, 0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    return R, np.array([np.cos(angle / 2), *(np.sin(angle / 2) * np.asarray(axis))])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a * b`` for one quaternion ``a`` (4,) and many ``b`` (N,4), w x y z."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2],
                    axis=1)


def draw_joints(image: np.ndarray, joints: list[Joint], camera: Camera, length: float) -> np.ndarray:
    """Each joint's axis as an arrow from its origin (``length`` metres), in its part's colour,
    named at the origin."""
    import cv2

    img = np.ascontiguousarray(image.copy())
    for i, joint in enumerate(joints):
        uv, z = camera.project(np.stack([joint.origin, joint.origin + length * joint.axis]))
        if not np.all(z > 0) or not np.all(np.isfinite(uv)):
            continue
        colour = tuple(int(255 * c) for c in PART_COLOURS[i % len(PART_COLOURS)])
        a, b = (tuple(int(round(v)) for v in p) for p in uv)
        cv2.arrowedLine(img, a, b, (255, 255, 255), 3, cv2.LINE_AA, tipLength=0.25)
        cv2.arrowedLine(img, a, b, colour, 2, cv2.LINE_AA, tipLength=0.25)
        cv2.circle(img, a, 3, colour, -1, cv2.LINE_AA)
        _text(img, joint.name, (a[0] + 4, a[1] - 4), colour)
    return img


def _text(img: np.ndarray, text: str, org: tuple[int, int], colour) -> None:
    import cv2

    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.38, colour, 1, cv2.LINE_AA)


def labelled(panel: Panel) -> np.ndarray:
    """The panel's image under a strip with its label."""
    h, w = panel.image.shape[:2]
    strip = np.full((LABEL_HEIGHT, w, 3), 32, np.uint8)
    _text(strip, panel.label, (4, LABEL_HEIGHT - 5), (235, 235, 235))
    return np.concatenate([strip, panel.image], axis=0)


def sheet(panels: list[Panel], columns: int | None = None, gap: int = 4) -> np.ndarray:
    """The labelled panels on a grid (all panels the same size), ``gap`` pixels apart."""
    tiles = [labelled(p) for p in panels]
    h, w = tiles[0].shape[:2]
    columns = columns or (2 if len(tiles) <= 4 else 3)
    rows = -(-len(tiles) // columns)
    out = np.full((rows * h + (rows + 1) * gap, columns * w + (columns + 1) * gap, 3), 16, np.uint8)
    for k, tile in enumerate(tiles):
        r, c = divmod(k, columns)
        y, x = gap + r * (h + gap), gap + c * (w + gap)
        out[y:y + h, x:x + w] = tile
    return out


def best_view(splats: SplatArrays, labels: np.ndarray, cameras: list[Camera],
              width: int = 48) -> int:
    """Index of the camera that sees most of the moving parts: the part-coloured splat is rendered
    small from each and the coloured (saturated) pixels counted; 0 when nothing moves."""
    if not np.any(labels > 0):
        return 0
    coloured = coloured_by_part(splats, labels)
    counts = []
    for camera in cameras:
        img = render_splat(coloured, camera.scaled(width / camera.width)).astype(int)
        counts.append(int(np.count_nonzero(img.max(axis=2) - img.min(axis=2) > 80)))
    return int(np.argmax(counts))


def panels(out: Path, capture_path: Path, width: int = 240) -> list[Panel]:
    """The sheet's panels for OUT (those whose inputs exist), rendered ``width`` pixels wide from
    the static view that shows the moving parts best."""
    import cv2

    capture = load_capture(capture_path)
    if not capture.static:
        raise InputError(Path(capture_path) / "transforms.json", "no static frame to show",
                         field="frames")
    splat_path, proposals = out / layout.SPLAT, out / layout.PROPOSALS
    splats = read_ply(splat_path) if splat_path.is_file() else None
    joints = {name: read_articulation(out / file).joints
              for name, file in (("joints", layout.PROPOSALS), ("optimised", layout.ARTICULATION))
              if splats is not None and (out / file).is_file()}
    labels = {name: _labels(out, name, splats, js) for name, js in joints.items()}
    view = best_view(splats, labels["joints"], [f.camera for f in capture.static]) \
        if "joints" in labels and proposals.is_file() else 0
    frame = capture.static[view]
    camera = frame.camera.scaled(width / frame.camera.width)
    size = (camera.width, camera.height)
    result = [Panel("capture", "Capture frame",
                    cv2.resize(frame.rgb, size, interpolation=cv2.INTER_AREA))]
    if splats is None:
        return result
    result.append(Panel("splat", f"Splat ({len(splats):,} Gaussians)", render_splat(splats, camera)))
    extent = float(np.ptp(splats.means, axis=0).max()) if len(splats) else 1.0
    for name, title in (("joints", "Joints"), ("optimised", "Optimised joints")):
        if name not in joints:
            continue
        parts = render_splat(coloured_by_part(splats, labels[name]), camera)
        result.append(Panel(name, f"{title} and parts ({len(joints[name])})",
                            draw_joints(parts, joints[name], camera, 0.3 * extent)))
        if name == "joints":
            result.append(Panel("posed", "Posed open",
                                render_splat(posed(splats, joints[name], labels[name]), camera)))
    strip = out / layout.CHECK_STRIP
    if strip.is_file():
        image = cv2.imread(str(strip), cv2.IMREAD_COLOR)
        if image is not None:
            result.append(Panel("check", "Manipulation check (PyBullet)",
                                _fit(cv2.cvtColor(image, cv2.COLOR_BGR2RGB), size)))
    return result


def _labels(out: Path, name: str, splats: SplatArrays, joints: list[Joint]) -> np.ndarray:
    """Part of every Gaussian: the optimisation's own labels (part_labels.npy) for the optimised
    joints, else the joints' extent boxes."""
    path = out / layout.PART_LABELS
    if name == "optimised" and path.is_file():
        labels = np.load(path)
        if labels.shape == (len(splats),):
            return labels.astype(np.int64)
    return assign_parts(splats.means, joints)


def _fit(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``image`` scaled to fit ``size`` (width, height), centred on the background."""
    import cv2

    w, h = size
    scale = min(w / image.shape[1], h / image.shape[0])
    fw, fh = max(1, int(image.shape[1] * scale)), max(1, int(image.shape[0] * scale))
    out = np.full((h, w, 3), int(255 * BACKGROUND[0]), np.uint8)
    y, x = (h - fh) // 2, (w - fw) // 2
    out[y:y + fh, x:x + fw] = cv2.resize(image, (fw, fh), interpolation=cv2.INTER_AREA)
    return out


def write_contact_sheet(out: Path, capture_path: Path, path: Path, width: int = 240,
                        panels_dir: Path | None = None) -> list[Panel]:
    """Write the sheet to ``path`` (PNG, atomically) and, with ``panels_dir``, each labelled
    panel as ``<name>.png`` there."""
    import cv2

    found = panels(Path(out), Path(capture_path), width)
    for target, image in [(path, sheet(found))] + (
            [(Path(panels_dir) / f"{p.name}.png", labelled(p)) for p in found]
            if panels_dir is not None else []):
        ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        if not ok:
            raise OSError(f"could not encode {target}")
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(target, data.tobytes())
    return found
