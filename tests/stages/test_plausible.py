"""A part's motion must keep it out of the body: the static views' depth tells opening from
closing (core/stages/optimise/plausible.py), and the optimisation's grasp handle follows the fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from artgs.core.geometry.parts import assign_parts
from artgs.core.model.capture import Frame, load_capture
from artgs.core.model.cameras import Camera, intrinsics, look_at
from artgs.core.model.joints import Joint, read_articulation, rotation_about_axis
from artgs.core.model.regime import regime
from artgs.core.stages.optimise.hypotheses import (PROBE_SPREAD_DEG, box_edges, distinct,
                                                face_edges, probed)
from artgs.core.stages.optimise.plausible import HIDDEN_SHARE, into_body, open_space
from artgs.core.stages.optimise.stage import handle_holds, object_size
from artgs.core.stages.reconstruct import initial_splats
from artgs.core.synth.generate import generate_object

SIZE = {"width": 64, "height": 48, "static_views": 8, "steps": 3}


@pytest.fixture(scope="module", params=["cabinet", "chest"])
def capture(request, tmp_path_factory) -> Path:
    """A cabinet (door + drawer) and a chest (lid), far noisy cameras for the chest."""
    root = tmp_path_factory.mktemp("plausible")
    if request.param == "chest":
        return generate_object(root / "chest", "chest", 0, regime=regime("realistic"), **SIZE)
    return generate_object(root / "cabinet", "cabinet", 1, **SIZE)


def test_opening_goes_into_space_closing_into_the_body(capture):
    cap = load_capture(capture)
    gt = read_articulation(capture / "gt.json")
    means = initial_splats(cap.static)[0].means.astype(float)
    space = open_space(cap.static, object_size(means))
    labels = assign_parts(means, gt.joints)
    for k, j in enumerate(gt.joints):
        pts = means[labels == k + 1]
        assert len(pts) > 20, j.name
        opening = 0.8 * j.limit[1]
        out = space.hidden_share(j.type, j.axis, j.origin, opening, pts)
        into = space.hidden_share(j.type, j.axis, j.origin, -opening, pts)
        assert out < HIDDEN_SHARE < into, (j.name, out, into)
        assert into_body(space, j.type, j.axis, j.origin, np.array([0.0, -opening]), pts) > \
            HIDDEN_SHARE
        assert into_body(space, j.type, j.axis, j.origin, np.array([0.0, opening]), pts) == 0.0
        assert space.hidden_share(j.type, j.axis, j.origin, 0.0, pts) == 0.0


def _floor_view(eye) -> Frame:
    """A 64x48 view of the bare floor z = 0 from ``eye``, its exact depth."""
    cam = Camera(intrinsics(60.0, 60.0, 32.0, 24.0), look_at(np.asarray(eye, float), np.zeros(3)),
                 64, 48)
    rays = cam.pixel_rays() @ np.linalg.inv(cam.w2c)[:3, :3].T      # world, per unit depth
    depth = (-cam.center[2] / rays[..., 2]).astype(np.float32)
    depth[~(depth > 0)] = 0.0
    return Frame(0, "floor.png", cam, np.zeros((48, 64, 3), np.uint8), depth, None)


def test_a_part_hidden_both_ways_is_not_judged_into_the_body():
    """A board hinged 3 cm under a floor the static views saw (an oven door opening flat onto
    the floor, its fit a little low) is hidden turned either way: the views cannot tell a body
    from the floor, so neither way goes into the body. Pushed down through the floor it is
    hidden where pulled up it is not: into the body."""
    space = open_space([_floor_view([0.0, -1.5, 0.4]), _floor_view([1.0, 1.2, 0.5]),
                        _floor_view([0.1, 0.2, 1.5])], size=0.5)
    grid = np.stack(np.meshgrid(np.linspace(-0.2, 0.2, 9), [0.0],
                                np.linspace(0.05, 0.4, 8)), -1).reshape(-1, 3)
    x, hinge = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, -0.03])
    for turn in (np.pi / 2, -np.pi / 2):
        assert space.hidden_share("revolute", x, hinge, turn, grid) > HIDDEN_SHARE
        assert into_body(space, "revolute", x, hinge, np.array([0.0, turn]), grid) == 0.0
    z = np.array([0.0, 0.0, 1.0])
    assert into_body(space, "prismatic", z, hinge, np.array([-0.5]), grid) > HIDDEN_SHARE
    assert into_body(space, "prismatic", z, hinge, np.array([0.5]), grid) == 0.0


def _joint(kind: str, point) -> Joint:
    return Joint(name="door", type=kind, axis=np.array([0.0, 0.0, 1.0]),
                 origin=np.zeros(3), handle={"point": list(point), "approach": [1.0, 0, 0]})


def test_start_handle_kept_only_on_the_fitted_part_of_the_same_type():
    pts = np.random.default_rng(0).uniform([0, 0, 0], [0.02, 0.4, 0.6], size=(500, 3))
    on, off = [0.01, 0.3, 0.3], [0.01, 0.3, 0.9]
    assert handle_holds(_joint("revolute", on), "revolute", pts, size=1.0)
    assert not handle_holds(_joint("prismatic", on), "revolute", pts, size=1.0)
    assert not handle_holds(_joint("revolute", off), "revolute", pts, size=1.0)
    assert not handle_holds(None, "revolute", pts, size=1.0)


def test_probes_are_distinct_starts() -> None:
    """Of ranked hypotheses, one within PROBE_SPREAD_DEG of a better one (either sign) is the
    same start; hinges along the same direction on other lines are not."""
    z, x = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    near = rotation_about_axis(x, np.radians(PROBE_SPREAD_DEG - 5)) @ -z
    far = rotation_about_axis(x, np.radians(PROBE_SPREAD_DEG + 5)) @ z
    o = np.zeros(3)
    ranked = [(0.1, z, o), (0.2, near, o), (0.3, far, o), (0.4, x, o)]
    assert [h[0] for h in distinct(ranked, "prismatic", 1.0)] == [0.1, 0.3, 0.4]
    hinges = [(0.1, z, o), (0.2, -z, o + [0.01, 0, 0.3]), (0.3, z, o + [0.5, 0, 0])]
    assert [h[0] for h in distinct(hinges, "revolute", 1.0)] == [0.1, 0.3]
    # the best three are probed, and the best other start when those three are one start
    assert [h[0] for h in probed(ranked, "prismatic", 1.0)] == [0.1, 0.2, 0.3]
    one = [(0.1, z, o), (0.2, near, o), (0.25, -z, o), (0.3, far, o), (0.4, x, o)]
    assert [h[0] for h in probed(one, "prismatic", 1.0)] == [0.1, 0.2, 0.25, 0.3]


def test_a_piece_of_a_door_gets_the_hinge_of_its_face() -> None:
    """The free-edge half of a door (the part the frames show moving most) has its own box edges
    through the door's middle; the edges of the face it lies in include the true hinge, also
    with the object turned in space (the face's sides, not the object's principal axes)."""
    rng = np.random.default_rng(0)
    face = np.c_[rng.normal(0, 0.002, 4000), rng.uniform(0, 0.6, 4000), rng.uniform(0, 1, 4000)]
    body = np.c_[rng.uniform(-0.5, -0.05, 3000), rng.uniform(0, 0.6, 3000),
                 rng.uniform(0, 1, 3000)]
    piece = face[face[:, 1] > 0.35]
    for R in (np.eye(3), rotation_about_axis(np.array([1.0, 2.0, 3.0]) / np.sqrt(14), 0.7)):
        hinge = R @ np.array([0.0, 0.0, 1.0])
        # a line (d, p) parallel to the hinge passes |hinge x p| from it (it runs through 0)
        hinges = [np.linalg.norm(np.cross(hinge, p)) for d, p in
                  face_edges(np.r_[face, body] @ R.T, piece @ R.T, 0.01) if abs(d @ hinge) > 0.999]
        assert hinges and min(hinges) < 0.02
    own = [np.linalg.norm(np.cross(d, p)) for d, p in box_edges(piece, np.eye(3))
           if abs(d[2]) > 0.99]
    assert min(own) > 0.3
