"""PLY I/O in the standard 3DGS layout: round trips, the INRIA byte layout, tolerant reading, bad files."""

from __future__ import annotations

import numpy as np
import pytest

from artgs.core.model.errors import InputError
from artgs.core.model.ply import SplatArrays, read_ply, write_ply


def _splats(n: int, degree: int, seed: int = 0) -> SplatArrays:
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return SplatArrays(
        means=rng.normal(size=(n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        log_scales=rng.normal(-4, 1, size=(n, 3)).astype(np.float32),
        opacity_logits=rng.normal(size=n).astype(np.float32),
        sh=rng.normal(size=(n, k, 3)).astype(np.float32))


def _assert_equal(a: SplatArrays, b: SplatArrays) -> None:
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip(tmp_path, degree):
    s = _splats(57, degree)
    write_ply(tmp_path / "s.ply", s)
    r = read_ply(tmp_path / "s.ply")
    assert r.degree == degree and r.sh.shape == (57, (degree + 1) ** 2, 3)
    assert r.means.dtype == np.float32
    _assert_equal(s, r)
    # exact size: header + 4 bytes x (14 + 3 normals + 3 (K-1)) per vertex
    props = 17 + 3 * ((degree + 1) ** 2 - 1)
    header = (tmp_path / "s.ply").read_bytes().split(b"end_header\n")[0]
    assert (tmp_path / "s.ply").stat().st_size == len(header) + 11 + 57 * 4 * props


def _inria_bytes(xyz, f_dc, f_rest_nk3, opac, scale, rot) -> bytes:
    """Bytes exactly as gaussian-splatting's GaussianModel.save_ply writes them through plyfile."""
    n = xyz.shape[0]
    attrs = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    attrs += [f"f_rest_{i}" for i in range(f_rest_nk3.shape[1] * 3)]
    attrs += ["opacity"] + [f"scale_{i}" for i in range(3)] + [f"rot_{i}" for i in range(4)]
    # _features_rest is (N, K-1, 3); save_ply does .transpose(1, 2).flatten(start_dim=1)
    f_rest = np.transpose(f_rest_nk3, (0, 2, 1)).reshape(n, -1)
    table = np.concatenate([xyz, np.zeros_like(xyz), f_dc, f_rest, opac[:, None], scale, rot], 1)
    elements = np.empty(n, dtype=[(a, "f4") for a in attrs])
    elements[:] = list(map(tuple, table))
    header = "ply\nformat binary_little_endian 1.0\n" + f"element vertex {n}\n"
    header += "".join(f"property float {a}\n" for a in attrs) + "end_header\n"
    return header.encode("ascii") + elements.tobytes()


def test_reads_and_writes_reference_inria_layout(tmp_path):
    n = 5
    xyz = np.arange(n * 3, dtype=np.float32).reshape(n, 3)
    f_dc = np.full((n, 3), 0.25, np.float32)
    # coefficient k of channel c = 100 c + k: makes the channel-major order visible
    rest = np.array([[[100 * c + k for c in range(3)] for k in range(1, 16)]] * n, np.float32)
    opac = np.linspace(-1, 1, n).astype(np.float32)
    scale = np.full((n, 3), -3.0, np.float32)
    rot = np.tile(np.array([1, 0, 0, 0], np.float32), (n, 1))
    data = _inria_bytes(xyz, f_dc, rest, opac, scale, rot)
    (tmp_path / "ref.ply").write_bytes(data)
    r = read_ply(tmp_path / "ref.ply")
    assert r.degree == 3
    np.testing.assert_array_equal(r.means, xyz)
    np.testing.assert_array_equal(r.sh[:, 0], f_dc)
    assert r.sh[0, 1, 0] == 1 and r.sh[0, 1, 2] == 201 and r.sh[0, 15, 1] == 115
    np.testing.assert_array_equal(r.opacity_logits, opac)
    np.testing.assert_array_equal(r.log_scales, scale)
    np.testing.assert_array_equal(r.quats, rot)
    # and we write byte-identical files
    write_ply(tmp_path / "ours.ply", r)
    assert (tmp_path / "ours.ply").read_bytes() == data


def _custom_ply(path, s: SplatArrays, fmt: str, type_name: str, order: list[int], extra: bool):
    """A 3DGS PLY with shuffled properties, another type, optional extra property and face element."""
    n, k = len(s), s.sh.shape[1]
    cols = {"x": s.means[:, 0], "y": s.means[:, 1], "z": s.means[:, 2],
            "f_dc_0": s.sh[:, 0, 0], "f_dc_1": s.sh[:, 0, 1], "f_dc_2": s.sh[:, 0, 2],
            "opacity": s.opacity_logits}
    for i in range(3):
        cols[f"scale_{i}"] = s.log_scales[:, i]
    for i in range(4):
        cols[f"rot_{i}"] = s.quats[:, i]
    for c in range(3):
        for j in range(k - 1):
            cols[f"f_rest_{c * (k - 1) + j}"] = s.sh[:, j + 1, c]
    if extra:
        cols["red"] = np.full(n, 7.0)
    names = list(cols)
    names = [names[i] for i in order] if order else names
    header = f"ply\nformat {fmt} 1.0\ncomment made by hand\nelement vertex {n}\n"
    header += "".join(f"property {type_name} {a}\n" for a in names)
    if extra:
        header += "element face 1\nproperty list uchar int vertex_indices\n"
    header += "end_header\n"
    if fmt == "ascii":
        body = "".join(" ".join(repr(float(cols[a][i])) for a in names) + "\n" for i in range(n))
        body += "3 0 1 2\n" if extra else ""
        path.write_bytes(header.encode() + body.encode())
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        t = {"double": "f8", "float": "f4"}[type_name]
        arr = np.empty(n, dtype=[(a, e + t) for a in names])
        for a in names:
            arr[a] = cols[a]
        tail = bytes([3]) + np.array([0, 1, 2], e + "i4").tobytes() if extra else b""
        path.write_bytes(header.encode() + arr.tobytes() + tail)


@pytest.mark.parametrize("fmt,type_name", [("binary_little_endian", "double"),
                                           ("binary_big_endian", "float"), ("ascii", "float")])
def test_tolerant_reading(tmp_path, fmt, type_name):
    s = _splats(9, 1, seed=3)
    order = list(np.random.default_rng(1).permutation(14 + 9 + 1))
    _custom_ply(tmp_path / "c.ply", s, fmt, type_name, order, extra=True)
    r = read_ply(tmp_path / "c.ply")
    assert r.degree == 1
    for name in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        np.testing.assert_allclose(getattr(r, name), getattr(s, name), rtol=1e-6, err_msg=name)


def test_missing_property_names_file_and_property(tmp_path):
    s = _splats(4, 0)
    write_ply(tmp_path / "s.ply", s)
    data = (tmp_path / "s.ply").read_bytes().replace(b"property float opacity\n",
                                                     b"property float opacitx\n")
    (tmp_path / "bad.ply").write_bytes(data)
    with pytest.raises(InputError) as e:
        read_ply(tmp_path / "bad.ply")
    assert "bad.ply" in str(e.value) and "'opacity'" in str(e.value)


@pytest.mark.parametrize("content,words", [
    (b"hello world\n", "not a PLY"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n", "end_header"),
    (b"ply\nformat weird 1.0\nend_header\n", "format"),
    (b"ply\nformat ascii 1.0\nelement face 2\nproperty float x\nend_header\n", "vertex"),
])
def test_bad_headers(tmp_path, content, words):
    (tmp_path / "b.ply").write_bytes(content)
    with pytest.raises(InputError, match=words) as e:
        read_ply(tmp_path / "b.ply")
    assert "b.ply" in str(e.value)


def test_truncated_and_bad_sh_count_and_missing_file(tmp_path):
    write_ply(tmp_path / "s.ply", _splats(10, 2))
    data = (tmp_path / "s.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-7])
    with pytest.raises(InputError, match="truncated"):
        read_ply(tmp_path / "t.ply")
    (tmp_path / "r.ply").write_bytes(data.replace(b"property float f_rest_23\n", b""))
    with pytest.raises(InputError, match="f_rest"):
        read_ply(tmp_path / "r.ply")
    with pytest.raises(InputError, match="not found"):
        read_ply(tmp_path / "none.ply")


def test_write_is_atomic_and_checks_shapes(tmp_path):
    write_ply(tmp_path / "s.ply", _splats(3, 0))
    before = (tmp_path / "s.ply").read_bytes()
    bad = _splats(3, 0)
    bad.quats = bad.quats[:, :3]
    with pytest.raises(ValueError, match="quats"):
        write_ply(tmp_path / "s.ply", bad)
    assert (tmp_path / "s.ply").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.ply"]
