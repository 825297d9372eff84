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

The subject is a procedural object (core.synth.objects, ``category`` + ``seed``) or an articulated
URDF asset (core.synth.asset, ``--urdf``); both go through the same cameras, renderer, sensor model
and writer. How they are drawn is the regime (core.model.regime: ``tight`` or ``realistic``).

Interaction sequence ``sequential``: time 0 = all closed; then each joint in turn opens in ``steps``
equal steps up to its upper limit and STAYS OPEN; with ``simultaneous`` (objects with >= 2 joints)
a last segment closes the first two joints together in ``steps`` steps. ``mixed``: each joint in
turn opens fully (p = 0.5), partially (30-80 %, p = 0.25) or only a little (10 deg / 3 cm,
p = 0.25), then every joint moves at once to a new value (the open ones close by 50-100 %, the
others open fully); a single joint closes half-way instead. The folder is built beside the target
and renamed into place, so it appears complete or not at all. Same seed -> byte-identical files.
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
from ..model.categories import CATEGORIES, KINDS
from ..model.errors import InputError
from ..model.joints import Articulation, Joint, write_articulation
from ..model.progress import QUIET, Progress
from ..model.regime import Regime, regime as make_regime
from ..sim.client import Scene
from . import sensor
from .asset import AssetSpec, load_asset
from .layouts import random_spec
from .objects import ObjectSpec
from .robot import RobotInScene, check_robot, plan_robot, robot_keys
from .room import room_urdf
from .texture import make_texture

Subject = ObjectSpec | AssetSpec

#: Focal length as a multiple of the image width.
FOCAL_FACTOR = 1.1
_MAX_PER_CATEGORY = 1000


def generate_object(out: str | Path, category: str, seed: int, *, width: int = 160,
                    height: int = 120, static_views: int = 24, steps: int = 6,
                    depth_noise: float = 0.0, simultaneous: bool = False,
                    regime: Regime | None = None, robot: str | None = None) -> Path:
    """Generate one object of ``category`` from ``seed`` and write its capture folder ``out``.

    An existing folder is replaced only if it is an earlier synthetic capture (has ``gt.json``).
    """
    regime = regime or make_regime("tight")
    _check_options(width, height, static_views, steps, depth_noise)
    _check_category(category, regime)
    _check_seed(seed)
    _check_target(Path(out))
    check_robot(robot)
    spec = random_spec(category, seed, variety=regime.variety)
    return _generate(Path(out), spec, width, height, static_views, steps, depth_noise,
                     simultaneous, regime, robot)


def generate_asset(out: str | Path, urdf_path: str | Path, seed: int, *, kind: str | None = None,
                   joints: list[str] | None = None, size: float | None = None,
                   width: int = 160, height: int = 120, static_views: int = 24, steps: int = 6,
                   depth_noise: float = 0.0, simultaneous: bool = False,
                   regime: Regime | None = None, robot: str | None = None) -> Path:
    """Render an articulated URDF asset (core.synth.asset) into the capture folder ``out``."""
    regime = regime or make_regime("tight")
    _check_options(width, height, static_views, steps, depth_noise)
    _check_seed(seed)
    _check_target(Path(out))
    if robot is not None:
        raise InputError("command line", "--robot works with procedural objects only, not yet "
                         "with --urdf assets", field="robot")
    spec = load_asset(urdf_path, seed, kind=kind, joints=joints, size=size)
    return _generate(Path(out), spec, width, height, static_views, steps, depth_noise,
                     simultaneous, regime)


def _generate(out: Path, subject: Subject, *args) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        os.chmod(tmp, 0o755)
        _write_capture(tmp, subject, *args)
        _move_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def generate_set(out: str | Path, categories: list[str] | tuple[str, ...] | None,
                 per_category: int, seed: int, progress: Progress = QUIET,
                 **opts: Any) -> list[Path]:
    """Write ``OUT/<category>_<kk>/`` for ``per_category`` objects of each category (default:
    the seven categories, plus the extra kinds when the regime has ``variety``).

    Object ``kk`` of a set with ``seed`` uses object seed ``1000 * seed + kk``.
    """
    reg = opts.get("regime") or make_regime("tight")
    categories = list(categories or (KINDS if reg.variety else CATEGORIES))
    if not 1 <= per_category <= _MAX_PER_CATEGORY:
        raise InputError("command line", f"must be between 1 and {_MAX_PER_CATEGORY}",
                         field="per-category")
    for c in categories:
        _check_category(c, reg)
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


def asset_folder_name(urdf_path: str | Path, kind: str | None = None) -> str:
    """``<kind>_<asset id>`` for ``<...>/<kind>/<id>/mobility.urdf``."""
    p = Path(urdf_path)
    return f"{kind or p.parent.parent.name}_{p.parent.name}"


def generate_assets(out: str | Path, urdfs: list[Path], seed: int, progress: Progress = QUIET,
                    **opts: Any) -> list[Path]:
    """Render each URDF asset into ``OUT/<kind>_<id>/`` (asset seed ``seed``)."""
    _check_seed(seed)
    names = [asset_folder_name(u, opts.get("kind")) for u in urdfs]
    if len(set(names)) != len(names):
        raise InputError("command line", f"two assets would share a folder name in {names}",
                         field="urdf")
    for name in names:
        _check_target(Path(out) / name)
    progress.start("synth", f"{len(urdfs)} assets")
    paths = []
    for n, (u, name) in enumerate(zip(urdfs, names)):
        t0 = time.perf_counter()
        paths.append(generate_asset(Path(out) / name, u, seed, **opts))
        progress.update("synth", (n + 1) / len(urdfs), name,
                        seconds=round(time.perf_counter() - t0, 2))
    progress.finish("synth", objects=len(paths))
    return paths


def interaction_schedule(joints: list[Joint], steps: int, simultaneous: bool,
                         sequence: str = "sequential", rng: np.random.Generator | None = None
                         ) -> list[dict[str, float]]:
    """Joint values per interaction time (index = time); see the module docstring."""
    state = {j.name: 0.0 for j in joints}
    schedule = [dict(state)]

    def move(targets: dict[str, float]) -> None:
        start = dict(state)
        for s in range(1, steps + 1):
            for name, goal in targets.items():
                state[name] = start[name] + (goal - start[name]) * s / steps
            schedule.append(dict(state))

    if sequence == "sequential":
        for j in joints:
            move({j.name: j.limit[1]})
        if simultaneous and len(joints) >= 2:
            move({joints[0].name: 0.0, joints[1].name: 0.0})
        return schedule
    rng = rng or np.random.default_rng(0)
    for j in joints:
        hi = j.limit[1]
        u = rng.random()
        small = math.radians(10) if j.type == "revolute" else 0.03
        goal = hi if u < 0.5 else hi * rng.uniform(0.3, 0.8) if u < 0.75 else min(small, hi)
        move({j.name: goal})
    if len(joints) >= 2:
        move({j.name: (state[j.name] * (1 - rng.uniform(0.5, 1.0))
                       if state[j.name] > 0.5 * j.limit[1] else j.limit[1]) for j in joints})
    elif joints:
        move({joints[0].name: state[joints[0].name] / 2})
    return schedule


def framing(spec: Subject, K: np.ndarray, width: int, height: int
            ) -> tuple[np.ndarray, float, float]:
    """Centre and bounding radius of the closed object, and the distance that frames it."""
    lo, hi = spec.bounds()
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo) / 2)
    half_fov = min(math.atan(width / 2 / K[0, 0]), math.atan(height / 2 / K[1, 1]))
    return centre, radius, radius / math.sin(half_fov)


def _yaw(spec: Subject) -> float:
    return math.atan2(spec.base_pose[1, 0], spec.base_pose[0, 0])


def static_cameras(spec: Subject, K: np.ndarray, width: int, height: int, n: int,
                   rng: np.random.Generator, distance: tuple[float, float] | None = None
                   ) -> list[Camera]:
    """``n`` views over the front hemisphere, looking at the object's centre: framing it whole
    (``distance`` None) or at ``distance`` x the framing distance with a jittered look-at point."""
    centre, radius, dist = framing(spec, K, width, height)
    yaw = _yaw(spec)
    lo_el, hi_el = math.sin(math.radians(5)), math.sin(math.radians(60))
    cams = []
    for k in range(n):
        el = math.asin(lo_el + (hi_el - lo_el) * (k + rng.uniform(0.2, 0.8)) / n)
        az = math.radians(-80 + 160 * ((k * 0.6180339887 + rng.uniform(-0.03, 0.03)) % 1.0))
        if distance is None:
            cam = _orbit_camera(K, width, height, centre, yaw + az, el, dist)
            cams.append(_fit(cam, spec, centre, rng.uniform(0.6, 0.85)))
        else:
            cams.append(_orbit_camera(K, width, height, centre, yaw + az, el,
                                      dist * rng.uniform(*distance), _jitter(rng, radius)))
    return cams


def _jitter(rng: np.random.Generator, radius: float) -> np.ndarray:
    """A look-at offset uniform in a ball of 0.15 bounding radii."""
    d = rng.normal(size=3)
    return d / np.linalg.norm(d) * 0.15 * radius * rng.random() ** (1 / 3)


def _fit(camera: Camera, spec: Subject, centre: np.ndarray, fill: float) -> Camera:
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


def interaction_cameras(spec: Subject, K: np.ndarray, width: int, height: int,
                        rng: np.random.Generator, distance: tuple[float, float] | None = None,
                        azimuth: float = 0.0) -> list[Camera]:
    """Two fixed cameras. ``distance`` None: left-front and right-front (30-45 deg), framing the
    closed object tightly (opening parts may leave the field of view). Otherwise at ``distance`` x
    the framing distance, azimuths anywhere within +-``azimuth`` deg of the front (one on each
    side of a random split), elevation 5-45 deg, jittered look-at point."""
    centre, radius, dist = framing(spec, K, width, height)
    yaw = _yaw(spec)
    cams = []
    if distance is None:
        for side in (-1.0, 1.0):
            az = side * math.radians(rng.uniform(30, 45))
            el = math.radians(rng.uniform(15, 30))
            cam = _orbit_camera(K, width, height, centre, yaw + az, el, dist)
            cams.append(_fit(cam, spec, centre, rng.uniform(0.7, 0.85)))
        return cams
    split = rng.uniform(-0.5, 0.5) * azimuth
    for lo, hi in ((-azimuth, split), (split, azimuth)):
        az = math.radians(rng.uniform(lo, hi))
        el = math.radians(rng.uniform(5, 45))
        cams.append(_orbit_camera(K, width, height, centre, yaw + az, el,
                                  dist * rng.uniform(*distance), _jitter(rng, radius)))
    return cams


def _orbit_camera(K: np.ndarray, width: int, height: int, centre: np.ndarray, azimuth: float,
                  elevation: float, dist: float, offset: np.ndarray | None = None) -> Camera:
    d = np.array([math.cos(elevation) * math.cos(azimuth),
                  math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
    target = centre if offset is None else centre + offset
    return Camera(K, look_at(centre + dist * d, target), width, height)


def _write_capture(root: Path, spec: Subject, width: int, height: int, static_views: int,
                   steps: int, depth_noise: float, simultaneous: bool, regime: Regime,
                   robot: str | None = None) -> None:
    K = intrinsics(FOCAL_FACTOR * width, FOCAL_FACTOR * width, width / 2, height / 2)
    key = list(spec.key)
    rng = np.random.default_rng(key + [1])
    noise_rng = np.random.default_rng(key + [2])
    statics = static_cameras(spec, K, width, height, static_views, rng, regime.static_distance)
    fixed = interaction_cameras(spec, K, width, height, rng, regime.interaction_distance,
                                regime.azimuth)
    joints = spec.joints()
    schedule = interaction_schedule(joints, steps, simultaneous, regime.sequence,
                                    np.random.default_rng(key + [5]))
    centre, radius, _ = framing(spec, K, width, height)
    sensor_rng = np.random.default_rng(key + [6])
    a, b = (np.asarray(regime.depth_sigma) * sensor_rng.uniform(0.4, 1.0)).tolist()

    urdf_path = spec.write_gt_urdf(root)
    shots = [(f"static_{k:03d}", cam, None, {"phase": "static"}) for k, cam in enumerate(statics)]
    shots += [(f"t{t:03d}_cam{c}", cam, states, {"phase": "interaction", "time": t})
              for t, states in enumerate(schedule) for c, cam in enumerate(fixed)]
    frames: list[dict[str, Any]] = []
    plan = plan_robot(spec, schedule, robot) if robot else None
    with Scene() as scene, tempfile.TemporaryDirectory(prefix="artgs-room-") as scratch:
        body = _load_subject(scene, spec, urdf_path)
        arm = RobotInScene(scene.client, plan) if plan else None
        if regime.room:
            lo, hi = spec.bounds()
            eyes = np.array([cam.center for cam in statics + fixed])
            room, textures = room_urdf(spec.base_pose, _half_size(spec), float(lo[2]),
                                       np.random.default_rng(key + [7]), eyes, centre)
            (Path(scratch) / "room.urdf").write_text(room, encoding="utf-8")
            room_body = scene.load(Path(scratch) / "room.urdf")
            for name, tex in textures.items():
                if tex is not None:
                    scene.set_texture(room_body, tex, [room_body.links[name]])
        for stem, camera, states, extra in shots:
            if states is not None:
                scene.set_states(body, states)
            if arm is not None and extra["phase"] == "interaction":
                extra = {**extra, "robot_joint_positions": arm.show(extra["time"])}
            # open parts stay within 3 bounding radii of the centre: the far plane never clips
            far = float(np.linalg.norm(camera.center - centre)) + max(4.0 * radius,
                                                                      4.0 if regime.room else 0.0)
            frame = scene.render(camera, 0.05, far)
            rgb, mask = frame.rgb, frame.body == body.id
            # depth of the object and of the robot (in RGB and depth, never in the masks)
            seen = mask | (frame.body == arm.body) if arm is not None else mask
            depth = frame.depth if regime.room else np.where(seen, frame.depth, 0.0)
            depth = depth.astype(np.float32)
            if depth_noise > 0:
                noisy = depth + noise_rng.normal(0.0, depth_noise, depth.shape).astype(np.float32)
                depth = np.where(depth > 0, np.maximum(noisy, 1e-3), 0.0).astype(np.float32)
            if regime.depth_dropout:
                depth = sensor.dropout(depth, rgb, camera, sensor_rng)
                depth = sensor.flying_pixels(depth, mask, sensor_rng)
            if a > 0 or b > 0 or regime.depth_quantum > 0:
                depth = sensor.noisy_depth(depth, a, b, regime.depth_quantum, sensor_rng)
            if regime.exposure != (1.0, 1.0):
                rgb = sensor.exposure(rgb, sensor_rng.uniform(*regime.exposure), sensor_rng)
            mask = sensor.jitter_mask(mask, regime.mask_jitter, sensor_rng)
            _write_frame(root, stem, rgb, depth, mask if regime.masks else None)
            entry = {"file_path": f"images/{stem}.png", "depth_file_path": f"depth/{stem}.npy"}
            if regime.masks:
                entry["mask_path"] = f"masks/{stem}.png"
            frames.append({**entry,
                           "transform_matrix": [[float(v) for v in row] for row in camera.c2w],
                           **extra})

    atomic.write_json(root / "transforms.json", {
        "camera_model": "PINHOLE", "fl_x": float(K[0, 0]), "fl_y": float(K[1, 1]),
        "cx": float(K[0, 2]), "cy": float(K[1, 2]), "w": width, "h": height,
        **(robot_keys(plan) if plan else {}), "frames": frames})
    meta: dict[str, Any] = {"category": spec.category, "seed": spec.seed}
    if regime != make_regime("tight"):
        meta["regime"] = {k: v for k, v in regime.__dict__.items()}
    if isinstance(spec, AssetSpec):
        meta["asset"] = str(spec.path)
        meta["scale"] = spec.scale
    write_articulation(root / "gt.json", ground_truth(spec, schedule, meta))


def ground_truth(spec: Subject, schedule: list[dict[str, float]],
                 meta: dict[str, Any] | None = None) -> Articulation:
    """The subject's world-frame joints with their ``states`` per time of ``schedule``, ``extent``
    and ``handle``; ``meta`` defaults to the category and seed."""
    joints = spec.joints()
    for joint in joints:
        joint.states = {t: s[joint.name] for t, s in enumerate(schedule)}
    spec.annotate(joints)
    return Articulation(joints, meta if meta is not None else
                        {"category": spec.category, "seed": spec.seed})


def _load_subject(scene: Scene, spec: Subject, urdf_path: Path):
    """Load the subject's gt.urdf: procedural objects get their random texture, assets their
    MTL colours and textures."""
    if isinstance(spec, AssetSpec):
        import pybullet as p
        return scene.load(urdf_path, flags=p.URDF_USE_MATERIAL_COLORS_FROM_MTL)
    body = scene.load(urdf_path)
    texture = make_texture(np.random.default_rng(list(spec.key) + [3]))
    if texture is not None:
        scene.set_texture(body, texture)
    return body


def _half_size(spec: Subject) -> np.ndarray:
    """Half extents of the closed object along its own axes, about its frame origin (x, y) and
    from the floor (z: full height / 2)."""
    pts = spec.corners() - spec.base_pose[:3, 3]
    local = pts @ spec.base_pose[:3, :3]
    return np.array([np.abs(local[:, 0]).max(), np.abs(local[:, 1]).max(),
                     (local[:, 2].max() - local[:, 2].min()) / 2])


def _write_frame(root: Path, stem: str, rgb: np.ndarray, depth: np.ndarray,
                 mask: np.ndarray | None) -> None:
    """images/<stem>.png, depth/<stem>.npy (float32 metres), masks/<stem>.png (0/255)."""
    _write_png(root / "images" / f"{stem}.png", rgb[:, :, ::-1])
    if mask is not None:
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


def _check_category(category: str, regime: Regime) -> None:
    kinds = KINDS if regime.variety else CATEGORIES
    if category not in kinds:
        extra = " (door, washing_machine and chest need a regime with variety)" \
            if category in KINDS else ""
        raise InputError("command line", f"unknown category {category!r}; expected one of "
                         f"{', '.join(kinds)}{extra}", field="category")


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
