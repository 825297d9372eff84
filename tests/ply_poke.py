"""Test helper: overwrite one value of a splat PLY in place, past what write_ply allows."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def poke_ply(path: Path, row: int, field: str, value: float) -> None:
    """Set one float32 value of a binary little-endian PLY written by write_ply (which itself
    refuses to write values no splat can hold)."""
    data = bytearray(path.read_bytes())
    head_end = data.index(b"end_header\n") + len(b"end_header\n")
    names = [line.split()[-1] for line in data[:head_end].decode().splitlines()
             if line.startswith("property")]
    offset = head_end + 4 * (row * len(names) + names.index(field))
    data[offset:offset + 4] = np.float32(value).tobytes()
    path.write_bytes(bytes(data))
