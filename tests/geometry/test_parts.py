"""Part assignment from the joints' extent boxes: inside/outside, margin, rotation, overlaps."""

from __future__ import annotations

import numpy as np
import pytest

from artgs.core.model.errors import ArtgsError
from artgs.core.model.joints import Joint, rotation_about_axis
from artgs.core.geometry.parts import assign_parts


def _joint(name: str, center, half, axes=np.eye(3), extent: bool = True) -> Joint:
    ext = {"center": list(map(float, center)), "axes": np.asarray(axes).tolist(),
           "half_size": list(map(float, half))} if extent else None
    return Joint(name, "revolute", [0, 0, 1], center, (0, 1.5), extent=ext)


def _uniform_in_box(rng, center, half, axes, n):
    local = rng.uniform(-1, 1, size=(n, 3)) * np.asarray(half)
    return local @ np.asarray(axes) + np.asarray(center)


def test_points_in_rotated_boxes_get_their_joint_and_the_rest_is_base():
    rng = np.random.default_rng(0)
    R = rotation_about_axis(np.array([0.3, 0.2, 1.0]), 0.7)  # rows: rotated box axes
    door = _joint("door", [0.5, 0, 0.5], [0.02, 0.3, 0.5], R)
    drawer = _joint("drawer", [-0.6, 0.1, 0.2], [0.2, 0.25, 0.1])
    pts_door = _uniform_in_box(rng, door.extent["center"], [0.02, 0.3, 0.5], R, 200)
    pts_drawer = _uniform_in_box(rng, drawer.extent["center"], [0.2, 0.25, 0.1], np.eye(3), 200)
    base = rng.uniform(-3, 3, size=(400, 3))
    base = base[np.linalg.norm(base, axis=1) > 2.5]  # far from both boxes
    labels = assign_parts(np.concatenate([pts_door, pts_drawer, base]), [door, drawer])
    assert labels.dtype.kind == "i" and labels.shape == (400 + len(base),)
    np.testing.assert_array_equal(labels[:200], 1)
    np.testing.assert_array_equal(labels[200:400], 2)
    np.testing.assert_array_equal(labels[400:], 0)


def test_margin_is_relative_to_the_largest_half_size_and_follows_the_box_axes():
    R = rotation_about_axis(np.array([0.0, 0.0, 1.0]), np.pi / 4)
    j = _joint("door", [1, 2, 3], [0.01, 0.5, 1.0], R)
    normal = R[0]  # thin direction of the box
    near = np.array([1, 2, 3]) + normal * (0.01 + 0.04)   # within 0.05 * 1.0 of the face
    far = np.array([1, 2, 3]) + normal * (0.01 + 0.06)
    along_world_x = np.array([1, 2, 3]) + np.array([0.2, 0, 0])  # outside: box is rotated
    labels = assign_parts(np.stack([near, far, along_world_x]), [j])
    np.testing.assert_array_equal(labels, [1, 0, 0])
    np.testing.assert_array_equal(assign_parts(np.stack([near, far]), [j], margin=0.0), [0, 0])


def test_overlap_goes_to_the_smaller_box_then_the_nearer_centre():
    big = _joint("door", [0, 0, 0], [1, 1, 1])
    small = _joint("drawer", [0.5, 0, 0], [0.2, 0.2, 0.2])
    twin = _joint("twin", [0.7, 0, 0], [0.2, 0.2, 0.2])
    pts = np.array([[0.45, 0, 0], [0.65, 0, 0], [-0.5, 0, 0], [0.58, 0, 0]])
    np.testing.assert_array_equal(assign_parts(pts, [big, small]), [2, 2, 1, 2])
    np.testing.assert_array_equal(assign_parts(pts, [small, big]), [1, 1, 2, 1])
    # equal boxes: nearest centre (0.45 -> small, 0.65 -> twin, 0.58 -> small)
    np.testing.assert_array_equal(assign_parts(pts, [big, small, twin]), [2, 3, 1, 2])


def test_joints_without_extent_get_no_points():
    j = _joint("door", [0, 0, 0], [1, 1, 1], extent=False)
    k = _joint("drawer", [0, 0, 0], [1, 1, 1])
    np.testing.assert_array_equal(assign_parts(np.zeros((3, 3)), [j]), [0, 0, 0])
    np.testing.assert_array_equal(assign_parts(np.zeros((2, 3)), [j, k]), [2, 2])
    assert assign_parts(np.zeros((0, 3)), [k]).shape == (0,)


def test_bad_extent_names_joint_and_field():
    j = _joint("door", [0, 0, 0], [1, 1, 1])
    j.extent = {"center": [0, 0, 0], "half_size": [1, 1, 1]}
    with pytest.raises(ArtgsError, match=r"joint 'door', field 'extent'"):
        assign_parts(np.zeros((1, 3)), [j])
    j.extent = {"center": [0, 0, 0], "axes": np.zeros((3, 3)).tolist(), "half_size": [1, 1, 1]}
    with pytest.raises(ArtgsError, match=r"joint 'door', field 'extent'"):
        assign_parts(np.zeros((1, 3)), [j])
