"""The three questions asked to the vision-language model (ArtGS paper, Table "VQA tasks").

All prompt text lives here. The answers are read by ``vlm.parse``, which accepts the paper's
free-text template as well as InternVL ``<box>`` answers and Qwen2.5-VL JSON, so the wording can be
changed freely. Boxes sent to the model (the part box in :data:`HANDLE`) use InternVL's convention:
``<box>[[x1, y1, x2, y2]]</box>`` on a 0-1000 grid over the image width and height.
"""

from __future__ import annotations

#: Object classification: category and number of movable parts.
CLASSIFY = "What is the object, and what are its movable components?"

#: Bones reasoning: per part, its joint type, joint parameter (two image points) and bounding box.
BONES = ("What are the joint types, joint parameters, and specific bounding box coordinates of "
         "these movable parts?")

#: Part detection: the handle inside one part's box (``{box}`` is filled by :func:`handle_prompt`).
HANDLE = ("What are the bounding box coordinates of the handle for the movable part within "
          "<box>{box}</box>?")


def handle_prompt(box_grid: list[int]) -> str:
    """The handle question for a part box given on the 0-1000 grid."""
    return HANDLE.format(box="[[" + ", ".join(str(int(v)) for v in box_grid) + "]]")
