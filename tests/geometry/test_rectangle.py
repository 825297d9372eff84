"""The smallest-area box of planar points: the sides of a turned rectangle, despite strays."""

import numpy as np

from artgs.core.geometry.rectangle import smallest_rectangle


def test_a_turned_rectangle_gives_its_sides_and_size() -> None:
    rng = np.random.default_rng(0)
    local = np.c_[rng.uniform(0, 0.6, 5000), rng.uniform(0, 1.0, 5000)]
    t = np.radians(23.0)
    R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    xy = np.r_[local @ R.T, rng.uniform(-3, 3, (20, 2))]        # 20 stray points far out
    angle, lo, hi = smallest_rectangle(xy, limit=2000)
    assert abs(np.degrees(angle) - 23.0) <= 1.5      # 1 deg steps
    assert np.allclose(hi - lo, [0.6, 1.0], atol=0.04)


def test_an_upright_boxs_axes_are_its_up_and_its_footprints_sides() -> None:
    """Points of a box turned 23.4 degrees about a tilted up give that up exactly and the box's
    sides within a degree (the trimmed boxes' area is flat within about a degree of the sides:
    the few points their corners cut); a drum gives up only."""
    from scipy.spatial.transform import Rotation

    from artgs.core.geometry.rectangle import upright_axes

    rng = np.random.default_rng(1)
    box = rng.uniform([0, 0, 0], [0.6, 0.4, 0.9], (20000, 3))
    tilt = Rotation.from_rotvec([0.05, -0.03, 0.0]).as_matrix()
    turn = Rotation.from_rotvec([0, 0, np.radians(23.4)]).as_matrix()
    R = tilt @ turn
    axes = upright_axes(box @ R.T, R[:, 2])
    assert axes.shape == (3, 3)
    assert np.allclose(axes[0], R[:, 2])
    for true in R.T:
        assert np.degrees(np.arccos(min(np.max(np.abs(axes @ true)), 1.0))) < 1.0
    t = rng.uniform(0, 2 * np.pi, 20000)
    drum = np.c_[0.3 * np.cos(t), 0.3 * np.sin(t), rng.uniform(0, 0.9, 20000)]
    assert np.allclose(upright_axes(drum, [0, 0, 1]), [[0, 0, 1]])
