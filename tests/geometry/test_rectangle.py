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
