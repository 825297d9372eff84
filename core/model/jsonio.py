"""Reading JSON input files with errors that name the file."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .errors import InputError


def read_json_object(path: str | Path, missing: str = "file not found") -> dict[str, Any]:
    """The JSON object in ``path``; InputError naming the file when missing, invalid or not an object."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, missing)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(path, f"not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise InputError(path, f"must hold a JSON object, not a {type(data).__name__}")
    return data
