"""Gaussian splats as PLY files in the standard 3DGS layout (numpy only: the Blender process uses it).

Layout (as the INRIA 3DGS code writes it, readable by other 3DGS viewers): one ``vertex`` element,
binary little endian, float32 properties ``x y z nx ny nz f_dc_0..2 f_rest_0..M-1 opacity
scale_0..2 rot_0..3``. ``opacity`` is a logit, ``scale_*`` are natural logs, ``rot_*`` is the
quaternion w x y z (not necessarily normalised). ``f_rest`` holds the SH coefficients 1..K-1
channel-major: all red coefficients, then green, then blue, so ``f_rest[c * (K-1) + k - 1] =
sh[k, c]``; the SH degree (0..3) follows from M = 3 (K - 1), K = (degree + 1)^2.

Reading is tolerant: any property order, extra properties ignored, ASCII or binary (either
endianness), any numeric property type, other elements before or after ``vertex``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.lib.recfunctions import structured_to_unstructured

from .atomic import atomic_path
from .errors import InputError

#: PLY scalar type names -> numpy type codes (both the classic and the sized spellings).
_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": None}
_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")
_HEADER_LIMIT = 1 << 16
#: Largest log scale a Gaussian may have: exp(2 s) (its variance) must stay finite in float32.
_MAX_LOG_SCALE = 40.0


@dataclass
class SplatArrays:
    """Gaussians as numpy arrays (float32).

    ``means`` (N,3); ``quats`` (N,4) w x y z; ``log_scales`` (N,3); ``opacity_logits`` (N,);
    ``sh`` (N,K,3), K = (degree+1)^2, ``sh[:, 0]`` the DC term (colour = SH + 0.5 as in 3DGS).
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    opacity_logits: np.ndarray
    sh: np.ndarray

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def degree(self) -> int:
        """SH degree (0..3)."""
        return int(round(np.sqrt(self.sh.shape[1]))) - 1

    def first_invalid(self) -> tuple[str, int, int, str] | None:
        """The first value no splat can hold, as (array, Gaussian, column, why), else None:
        a non-finite number, a zero quaternion (no rotation; column 0), or a log scale whose
        variance ``exp(2 s)`` overflows float32."""
        arrays = {"means": self.means, "quats": self.quats, "log_scales": self.log_scales,
                  "opacity_logits": self.opacity_logits.reshape(-1, 1),
                  "sh": self.sh.reshape(len(self), 3 * self.sh.shape[1])}
        for name, a in arrays.items():
            bad = ~np.isfinite(a)
            if bad.any():
                row, col = np.argwhere(bad)[0]
                return name, int(row), int(col), f"is {a[row, col]} (not a finite float32)"
        zero = ~(np.abs(self.quats) > 0).any(axis=1)
        if zero.any():
            return ("quats", int(np.argmax(zero)), 0,
                    "is the zero quaternion (rot_0..rot_3 all 0), which is no rotation")
        big = self.log_scales > _MAX_LOG_SCALE
        if big.any():
            row, col = np.argwhere(big)[0]
            return ("log_scales", int(row), int(col), f"has log scale {self.log_scales[row, col]:g}"
                    f" > {_MAX_LOG_SCALE:g} (its covariance overflows float32)")
        return None

    def validate(self) -> None:
        """Raise ValueError if the array shapes do not fit together."""
        n = self.means.shape[0]
        shapes = {"means": (self.means.shape, (n, 3)), "quats": (self.quats.shape, (n, 4)),
                  "log_scales": (self.log_scales.shape, (n, 3)),
                  "opacity_logits": (self.opacity_logits.shape, (n,))}
        for name, (got, want) in shapes.items():
            if tuple(got) != want:
                raise ValueError(f"SplatArrays.{name} has shape {tuple(got)}, expected {want}")
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3 \
                or self.sh.shape[1] not in (1, 4, 9, 16):
            raise ValueError(f"SplatArrays.sh has shape {tuple(self.sh.shape)}, expected (N, K, 3) "
                             "with K in 1, 4, 9, 16")


def write_ply(path: str | Path, splats: SplatArrays) -> None:
    """Write ``splats`` to ``path`` in the standard 3DGS layout, atomically.

    Raises ValueError (before touching ``path``) for values :func:`read_ply` would refuse.
    """
    splats.validate()
    invalid = splats.first_invalid()
    if invalid is not None:
        name, row, col, why = invalid
        raise ValueError(f"SplatArrays.{name}[{row}, {col}] {why}")
    n, k = len(splats), splats.sh.shape[1]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (k - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    rest = np.transpose(splats.sh[:, 1:, :], (0, 2, 1)).reshape(n, 3 * (k - 1))  # channel-major
    columns = np.concatenate([
        splats.means.reshape(n, 3), np.zeros((n, 3), np.float32), splats.sh[:, 0, :], rest,
        splats.opacity_logits.reshape(n, 1), splats.log_scales.reshape(n, 3),
        splats.quats.reshape(n, 4)], axis=1).astype("<f4")
    header = "ply\nformat binary_little_endian 1.0\n"
    header += f"element vertex {n}\n"
    header += "".join(f"property float {name}\n" for name in names)
    header += "end_header\n"
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(columns).tobytes())


def read_ply(path: str | Path) -> SplatArrays:
    """Read a 3DGS PLY file; raises :class:`InputError` naming the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "file not found")
    with open(path, "rb") as f:
        fmt, elements, header_len = _read_header(path, f)
    vertex = next((e for e in elements if e[0] == "vertex"), None)
    if vertex is None:
        raise InputError(path, "no 'vertex' element in the PLY header", field="vertex")
    _, count, props = vertex
    names = [name for name, _ in props]
    duplicate = next((name for i, name in enumerate(names) if name in names[:i]), None)
    if duplicate is not None:
        raise InputError(path, f"vertex property '{duplicate}' is declared twice", field=duplicate)
    for name in _REQUIRED:
        if name not in names:
            raise InputError(path, f"missing vertex property '{name}' (not a 3DGS splat file?)",
                             field=name)
    if any(kind == "list" for _, kind in props):
        raise InputError(path, "list properties in the vertex element are not supported",
                         field="vertex")
    n_rest = sum(1 for name in names if name.startswith("f_rest_"))
    if n_rest not in (0, 9, 24, 45):
        raise InputError(path, f"{n_rest} f_rest properties; expected 0, 9, 24 or 45 "
                         "(SH degree 0..3)", field="f_rest")
    for i in range(n_rest):
        if f"f_rest_{i}" not in names:
            raise InputError(path, f"missing vertex property 'f_rest_{i}'", field=f"f_rest_{i}")
    if count == 0:
        raise InputError(path, "holds no Gaussians (element vertex 0)", field="vertex")
    table = structured_to_unstructured(_read_vertex(path, fmt, elements, header_len),
                                       dtype=np.float32)
    column = {name: i for i, name in enumerate(names)}

    def cols(*keys: str) -> np.ndarray:
        return table[:, [column[k] for k in keys]]

    k = n_rest // 3 + 1
    sh = np.empty((count, k, 3), np.float32)
    sh[:, 0] = cols("f_dc_0", "f_dc_1", "f_dc_2")
    if n_rest:
        rest = cols(*[f"f_rest_{i}" for i in range(n_rest)]).reshape(count, 3, k - 1)
        sh[:, 1:] = np.transpose(rest, (0, 2, 1))
    splats = SplatArrays(means=cols("x", "y", "z"), quats=cols("rot_0", "rot_1", "rot_2", "rot_3"),
                         log_scales=cols("scale_0", "scale_1", "scale_2"),
                         opacity_logits=table[:, column["opacity"]].copy(), sh=sh)
    invalid = splats.first_invalid()
    if invalid is not None:
        array, row, col, why = invalid
        raise InputError(path, f"element vertex[{row}] {why}", field=_field_name(array, col, k))
    return splats


def _field_name(array: str, col: int, k: int) -> str:
    """The PLY property holding column ``col`` of SplatArrays' ``array`` (K SH coefficients)."""
    if array == "sh":
        coeff, channel = divmod(col, 3)
        return f"f_dc_{channel}" if coeff == 0 else f"f_rest_{channel * (k - 1) + coeff - 1}"
    return {"means": ("x", "y", "z"), "quats": tuple(f"rot_{i}" for i in range(4)),
            "log_scales": tuple(f"scale_{i}" for i in range(3)),
            "opacity_logits": ("opacity",)}[array][col]


def _read_header(path: Path, f) -> tuple[str, list, int]:
    """Parse the header: (format, [(element, count, [(prop, type|'list')])], header bytes)."""
    if f.read(4) not in (b"ply\n", b"ply\r"):
        raise InputError(path, "not a PLY file (no 'ply' magic line)")
    f.seek(0)
    fmt, elements = None, []
    while True:
        line = f.readline(_HEADER_LIMIT)
        if not line or f.tell() > _HEADER_LIMIT:
            raise InputError(path, "PLY header has no 'end_header' line")
        words = line.decode("ascii", "replace").split()
        if not words or words[0] in ("ply", "comment", "obj_info"):
            continue
        if words[0] == "end_header":
            break
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _FORMATS:
                raise InputError(path, f"unknown PLY format line {line.strip()!r}", field="format")
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) >= 3:
            if words[1] == "list":
                elements[-1][2].append((words[-1], "list"))
            elif words[1] in _TYPES:
                elements[-1][2].append((words[2], _TYPES[words[1]]))
            else:
                raise InputError(path, f"unknown property type in {line.strip()!r}",
                                 field=words[-1])
        else:
            raise InputError(path, f"cannot parse PLY header line {line.strip()!r}")
    if fmt is None:
        raise InputError(path, "PLY header has no 'format' line", field="format")
    return fmt, elements, f.tell()


def _read_vertex(path: Path, fmt: str, elements: list, header_len: int) -> np.ndarray:
    """The vertex element as a structured array (one field per property)."""
    endian = _FORMATS[fmt]
    offset, skip_lines = header_len, 0
    for name, count, props in elements:
        if name == "vertex":
            break
        if endian is None:
            skip_lines += count
        elif any(kind == "list" for _, kind in props):
            raise InputError(path, f"element '{name}' with list properties precedes 'vertex'",
                             field=name)
        else:
            offset += count * sum(np.dtype(kind).itemsize for _, kind in props)
    count, props = next((c, p) for n, c, p in elements if n == "vertex")
    if endian is None:
        dtype = np.dtype([(p, kind) for p, kind in props])
        size = path.stat().st_size - header_len
        if count * len(props) * 2 > size:   # each value takes at least a digit and a separator
            raise InputError(path, f"file is truncated: {size} bytes of ASCII data cannot hold "
                             f"the {count} vertices the header promises", field="vertex")
        with open(path, "rb") as f:
            f.seek(header_len)
            try:
                table = np.loadtxt(f, dtype=np.float64, skiprows=skip_lines, max_rows=count,
                                   ndmin=2)
            except ValueError as exc:
                raise InputError(path, f"bad ASCII vertex data ({exc})", field="vertex") from exc
        if table.shape != (count, len(props)) and count > 0:
            raise InputError(path, f"expected {count} ASCII vertex rows of {len(props)} values, "
                             f"got {table.shape}", field="vertex")
        data = np.empty(count, dtype)
        for i, (p, _) in enumerate(props):
            data[p] = table[:, i] if count else 0
        return data
    dtype = np.dtype([(p, endian + kind) for p, kind in props])
    need = offset + count * dtype.itemsize
    size = path.stat().st_size
    if size < need:
        raise InputError(path, f"file is truncated: {size} bytes, the header promises {need}",
                         field="vertex")
    return np.fromfile(path, dtype=dtype, count=count, offset=offset)
