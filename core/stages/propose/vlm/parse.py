"""Reading the VLM's answers: category, number of parts, per part its joint type, points and box.

Accepted answer formats (mixed freely, case-insensitive):

- the paper's template: ``Part 1 is a door, and its joint type is revolute. The joint parameter is
  [[x1, y1, x2, y2]]. Its bounding box is [[x1, y1, x2, y2]].`` (several parts in one answer);
- InternVL grounding: ``<ref>door</ref><box>[[x1, y1, x2, y2]]</box>``;
- Qwen2-VL: ``<|box_start|>(x1,y1),(x2,y2)<|box_end|>``;
- JSON, optionally inside a Markdown fence: ``[{"label": "door", "joint_type": "revolute",
  "joint": [x1, y1, x2, y2], "bbox_2d": [x1, y1, x2, y2]}]`` (Qwen2.5-VL style; key synonyms below);
- bare lists ``[x1, y1, x2, y2]``, ``[[x1, y1], [x2, y2]]``, ``(x1, y1), (x2, y2)``.

Coordinates, the rule (``coords="auto"``), decided once per answer:

1. numbers inside ``<box>...</box>`` or ``<|box_start|>...<|box_end|>`` are on InternVL's/Qwen2-VL's
   0-1000 grid over the image width and height, always;
2. otherwise, if every value is within 0..1 -> fractions of the image size (``unit``);
3. otherwise, if any x exceeds the image width or any y its height -> the 0-1000 grid;
4. otherwise JSON answers with a ``bbox_2d`` key -> absolute pixels (Qwen2.5-VL's convention);
5. otherwise -> the 0-1000 grid (InternVL's convention, the model of the paper).

``coords="grid1000"``, ``"pixels"`` or ``"unit"`` (``$ARTGS_VLM_COORDS``) override rules 2-5.
Pixel coordinates are image coordinates: the left/top image edge is 0, the right/bottom is the
width/height. Parts whose answer cannot be used are returned with a ``skip`` reason, never raised.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ....model.categories import CATEGORIES

#: Synonyms -> the seven categories; the earliest mention in the answer wins (longer on ties).
CATEGORY_SYNONYMS: dict[str, str] = {
    "dishwasher": "dishwasher", "dish washer": "dishwasher", "dish-washer": "dishwasher",
    "refrigerator": "refrigerator", "fridge": "refrigerator", "freezer": "refrigerator",
    "icebox": "refrigerator",
    "microwave": "microwave", "microwave oven": "microwave",
    "oven": "oven", "stove": "oven", "cooker": "oven", "range": "oven",
    "storage": "storage", "storage furniture": "storage", "wardrobe": "storage",
    "closet": "storage", "locker": "storage", "shelf": "storage", "bookcase": "storage",
    "drawer": "drawer", "chest of drawers": "drawer", "dresser": "drawer",
    "drawer unit": "drawer", "nightstand": "drawer", "filing cabinet": "drawer",
    "cabinet": "cabinet", "cupboard": "cabinet", "sideboard": "cabinet",
    "kitchen cabinet": "cabinet",
}
assert set(CATEGORY_SYNONYMS.values()) == set(CATEGORIES)

_NUMBER_WORDS = {"no": 0, "zero": 0, "a": 1, "an": 1, "a single": 1, "one": 1, "single": 1,
                 "two": 2, "both": 2, "a pair of": 2, "three": 3, "four": 4, "five": 5, "six": 6,
                 "seven": 7, "eight": 8, "nine": 9, "ten": 10, "eleven": 11, "twelve": 12}
_NUM = r"(\d+|a single|a pair of|" + "|".join(sorted(_NUMBER_WORDS, key=len, reverse=True)) + r")"
_PART_NOUNS = r"(?:doors?|drawers?|lids?|panels?|flaps?|trays?|baskets?|shelves|shelf)"

#: Words for the joint types (the first mention in a part's text wins).
_REVOLUTE = r"revolute|rotat\w*|hinge\w*|swing\w*|pivot\w*"
_PRISMATIC = r"prismatic|slid\w*|translat\w*|linear|pull[- ]out"
#: Joint type assumed from the part's name when the answer gives none.
_TYPE_BY_LABEL = {"drawer": "prismatic", "tray": "prismatic", "basket": "prismatic",
                  "door": "revolute", "lid": "revolute", "flap": "revolute", "panel": "revolute"}

_JOINT_KEYS = ("joint", "joint_parameter", "joint_param", "joint_params", "joint_2d", "axis",
               "axis_2d", "joint_axis", "points", "line")
_BOX_KEYS = ("bbox_2d", "bbox", "box", "box_2d", "bounding_box", "part_bbox")
_LABEL_KEYS = ("label", "name", "part", "part_name", "category")
_TYPE_KEYS = ("joint_type", "type", "joint")
_TAG_BOX = re.compile(r"<box>(.*?)</box>|<\|box_start\|>(.*?)<\|box_end\|>", re.S | re.I)
_GROUP = re.compile(r"[\[(][\d\s.,+\-\[\]()]*[\])]")
_FLOAT = re.compile(r"-?\d+(?:\.\d+)?")
_JOIN = re.compile(r"\s*(?:,|;|to|and|-|–|->|→)?\s*", re.I)  # between a segment's two points
_EDGE_TOL = 0.03  # fraction of the image size a coordinate may overshoot before it is refused


@dataclass
class PartAnswer:
    """One movable part as the VLM described it, in pixel coordinates of the asked image."""

    index: int
    label: str = "part"
    joint_type: str | None = None
    joint_points: np.ndarray | None = None  # (2, 2): two image points (x, y) on the joint axis
    bbox: np.ndarray | None = None          # (4,): x1, y1, x2, y2
    skip: str | None = None                 # why this part cannot be used (None: usable)


@dataclass
class _Coords:
    """A coordinate group found in an answer: its numbers, text position, whether it was inside a
    box tag, and what it is (``joint`` points or part ``box``, once known)."""

    values: list[float]
    pos: int = 0
    tagged: bool = False
    role: str = ""


def parse_classification(text: str) -> tuple[str | None, int | None]:
    """Category (one of the seven, via synonyms) and number of movable parts, None where absent."""
    low = text.replace("*", "").lower()
    category, best = None, (len(low) + 1, 0)
    for word, cat in CATEGORY_SYNONYMS.items():
        m = re.search(r"\b" + re.escape(word) + r"s?\b", low)
        if m and (m.start(), -len(word)) < best:
            category, best = cat, (m.start(), -len(word))
    m = re.search(r"\b" + _NUM + r"\s+(?:\w+\s+)?(?:movable|moving|articulated|operable|moveable)?"
                  r"\s*(?:parts?|components?|links?)\b", low)
    if m:
        return category, _number(m.group(1))
    counts = [_number(n) for n in re.findall(r"\b" + _NUM + r"\s+(?:\w+\s+)?" + _PART_NOUNS + r"\b",
                                             low)]
    return category, (sum(counts) if counts else None)


def parse_parts(text: str, width: int, height: int, coords: str = "auto") -> list[PartAnswer]:
    """All parts in a bones-reasoning answer; unusable ones carry a ``skip`` reason."""
    items = _json_items(text)
    if items is not None:
        raw = [_part_from_json(i + 1, item) for i, item in enumerate(items)]
        groups = [g for _, groups in raw for g in groups]
        system = _coordinate_system(groups, width, height, coords, json_bbox2d=_has_bbox2d(items))
        parts = [_finish(part, groups, system, width, height) for part, groups in raw]
    else:
        raw = [_part_from_text(i, segment) for i, segment in _segments(text.replace("*", ""))]
        groups = [g for _, groups in raw for g in groups]
        if not groups:
            return [PartAnswer(1, skip=f"no coordinates in the answer {_quote(text)}")]
        system = _coordinate_system(groups, width, height, coords)
        parts = [_finish(part, groups, system, width, height) for part, groups in raw]
    return parts


def parse_handle(text: str, width: int, height: int, coords: str = "auto"
                 ) -> tuple[np.ndarray | None, str | None]:
    """The handle box (pixels) from a part-detection answer, or (None, reason)."""
    items = _json_items(text)
    if items is not None:
        groups = []
        for item in items:
            values = _find_key(item, _BOX_KEYS) if isinstance(item, dict) else item
            groups += _flat_group(values, "box")
        system = _coordinate_system(groups, width, height, coords, json_bbox2d=_has_bbox2d(items))
    else:
        groups = _groups(text)
        system = _coordinate_system(groups, width, height, coords)
    boxes = [g for g in groups if len(g.values) >= 4]
    if not boxes:
        return None, f"no handle box in the answer {_quote(text)}"
    return _box(boxes[0], system, width, height)


def to_grid1000(box: np.ndarray, width: int, height: int) -> list[int]:
    """A pixel box as InternVL's 0-1000 grid integers (for the part box in the handle question)."""
    scale = np.array([1000.0 / width, 1000.0 / height] * 2)
    return [int(round(v)) for v in np.clip(np.asarray(box, float) * scale, 0, 1000)]


# --- parts from JSON -------------------------------------------------------------------------

def _json_items(text: str) -> list[Any] | None:
    """The list of objects in a JSON answer (fenced or bare), or None if the answer is not JSON."""
    fence = re.search(r"```(?:json)?\s*(.*?)```", text, re.S | re.I)
    body = fence.group(1) if fence else text
    start = min((i for i in (body.find("["), body.find("{")) if i >= 0), default=-1)
    if start < 0:
        return None
    try:
        data, _ = json.JSONDecoder().raw_decode(body[start:])
    except json.JSONDecodeError:
        return None
    if isinstance(data, dict):
        for key in ("parts", "movable_parts", "objects", "results", "handles"):
            if isinstance(data.get(key), list):
                return data[key]
        return [data]
    if isinstance(data, list) and data and all(isinstance(d, dict) for d in data):
        return data
    return None  # a bare number list is a coordinate group, read by the text path


def _has_bbox2d(items: list[Any]) -> bool:
    return any(isinstance(i, dict) and "bbox_2d" in i for i in items)


def _find_key(item: dict, keys: tuple[str, ...]) -> Any:
    lowered = {str(k).lower(): v for k, v in item.items()}
    for key in keys:
        if key in lowered:
            return lowered[key]
    return None


def _flat_group(values: Any, role: str) -> list[_Coords]:
    """A JSON value holding 4 numbers (flat or as two pairs) as one coordinate group."""
    if values is None:
        return []
    flat = np.asarray(values, dtype=object).ravel().tolist() if isinstance(values, list) else []
    try:
        numbers = [float(v) for v in flat]
    except (TypeError, ValueError):
        return []
    return [_Coords(numbers, role=role)] if len(numbers) >= 4 else []


def _part_from_json(index: int, item: dict) -> tuple[PartAnswer, list[_Coords]]:
    part = PartAnswer(index)
    label = _find_key(item, _LABEL_KEYS)
    if isinstance(label, str) and label.strip():
        part.label = _clean_label(label)
    kind = _find_key(item, _TYPE_KEYS)
    part.joint_type = _joint_type(kind) if isinstance(kind, str) else None
    return part, (_flat_group(_find_key(item, _JOINT_KEYS), "joint")
                  + _flat_group(_find_key(item, _BOX_KEYS), "box"))


# --- parts from free text --------------------------------------------------------------------

def _segments(text: str) -> list[tuple[int, str]]:
    """Per-part pieces of a text answer: split at "Part N", else at numbered list items, else at
    each <ref>."""
    marks = list(re.finditer(r"\bpart\s*(?:#|no\.?\s*)?(\d+)\b", text, re.I))
    if not marks:  # a numbered list: "1. door ..." / "2) drawer ..."
        marks = list(re.finditer(r"^\s*[-*]?\s*(\d+)[.):]\s", text, re.M))
    if marks:
        return [(int(m.group(1)), text[m.start():(marks[k + 1].start() if k + 1 < len(marks)
                                                   else len(text))])
                for k, m in enumerate(marks)]
    refs = list(re.finditer(r"<ref>", text, re.I))
    if len(refs) > 1:
        return [(k + 1, text[m.start():(refs[k + 1].start() if k + 1 < len(refs) else len(text))])
                for k, m in enumerate(refs)]
    return [(1, text)] if text.strip() else []


def _part_from_text(index: int, segment: str) -> tuple[PartAnswer, list[_Coords]]:
    part = PartAnswer(index)
    low = segment.lower()
    ref = re.search(r"<ref>(.*?)</ref>", segment, re.I | re.S)
    name = re.search(r"\bis (?:an? |the )?([a-z][a-z \-]*?)"
                     r"(?=,|\.|;|\(| and\b| with\b| whose\b| that\b| which\b|$)",
                     re.sub(r"<[^>]*>", " ", low))
    if ref and ref.group(1).strip():
        part.label = _clean_label(ref.group(1))
    elif name and not re.match(r"(?:" + _REVOLUTE + "|" + _PRISMATIC + r")\b", name.group(1)):
        part.label = _clean_label(name.group(1))
    else:
        noun = re.search(r"\b(door|drawer|lid|flap|tray|basket|panel)s?\b", low)
        if noun:
            part.label = noun.group(1)
    typed = re.search(r"joint type\W+(?:is\s+)?(?:an?\s+)?(\w+)", low)
    part.joint_type = _joint_type(typed.group(1)) if typed else None
    if part.joint_type is None:
        part.joint_type = _joint_type(low)
    groups = _groups(segment)
    joint_kw = [m.start() for m in re.finditer(r"joint param\w*|joint\s+(?:axis|line|points?)|"
                                                r"\baxis\b|\bhinge\b", low)]
    box_kw = [m.start() for m in re.finditer(
        r"bounding box|\bbbox\b|(?<![</])\bbox\b(?!>)|\blocated at\b", low)]
    for k, g in enumerate(groups):
        last_joint = max((p for p in joint_kw if p < g.pos), default=-1)
        last_box = max((p for p in box_kw if p < g.pos), default=-1)
        if last_joint < 0 and last_box < 0:
            is_joint = (k == 0 and len(groups) > 1) and not g.tagged
        else:
            is_joint = last_joint > last_box
        g.role = "joint" if is_joint else "box"
    return part, groups


def _groups(text: str) -> list[_Coords]:
    """Coordinate groups with at least 4 numbers: tagged boxes first claim their text span."""
    out: list[_Coords] = []
    taken: list[tuple[int, int]] = []
    for m in _TAG_BOX.finditer(text):
        values = [float(v) for v in _FLOAT.findall(m.group(1) or m.group(2) or "")]
        taken.append(m.span())
        if len(values) >= 4:
            out.append(_Coords(values, m.start(), True))
    pending: tuple[list[float], int, int] | None = None  # a lone point (x, y) awaiting its pair
    for m in _GROUP.finditer(text):
        if any(a <= m.start() < b for a, b in taken):
            continue
        values = [float(v) for v in _FLOAT.findall(m.group(0))]
        if len(values) == 2:  # "(x1, y1) to (x2, y2)": two points make one group
            if pending is not None and _JOIN.fullmatch(text[pending[2]:m.start()]):
                out.append(_Coords(pending[0] + values, pending[1], False))
                pending = None
            else:
                pending = (values, m.start(), m.end())
        elif len(values) >= 4:
            out.append(_Coords(values, m.start(), False))
    return sorted(out, key=lambda g: g.pos)


# --- coordinates and checks ------------------------------------------------------------------

def _coordinate_system(groups: list[_Coords], width: int, height: int, coords: str,
                       json_bbox2d: bool = False) -> str:
    """The rule of the module docstring for the untagged groups of one answer."""
    if coords != "auto":
        return coords
    values = np.array([v for g in groups if not g.tagged for v in g.values[:4]], float)
    if values.size == 0:
        return "grid1000"
    if np.all((values >= 0) & (values <= 1.0)):
        return "unit"
    xy = values.reshape(-1, 2)
    if np.any(xy[:, 0] > width) or np.any(xy[:, 1] > height):
        return "grid1000"
    return "pixels" if json_bbox2d else "grid1000"


def _to_pixels(g: _Coords, system: str, width: int, height: int) -> np.ndarray:
    v = np.asarray(g.values[:4], float).reshape(2, 2)
    system = "grid1000" if g.tagged else system
    if system == "grid1000":
        v = v * np.array([width, height]) / 1000.0
    elif system == "unit":
        v = v * np.array([width, height])
    return v


def _inside(v: np.ndarray, width: int, height: int) -> bool:
    tol = _EDGE_TOL * np.array([width, height])
    return bool(np.all(v >= -tol) and np.all(v <= np.array([width, height]) + tol))


def _box(g: _Coords, system: str, width: int, height: int) -> tuple[np.ndarray | None, str | None]:
    v = _to_pixels(g, system, width, height)
    shown = [round(x, 1) for x in g.values[:4]]
    if not _inside(v, width, height):
        return None, f"box {shown} lies outside the {width}x{height} image ({system} coordinates)"
    v = np.clip(v, 0, [width, height])
    box = np.array([v[:, 0].min(), v[:, 1].min(), v[:, 0].max(), v[:, 1].max()])
    if box[2] - box[0] < 2 or box[3] - box[1] < 2:
        return None, f"box {shown} is smaller than 2 pixels"
    return box, None


def _finish(part: PartAnswer, groups: list[_Coords], system: str, width: int, height: int
            ) -> PartAnswer:
    """Convert the part's groups to pixels and decide whether the part is usable."""
    joint = next((g for g in groups if g.role == "joint"), None)
    box = next((g for g in groups if g.role == "box"), None)
    if part.joint_type is None:
        part.joint_type = _TYPE_BY_LABEL.get(part.label.split()[-1].rstrip("s"))
    if box is None:
        part.skip = f"part {part.index} ({part.label}): no bounding box in the answer"
        return part
    part.bbox, reason = _box(box, system, width, height)
    if reason:
        part.skip = f"part {part.index} ({part.label}): {reason}"
        return part
    if part.joint_type is None:
        part.skip = f"part {part.index} ({part.label}): no joint type in the answer"
        return part
    if joint is not None:
        points = _to_pixels(joint, system, width, height)
        if _inside(points, width, height):
            part.joint_points = np.clip(points, 0, [width, height])
        elif part.joint_type == "revolute":
            part.skip = (f"part {part.index} ({part.label}): joint points "
                         f"{[round(x, 1) for x in joint.values[:4]]} lie outside the image")
            return part
    if part.joint_type == "revolute":
        if part.joint_points is None:
            part.skip = f"part {part.index} ({part.label}): revolute but no joint parameter points"
        elif np.linalg.norm(part.joint_points[0] - part.joint_points[1]) < 2:
            part.skip = f"part {part.index} ({part.label}): the two joint points coincide"
    return part


def _joint_type(text: str) -> str | None:
    rev = re.search(r"\b(?:" + _REVOLUTE + r")", text, re.I)
    pri = re.search(r"\b(?:" + _PRISMATIC + r")", text, re.I)
    if rev and (not pri or rev.start() < pri.start()):
        return "revolute"
    return "prismatic" if pri else None


def _clean_label(label: str) -> str:
    words = re.sub(r"[^a-z ]", " ", label.lower()).split()
    return " ".join(words[-2:]) if words else "part"


def _number(word: str) -> int:
    return int(word) if word.isdigit() else _NUMBER_WORDS[word]


def _quote(text: str, limit: int = 120) -> str:
    text = " ".join(text.split())
    return repr(text[:limit] + ("..." if len(text) > limit else ""))
