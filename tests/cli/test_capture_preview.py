"""``artgs capture-preview`` (no bpy): the .npz Import Capture reads, against the loaded capture."""

from __future__ import annotations

import json

import numpy as np
import pytest

from artgs.core.model.capture import load_capture, summarize
from artgs.core.model.capture_preview import KEYS, read_preview, write_preview
from artgs.core.cli import main
from artgs.core.model.errors import InputError
from artgs.core.synth.generate import generate_object


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    return generate_object(tmp_path_factory.mktemp("cap") / "drawer", "drawer", 1, width=64,
                           height=48, static_views=4, steps=2)


def _full_points(cap) -> tuple[np.ndarray, np.ndarray]:
    pts, cols = [], []
    for f in cap.static:
        world, idx = f.camera.backproject(f.depth, f.mask)
        pts.append(world)
        cols.append(f.rgb.reshape(-1, 3)[idx])
    return np.concatenate(pts), np.concatenate(cols)


def test_cli_writes_cameras_points_and_summary(capture, tmp_path, capsys):
    path = tmp_path / "p.npz"
    assert main(["capture-preview", str(capture), "--preview", str(path), "--json"]) == 0
    events = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    cap = load_capture(capture)
    preview = read_preview(path)
    with np.load(path, allow_pickle=False) as data:  # plain arrays only
        assert sorted(data.files) == sorted(KEYS)
    n = len(cap.frames)
    assert preview.K.shape == (n, 3, 3) and preview.c2w.shape == (n, 4, 4)
    for i, f in enumerate(cap.frames):
        np.testing.assert_array_equal(preview.K[i], f.camera.K)
        np.testing.assert_array_equal(preview.c2w[i], f.camera.c2w)
        assert (preview.width[i], preview.height[i]) == (f.camera.width, f.camera.height)
        assert (preview.phase[i], preview.file_path[i]) == (f.phase, f.file_path)
        assert preview.time[i] == (-1 if f.time is None else f.time)
    full, colours = _full_points(cap)
    assert preview.points_total == len(full) == len(preview.points) < 200_000
    np.testing.assert_allclose(preview.points, full, atol=1e-5)
    np.testing.assert_array_equal(preview.colors, colours)
    fx = cap.static[0].camera.K[0, 0]
    depth = np.concatenate([f.depth[f.mask & (f.depth > 0)] for f in cap.static])
    np.testing.assert_allclose(preview.radius, 0.5 * depth / fx, rtol=1e-6)
    assert preview.summary == json.loads(json.dumps(summarize(cap)))
    assert events[-1]["event"] == "finished" and events[-1]["outputs"]["points"] == len(full)


def test_cap_is_a_deterministic_subset(capture, tmp_path):
    cap = load_capture(capture)
    full = _full_points(cap)[0]
    a = write_preview(cap, tmp_path / "a.npz", 300)
    b = read_preview(tmp_path / "a.npz")
    write_preview(cap, tmp_path / "b.npz", 300)
    assert len(a.points) == 300 and a.points_total == len(full)
    np.testing.assert_array_equal(b.points, read_preview(tmp_path / "b.npz").points)
    nearest = np.linalg.norm(b.points[:, None, :] - full[None], axis=2).min(axis=1)
    assert nearest.max() < 1e-5  # every kept point is one of the full preview's
    assert len(np.unique(b.points, axis=0)) == 300
    thinning = np.sqrt(len(full) / 300)
    assert b.radius.min() > thinning * 0.5 * 1.0 / cap.static[0].camera.K[0, 0]


def test_bad_capture_or_cap_writes_nothing(capture, tmp_path, capsys):
    path = tmp_path / "p.npz"
    tj = json.loads((capture / "transforms.json").read_text())
    tj["frames"][2]["transform_matrix"] = [[1, 0, 0], [0, 1, 0]]
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "transforms.json").write_text(json.dumps(tj))
    assert main(["capture-preview", str(bad), "--preview", str(path), "--json"]) == 2
    error = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert error["event"] == "error"
    assert str(bad / "transforms.json") in error["message"]
    assert "frame 2" in error["message"] and "'transform_matrix'" in error["message"]
    assert main(["capture-preview", str(capture), "--preview", str(path), "--max-points", "0",
                 "--quiet"]) == 2
    assert list(tmp_path.glob("*.npz")) == [] and list(tmp_path.glob(".p.*")) == []


def test_foreign_file_is_refused_by_name(tmp_path):
    path = tmp_path / "p.npz"
    np.savez(path, K=np.eye(3))
    with pytest.raises(InputError, match="another version of the engine") as err:
        read_preview(path)
    assert str(path) in str(err.value) and "c2w" in str(err.value)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="junk.npz"):
        read_preview(tmp_path / "junk.npz")
