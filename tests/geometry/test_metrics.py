"""Joint metrics of shared/spec/metrics.md."""

import numpy as np
import pytest

from artgs.core.model.joints import Joint
from artgs.core.geometry.metrics import axis_error_deg, line_distance, match_joints


def test_axis_error_is_sign_invariant():
    assert axis_error_deg([0, 0, 1], [0, 0, -1]) == pytest.approx(0.0)
    assert axis_error_deg([1, 0, 0], [1, 1, 0]) == pytest.approx(45.0)
    assert axis_error_deg([1, 0, 0], [-1, 1, 0]) == pytest.approx(45.0)
    assert axis_error_deg([1, 0, 0], [0, 1, 0]) == pytest.approx(90.0)


def test_line_distance_skew_and_parallel():
    # skew lines: x-axis and a y-direction line at z = 0.3
    assert line_distance([0, 0, 0], [1, 0, 0], [5, 0, 0.3], [0, 1, 0]) == pytest.approx(0.3)
    # parallel offset lines are never 0
    assert line_distance([0, 0, 0], [0, 0, 1], [0.04, 0.03, 9], [0, 0, -1]) == pytest.approx(0.05)
    assert line_distance([0, 0, 0], [0, 0, 1], [0, 0, 9], [0, 0, 1]) == pytest.approx(0.0)


def test_matching_is_one_to_one_and_penalises_missing():
    t1 = Joint("a", "revolute", [0, 0, 1], [0, 0, 0])
    t2 = Joint("b", "prismatic", [1, 0, 0], [0, 0, 0])
    p1 = Joint("x", "prismatic", [1, 0.02, 0], [1, 1, 1])
    p2 = Joint("y", "revolute", [0, 0.01, 1], [0.02, 0, 0])
    scores = match_joints([p1, p2], [t1, t2])
    assert [s.pred_name for s in scores] == ["y", "x"]
    assert all(s.type_correct for s in scores)
    assert scores[0].origin_error_cm == pytest.approx(2.0, abs=0.01)
    assert scores[1].origin_error_cm is None
    missing = match_joints([p2], [t1, t2])
    assert missing[1].pred_name is None and missing[1].axis_error_deg == 90.0
    assert not missing[1].type_correct
    assert np.isclose(match_joints([], [t1])[0].origin_error_cm, 100.0)
