"""Captures without masks: the object separated from the room in the static views' depth, its box
written by reconstruct to crop.json, and every frame's mask from the box (against the generator's
true masks)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from artgs.core.geometry.crop_capture import SEPARATION, crop_capture, separation_crop
from artgs.core.geometry.separate import camera_up
from artgs.core.model import layout
from artgs.core.model.cameras import look_at
from artgs.core.model.capture import load_capture
from artgs.core.model.crop import read_crop
from artgs.core.model.joints import read_articulation
from artgs.core.model.progress import Progress
from artgs.core.model.regime import regime
from artgs.core.model.registry import ReconstructOptions
from artgs.core.pipeline import run_stage
from artgs.core.synth.generate import generate_object


def test_up_from_level_cameras_looking_down_from_one_side():
    """Cameras 20-60 degrees above the object, all in its front half: their mean y leans ~25
    degrees toward the object; the x axes give the true up."""
    cams = np.array([look_at(np.array([2 * np.cos(a) * np.cos(e), 2 * np.sin(a) * np.cos(e),
                                       2 * np.sin(e)]), np.zeros(3))
                     for a in np.linspace(-1.2, 1.2, 5) for e in (0.35, 1.0)])
    mean_y = cams[:, :3, 1].sum(0) / np.linalg.norm(cams[:, :3, 1].sum(0))
    assert np.degrees(np.arccos(mean_y[2])) > 15
    assert np.degrees(np.arccos(min(1.0, camera_up(cams) @ [0, 0, 1]))) < 0.01


@pytest.fixture(scope="module")
def roomy(tmp_path_factory):
    """A realistic cabinet in a room (floor, wall, furniture), with its true masks."""
    out = generate_object(tmp_path_factory.mktemp("crop") / "c", "cabinet", 3,
                          regime=regime("realistic"), width=96, height=72, static_views=6,
                          steps=3)
    return out, load_capture(out)


def _unmasked(capture):
    return dataclasses.replace(capture, frames=[dataclasses.replace(f, mask=None)
                                                for f in capture.frames])


def test_box_masks_keep_the_object_and_drop_most_of_the_room(roomy):
    path, truth = roomy
    box, how = separation_crop(_unmasked(truth))
    assert box.source == SEPARATION and how["removed"].get("floor", 0) > 0
    gt = read_articulation(path / "gt.json")
    for j in gt.joints:                          # the closed parts' handles are in the box
        assert box.contains(np.asarray(j.handle["point"], float)[None])[0], j.name
    # the box is the object's: it holds the object's points and is not much bigger than they are
    from artgs.core.geometry.crop_capture import fused_points
    obj = fused_points(truth.static)
    assert box.contains(obj).mean() > 0.9
    span = np.percentile(obj @ box.axes.T, 98, 0) - np.percentile(obj @ box.axes.T, 2, 0)
    assert np.prod(2 * box.half_size) < 3 * np.prod(span), (2 * box.half_size, span)
    cropped = crop_capture(_unmasked(truth), box)
    for phase in ("static", "interaction"):
        pairs = [(c.mask, t.mask) for c, t in zip(cropped.frames, truth.frames)
                 if c.phase == phase]
        recall = np.mean([(c & t).sum() / t.sum() for c, t in pairs])
        room = np.mean([(c & ~t).sum() / (~t).sum() for c, t in pairs])
        assert recall > 0.9, (phase, recall)
        assert room < 0.6, (phase, room)       # the floor and the far room are out
    assert crop_capture(truth, None) is truth
    again = crop_capture(cropped, box)          # applying it twice changes nothing
    assert all(np.array_equal(a.mask, b.mask) for a, b in zip(again.frames, cropped.frames))


def test_reconstruct_writes_the_box_and_later_stages_see_its_masks(roomy, tmp_path):
    path, truth = roomy
    bare = _unmasked(truth)
    out = tmp_path / "out"
    figures = run_stage("reconstruct", out, ReconstructOptions(iterations=3), Progress("quiet"),
                        capture=bare)
    box = read_crop(out)
    assert box is not None and box.source == SEPARATION
    assert figures["separation"]["crop"] == layout.CROP
    assert 0 < figures["separation"]["static_pixels_kept"] < 0.9
    # run again on the capture with its masks: the separation's old box goes (it would crop it)
    run_stage("reconstruct", out, ReconstructOptions(iterations=3), Progress("quiet"),
              capture=truth)
    assert read_crop(out) is None
    run_stage("reconstruct", out, ReconstructOptions(iterations=3), Progress("quiet"),
              capture=bare)
    box = read_crop(out)
    assert box is not None and box.source == SEPARATION
    # a crop.json already in OUT (the user's) is kept as it is
    user = dataclasses.replace(box, source="blender")
    (out / layout.CROP).unlink()
    from artgs.core.model.crop import write_crop
    write_crop(out, user)
    figures = run_stage("reconstruct", out, ReconstructOptions(iterations=3), Progress("quiet"),
                        capture=bare)
    assert "separation" not in figures and read_crop(out).source == "blender"

