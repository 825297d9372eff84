"""``artgs synth``: synthetic articulated objects rendered into capture folders with ground truth.

One capture folder per object (shared/spec/capture-format.md)::

    <category>_<kk>/
      transforms.json          PINHOLE intrinsics at top level; static frames, then interaction frames
      images/static_000.png    RGB of the closed object, views over the front hemisphere
      images/t000_cam0.png     interaction frames: time step, fixed camera 0 (left-front) / 1 (right-front)
      depth/<same stem>.npy    float32 z-depth in metres, 0 = background
      masks/<same stem>.png    8-bit, 255 = object
      gt.urdf                  root link ``world`` + fixed ``base_pose`` joint: loads in the world frame
      gt.json                  articulation.json schema: world-frame joints with ``states`` {time: value},
                               ``extent`` (moving part's oriented box, closed) and ``handle``; top-level
                               ``category`` and ``seed``

Interaction sequence: time 0 = all closed; then each joint in turn opens in ``steps`` equal steps up
to its upper limit and STAYS OPEN; with ``simultaneous`` (objects with >= 2 joints) a last segment
closes the first two joints together in ``steps`` steps. The folder is built beside the target and
renamed into place, so it appears complete or not at all. Same seed -> byte-identical files.
"""

from __future__ import annotations

import io
import math
import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from ..model import atomic
from ..model.cameras import Camera, intrinsics, look_at
from ..model.categories import CATEGORIES
from ..model.errors import InputError
from ..model.joints import Articulation, Joint, write_articulation
from ..model.progress import QUIET, Progress
from .objects import ObjectSpec, random_spec
from ..sim.client import Scene
from .texture import make_texture

#: Focal length as a multiple of the image width.
FOCAL_FACTOR = 1.1
_MAX_PER_CATEGORY = 1000


def generate_object(out: str | Path, category: str, seed: int, *, width: int = 160,
                    height: int = 120, static_views: int = 24, steps: int = 6,
                    depth_noise: float = 0.0, simultaneous: bool = False) -> Path:
    """Generate one object of ``category`` from ``seed`` and write its capture folder ``out``.

    An existing folder is replaced only if it is an earlier synthetic capture (has ``gt.json``).
    """
    out = Path(out)
    _check_options(width, height, static_views, steps, depth_noise)
    _check_category(category)
    _check_seed(seed)
    _check_target(out)
    spec = random_spec(category, seed)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        os.chmod(tmp, 0o755)
        _write_capture(tmp, spec, width, height, static_views, steps, depth_noise, simultaneous)
        _move_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def generate_set(out: str | Path, categories: list[str] | tuple[str, ...] | None,
                 per_category: int, seed: int, progress: Progress = QUIET,
                 **opts: Any) -> list[Path]:
    """Write ``OUT/<category>_<kk>/`` for ``per_category`` objects of each category.

    Object ``kk`` of a set with ``seed`` uses object seed ``1000 * seed + kk``.
    """
    categories = list(categories or CATEGORIES)
    if not 1 <= per_category <= _MAX_PER_CATEGORY:
        raise InputError("command line", f"must be between 1 and {_MAX_PER_CATEGORY}",
                         field="per-category")
    for c in categories:
        _check_category(c)
    _check_seed(seed)
    _check_options(opts.get("width", 160), opts.get("height", 120), opts.get("static_views", 24),
                   opts.get("steps", 6), opts.get("depth_noise", 0.0))
    jobs = [(c, k) for c in categories for k in range(per_category)]
    for c, k in jobs:
        _check_target(Path(out) / f"{c}_{k:02d}")
    progress.start("synth", f"{len(jobs)} objects")
    paths = []
    for n, (c, k) in enumerate(jobs):
        t0 = time.perf_counter()
        path = generate_object(Path(out) / f"{c}_{k:02d}", c, _MAX_PER_CATEGORY * seed + k, **opts)
        paths.append(path)
        progress.update("synth", (n + 1) / len(jobs), path.name,
                        seconds=round(time.perf_counter() - t0, 2))
    progress.finish("synth", objects=len(paths))
    return paths


def synth_command(args, progress: Progress) -> int:
    """The ``artgs synth`` command."""
    paths = generate_set(args.out, args.category, args.per_category, args.seed, progress,
                         width=args.width, height=args.height, static_views=args.static_views,
                         steps=args.steps, depth_noise=args.depth_noise,
                         simultaneous=args.simultaneous)
    progress.finished(captures=[str(p) for p in paths])
    return 0


def interaction_schedule(spec: ObjectSpec, steps: int, simultaneous: bool
                         ) -> list[dict[str, float]]:
    """Joint values per interaction time (index = time); see the module docstring."""
    state = {q.name: 0.0 for q in spec.parts}
    schedule = [dict(state)]
    for q in spec.parts:
        for s in range(1, steps + 1):
            state[q.name] = q.limit[1] * s / steps
            schedule.append(dict(state))
    if simultaneous and len(spec.parts) >= 2:
        a, b = spec.parts[0], spec.parts[1]
        start_a, start_b = state[a.name], state[b.name]
        for s in range(1, steps + 1):
            state[a.name] = start_a * (1 - s / steps)
            state[b.name] = start_b * (1 - s / steps)
            schedule.append(dict(state))
    return schedule


def framing(spec: ObjectSpec, K: np.ndarray, width: int, height: int
            ) -> tuple[np.ndarray, float, float]:
    """Centre and bounding radius of the closed object, and the distance that frames it."""
    lo, hi = spec.bounds()
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    half_fov = min(math.atan(width / 2 / K[0, 0]), math.atan(height / 2 / K[1, 1]))
    return centre, radius, radius / math.sin(half_fov)


def static_cameras(spec: ObjectSpec, K: np.ndarray, width: int, height: int, n: int,
                   rng: np.random.Generator) -> list[Camera]:
    """``n`` views over the front hemisphere, looking at the object's centre, framing it whole."""
    centre, _, dist = framing(spec, K, width, height)
    yaw = math.atan2(spec.base_pose[1, 0], spec.base_pose[0, 0])
    lo_el, hi_el = math.sin(math.radians(5)), math.sin(math.radians(60))
    cams = []
    for k in range(n):
        el = math.asin(lo_el + (hi_el - lo_el) * (k + rng.uniform(0.2, 0.8)) / n)
        az = math.radians(-80 + 160 * ((k * 0.6180339887 + rng.uniform(-0.03, 0.03)) % 1.0))
        cam = _orbit_camera(K, width, height, centre, yaw + az, el, dist)
        cams.append(_fit(cam, spec, centre, rng.uniform(0.6, 0.85)))
    return cams


def _fit(camera: Camera, spec: ObjectSpec, centre: np.ndarray, fill: float) -> Camera:
    """``camera`` moved along its viewing ray so the closed object spans ``fill`` of the image
    (its box corners stay inside the frame)."""
    corners = spec.corners()
    half_wh = np.array([camera.width, camera.height]) / 2
    for _ in range(4):
        uv, _ = camera.project(corners)
        extent = float(np.max(np.abs(uv - camera.K[:2, 2]) / half_wh))
        eye = centre + (camera.center - centre) * extent / fill
        camera = Camera(camera.K, look_at(eye, centre), camera.width, camera.height)
    return camera


def interaction_cameras(spec: ObjectSpec, K: np.ndarray, width: int, height: int,
                        rng: np.random.Generator) -> list[Camera]:
    """Two fixed cameras, left-front and right-front, framing the closed object tightly (opening
    parts may leave the field of view)."""
    centre, _, dist = framing(spec, K, width, height)
    yaw = math.atan2(spec.base_pose[1, 0], spec.base_pose[0, 0])
    cams = []
    for side in (-1.0, 1.0):
        az = side * math.radians(rng.uniform(30, 45))
        el = math.radians(rng.uniform(15, 30))
        cam = _orbit_camera(K, width, height, centre, yaw + az, el, dist)
        cams.append(_fit(cam, spec, centre, rng.uniform(0.7, 0.85)))
    return cams


def _orbit_camera(K: np.ndarray, width: int, height: int, centre: np.ndarray, azimuth: float,
                  elevation: float, dist: float) -> Camera:
    d = np.array([math.cos(elevation) * math.cos(azimuth),
                  math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    return Camera(K, look_at(centre + dist * d, centre), width, height)


def _write_capture(root: Path, spec: ObjectSpec, width: int, height: int, static_views: int,
                   steps: int, depth_noise: float, simultaneous: bool) -> None:
    K = intrinsics(FOCAL_FACTOR * width, FOCAL_FACTOR * width, width / 2, height / 2)
    rng = np.random.default_rng([spec.seed, CATEGORIES.index(spec.category), 1])
    noise_rng = np.random.default_rng([spec.seed, CATEGORIES.index(spec.category), 2])
    statics = static_cameras(spec, K, width, height, static_views, rng)
    fixed = interaction_cameras(spec, K, width, height, rng)
    schedule = interaction_schedule(spec, steps, simultaneous)
    centre, radius, _ = framing(spec, K, width, height)

    urdf = root / "gt.urdf"
    atomic.write_text(urdf, spec.to_urdf())
    shots = [(f"static_{k:03d}", cam, None, {"phase": "static"}) for k, cam in enumerate(statics)]
    shots += [(f"t{t:03d}_cam{c}", cam, states, {"phase": "interaction", "time": t})
              for t, states in enumerate(schedule) for c, cam in enumerate(fixed)]
    texture = make_texture(np.random.default_rng([spec.seed, CATEGORIES.index(spec.category), 3]))
    frames: list[dict[str, Any]] = []
    with Scene() as scene:
        body = scene.load(urdf)
        if texture is not None:
            scene.set_texture(body, texture)
        for stem, camera, states, extra in shots:
            if states is not None:
                scene.set_states(body, states)
            # open parts stay within 3 bounding radii of the centre: the far plane never clips
            far = float(np.linalg.norm(camera.center - centre)) + 4.0 * radius
            frame = scene.render(camera, 0.05, far)
            rgb, mask = frame.rgb, frame.body == body.id
            depth = np.where(mask, frame.depth, 0.0).astype(np.float32)
            if depth_noise > 0:
                noisy = depth + noise_rng.normal(0.0, depth_noise, depth.shape).astype(np.float32)
                depth = np.where(mask, np.maximum(noisy, 1e-3), 0.0).astype(np.float32)
            _write_frame(root, stem, rgb, depth, mask)
            frames.append({"file_path": f"images/{stem}.png",
                           "depth_file_path": f"depth/{stem}.npy",
                           "mask_path": f"masks/{stem}.png",
                           "transform_matrix": [[float(v) for v in row] for row in camera.c2w],
                           **extra})

    atomic.write_json(root / "transforms.json", {
        "camera_model": "PINHOLE", "fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]),
        "cx": float(K[0, 2]), "cy": float(K[1, 2]), "w": width, "h": height, "frames": frames})
    write_articulation(root / "gt.json", _ground_truth(spec, schedule))


def _ground_truth(spec: ObjectSpec, schedule: list[dict[str, float]]) -> Articulation:
    R, t = spec.base_pose[:3, :3], spec.base_pose[:3, 3]
    joints: list[Joint] = []
    for q, joint in zip(spec.parts, spec.joints()):
        joint.states = {time: s[q.name] for time, s in enumerate(schedule)}
        corners = np.array([np.array(b.center) + sgn * np.array(b.half) for b in q.boxes
                            for sgn in (np.array([-1, -1, -1]), np.array([1, 1, 1]))]) + q.origin
        lo, hi = corners.min(0), corners.max(0)
        joint.extent = {"center": [float(v) for v in R @ ((lo + hi) / 2) + t],
                        "axes": [[float(v) for v in row] for row in R.T],
                        "half_size": [float(v) for v in (hi - lo) / 2]}
        handle = q.boxes[-1]
        joint.handle = {"point": [float(v) for v in R @ (np.array(handle.center) + q.origin) + t],
                        "approach": [float(v) + 0.0 for v in -R[:, 0]]}
        joints.append(joint)
    return Articulation(joints, {"category": spec.category, "seed": spec.seed})


def _write_frame(root: Path, stem: str, rgb: np.ndarray, depth: np.ndarray,
                 mask: np.ndarray) -> None:
    """images/<stem>.png, depth/<stem>.npy (float32 metres), masks/<stem>.png (0/255)."""
    _write_png(root / "images" / f"{stem}.png", rgb[:, :, ::-1])
    _write_png(root / "masks" / f"{stem}.png", mask.astype(np.uint8) * 255)
    buf = io.BytesIO()
    np.save(buf, depth)
    atomic.write_bytes(root / "depth" / f"{stem}.npy", buf.getvalue())


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError(f"PNG encoding failed for {path}")
    atomic.write_bytes(path, data.tobytes())


def _check_options(width: int, height: int, static_views: int, steps: int,
                   depth_noise: float) -> None:
    for name, value, low in (("width", width, 16), ("height", height, 16),
                             ("static-views", static_views, 1), ("steps", steps, 1)):
        if int(value) < low:
            raise InputError("command line", f"must be at least {low}, not {value}", field=name)
    if not (math.isfinite(depth_noise) and depth_noise >= 0):
        raise InputError("command line", f"must be a finite number >= 0, not {depth_noise}",
                         field="depth-noise")


def _check_category(category: str) -> None:
    if category not in CATEGORIES:
        raise InputError("command line", f"unknown category {category!r}; expected one of "
                         f"{', '.join(CATEGORIES)}", field="category")


def _check_seed(seed: int) -> None:
    if int(seed) < 0:
        raise InputError("command line", f"must be >= 0, not {seed}", field="seed")


def _check_target(out: Path) -> None:
    """Refuse to replace anything but an earlier synthetic capture folder."""
    if out.exists() and not (out.is_dir() and ((out / "gt.json").is_file() or not any(out.iterdir()))):
        raise InputError(out, "exists and is not a synthetic capture folder (no gt.json); "
                         "refusing to overwrite it")


def _move_into_place(tmp: Path, out: Path) -> None:
    if not out.exists():
        os.rename(tmp, out)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
    os.rename(out, old / out.name)
    os.rename(tmp, out)
    shutil.rmtree(old, ignore_errors=True)
