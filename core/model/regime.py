"""Capture regimes of ``artgs synth`` (numpy-free: the CLI derives its flags from :class:`Regime`): how cameras, sensor, appearance, interaction and surroundings
are drawn. Two presets; every field can be overridden on the command line (``--<field>``).

``tight`` is the generator's original behaviour (kept byte-identical): cameras that frame the object
tightly, exact depth (or constant Gaussian noise with ``--depth-noise``), perfect masks, one joint
after the other to its upper limit, boxes in part-to-part colours, no room.

``realistic`` (the benchmarks' default) imitates a phone/RGB-D capture; each default range is the
preset's value below (``x`` = the distance at which the object's bounding sphere fills the view):

- cameras: static views at 1-2 x, fixed interaction cameras at 1.2-3 x, azimuth anywhere in the
  front half (+-80 deg), elevation 5-60 deg (interaction 5-45 deg), look-at point jittered by up to
  0.15 bounding radii;
- depth: sigma = a z + b z^2 with a in 0.2-0.5 % and b in 0.05-0.15 %/m (per capture), quantised to
  1 mm; missing (0) along depth edges (jump > 2 cm or 3 % of z; dropped with p = 0.6, 1 px band),
  on dark surfaces (luminance < 0.1, p = 0.8) and at grazing angles (> 78 deg, p = 0.7); flying
  pixels (depth between foreground and background) on 15 % of silhouette pixels;
- RGB: per-frame exposure gain 0.85-1.15 and sensor noise sigma 1.5/255;
- masks: eroded or dilated by 1-2 px per frame (as a segmentation model), or none (``masks=False``);
- appearance/geometry variety: parts in the body's colour/texture, handles of several kinds or none,
  framed doors, extra kinds (room door in a frame, washing machine with a round door, chest lid);
- interaction: each joint opens fully, partially (30-80 %) or only a little (10 deg / 3 cm), then
  several joints move at once;
- room: textured floor, walls behind and beside, furniture next to the object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

from .errors import InputError
from .registry import option


@dataclass(frozen=True)
class Regime:
    """How one capture is drawn; ranges are (low, high), sampled uniformly per capture or frame."""

    static_distance: tuple[float, float] | None = option(
        None, "static view distance range, x framing distance (none: fit the object to 60-85 % of "
              "the image)")
    interaction_distance: tuple[float, float] | None = option(
        None, "fixed interaction camera distance range, x framing distance (none: fit 70-85 %)")
    azimuth: float = option(0.0, "interaction cameras: azimuth anywhere within +-this many degrees "
                               "of the front (0: left-front and right-front, 30-45 deg)")
    depth_sigma: tuple[float, float] = option(
        (0.0, 0.0), "depth noise sigma = A z + B z^2: A (relative) and B (1/m) upper bounds; "
                    "per capture drawn from [0.4, 1] x these")
    depth_quantum: float = option(0.0, "depth quantisation step, metres (0: none)")
    depth_dropout: bool = option(False, "missing depth on depth edges, dark and grazing surfaces; "
                                      "flying pixels at silhouettes")
    exposure: tuple[float, float] = option((1.0, 1.0), "per-frame exposure gain range")
    mask_jitter: int = option(0, "masks eroded or dilated by up to this many pixels per frame")
    masks: bool = option(True, "write masks (--no-masks: none, as phone/RGB-D apps deliver)")
    variety: bool = option(False, "appearance/geometry variety and extra kinds of objects")
    sequence: str = option("sequential", "interaction sequence: sequential (each joint fully "
                                       "open in turn) or mixed (full/partial/small openings, "
                                       "then several joints at once)")
    room: bool = option(False, "textured floor, walls and furniture around the object")


PRESETS: dict[str, Regime] = {
    "tight": Regime(),
    "realistic": Regime(static_distance=(1.0, 2.0), interaction_distance=(1.2, 3.0), azimuth=80.0,
                        depth_sigma=(0.005, 0.0015), depth_quantum=0.001, depth_dropout=True,
                        exposure=(0.85, 1.15), mask_jitter=2, masks=True, variety=True,
                        sequence="mixed", room=True),
}

SEQUENCES = ("sequential", "mixed")


def regime(name: str = "tight", **overrides: Any) -> Regime:
    """The preset ``name`` with ``overrides`` (fields set to None are left as the preset's)."""
    if name not in PRESETS:
        raise InputError("command line", f"unknown regime {name!r}; expected one of "
                         f"{', '.join(PRESETS)}", field="regime")
    known = {f.name for f in fields(Regime)}
    unknown = set(overrides) - known
    if unknown:
        raise TypeError(f"unknown regime options {sorted(unknown)}")
    r = replace(PRESETS[name], **{k: tuple(v) if isinstance(v, list) else v
                                  for k, v in overrides.items() if v is not None})
    _check(r)
    return r


def _check(r: Regime) -> None:
    def bad(name: str, msg: str) -> InputError:
        return InputError("command line", msg, field=name.replace("_", "-"))

    for name in ("static_distance", "interaction_distance"):
        v = getattr(r, name)
        if v is not None and not (len(v) == 2 and 0 < v[0] <= v[1] and math.isfinite(v[1])):
            raise bad(name, f"must be two numbers 0 < LOW <= HIGH, not {v}")
    if not 0 <= r.azimuth <= 90:
        raise bad("azimuth", f"must be within 0..90 degrees, not {r.azimuth}")
    if not (len(r.depth_sigma) == 2 and all(math.isfinite(v) and v >= 0 for v in r.depth_sigma)):
        raise bad("depth_sigma", f"must be two finite numbers >= 0, not {r.depth_sigma}")
    if not (math.isfinite(r.depth_quantum) and r.depth_quantum >= 0):
        raise bad("depth_quantum", f"must be >= 0, not {r.depth_quantum}")
    if not (len(r.exposure) == 2 and 0 < r.exposure[0] <= r.exposure[1] < 10):
        raise bad("exposure", f"must be two numbers 0 < LOW <= HIGH < 10, not {r.exposure}")
    if not 0 <= r.mask_jitter <= 5:
        raise bad("mask_jitter", f"must be within 0..5 pixels, not {r.mask_jitter}")
    if r.sequence not in SEQUENCES:
        raise bad("sequence", f"must be one of {', '.join(SEQUENCES)}, not {r.sequence!r}")
