"""The contact sheet's layout (core/render/contact_sheet.py): grid size, labels, fitted strips.
The whole sheet from a real pipeline run is checked in test_addon_pipeline.py."""

from __future__ import annotations

import numpy as np
import pytest

from artgs.core.render.contact_sheet import LABEL_HEIGHT, Panel, _fit, posed, sheet
from artgs.core.model.joints import Joint
from artgs.core.model.ply import SplatArrays


@pytest.mark.parametrize("n,columns", [(2, 2), (4, 2), (6, 3)])
def test_sheet_grid_and_labels(n, columns):
    panels = [Panel(f"p{k}", f"Panel {k}", np.full((30, 40, 3), 40 * k, np.uint8)) for k in range(n)]
    img = sheet(panels, gap=4)
    rows = -(-n // columns)
    assert img.shape == (rows * (30 + LABEL_HEIGHT) + (rows + 1) * 4, columns * 40 + (columns + 1) * 4, 3)
    for k in range(n):
        r, c = divmod(k, columns)
        y, x = 4 + r * (30 + LABEL_HEIGHT + 4), 4 + c * 44
        tile = img[y:y + 30 + LABEL_HEIGHT, x:x + 40]
        assert (tile[:LABEL_HEIGHT].max(axis=2) > 150).any()  # the label's text
        assert np.all(tile[LABEL_HEIGHT:] == 40 * k)          # the picture, untouched


def test_fit_keeps_the_aspect_ratio():
    strip = np.full((10, 100, 3), 200, np.uint8)  # a wide strip of check frames
    out = _fit(strip, (60, 40))
    assert out.shape == (40, 60, 3)
    filled = np.argwhere(out[:, :, 0] == 200)
    assert filled[:, 1].min() == 0 and filled[:, 1].max() == 59  # full width
    assert filled[:, 0].max() - filled[:, 0].min() + 1 == 6      # 10 * 0.6 rows, centred


def test_posed_moves_only_each_joints_part():
    n = 4
    splats = SplatArrays(np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32),
                         np.tile(np.float32([1, 0, 0, 0]), (n, 1)), np.zeros((n, 3), np.float32),
                         np.zeros(n, np.float32), np.zeros((n, 1, 3), np.float32))
    hinge = Joint("door", "revolute", [0, 0, 1], [0, 0, 0], (0.0, np.pi / 2))
    slide = Joint("drawer", "prismatic", [0, 0, 1], [0, 0, 0], (0.0, 0.3))
    out = posed(splats, [hinge, slide], np.array([1, 0, 2, 0]))
    np.testing.assert_allclose(out.means, [[0, 1, 0], [1, 0, 0], [0, 1, 0.3], [0, 0, 1]], atol=1e-6)
    # the rotated Gaussian's orientation turns with it: 90 degrees about z
    np.testing.assert_allclose(out.quats[0], [np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)], atol=1e-6)
    np.testing.assert_array_equal(out.quats[1], [1, 0, 0, 0])
