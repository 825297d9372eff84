"""articulation.json schema: round trip, validation messages, joint transforms."""

import json
import math

import numpy as np
import pytest

from artgs.core.model.errors import InputError
from artgs.core.model.joints import (Articulation, Joint, joint_transform, read_articulation,
                               rotation_about_axis, write_articulation)


def _door() -> Joint:
    return Joint("door", "revolute", [0, 0, 2.0], [0.21, 0.0, 0.4], (0.0, 1.57),
                 states={0: 0.0, 1: 0.12}, source="motion", confidence=0.9,
                 handle={"point": [0.5, 0.1, 0.4], "approach": [0, -1, 0]})


def test_round_trip_keeps_every_field(tmp_path):
    art = Articulation([_door(), Joint("drawer", "prismatic", [1, 0, 0], [0, 0, 0], (0, 0.3))],
                       {"method": "motion"})
    path = tmp_path / "articulation.json"
    write_articulation(path, art)
    data = json.loads(path.read_text())
    assert data["frame"] == "world" and data["method"] == "motion"
    assert data["joints"][0]["axis"] == [0.0, 0.0, 1.0]          # normalised
    assert data["joints"][0]["states"] == {"0": 0.0, "1": 0.12}
    assert data["joints"][1]["child"] == "drawer_link"
    back = read_articulation(path)
    assert [j.name for j in back.joints] == ["door", "drawer"]
    assert back.joints[0].states == {0: 0.0, 1: 0.12}
    assert back.joints[0].handle == _door().handle
    np.testing.assert_allclose(back.joints[0].origin, [0.21, 0.0, 0.4])
    assert back.meta == {"method": "motion"}


def test_unknown_keys_survive(tmp_path):
    path = tmp_path / "a.json"
    d = _door().to_dict()
    d["my_note"] = "keep me"
    path.write_text(json.dumps({"frame": "world", "joints": [d]}))
    assert read_articulation(path).joints[0].to_dict()["my_note"] == "keep me"


@pytest.mark.parametrize("field,value,words", [
    ("type", "ball", "type"), ("axis", [0, 0, 0], "non-zero"), ("axis", [1, 2], "three"),
    ("origin", [0, "x", 0], "origin"), ("limit", [1.0, 0.0], "above"), ("limit", [0], "two numbers"),
    ("states", {"a": 1.0}, "integer"), ("source", "guess", "source"),
])
def test_bad_joint_names_file_joint_and_field(tmp_path, field, value, words):
    d = _door().to_dict()
    d[field] = value
    path = tmp_path / "proposals.json"
    path.write_text(json.dumps({"joints": [d]}))
    with pytest.raises(InputError) as err:
        read_articulation(path)
    msg = str(err.value)
    assert str(path) in msg and "joint 0 ('door')" in msg and f"'{field}'" in msg and words in msg


def test_missing_file_duplicate_names_and_bad_json(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_articulation(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(InputError, match="not valid JSON"):
        read_articulation(bad)
    dup = tmp_path / "dup.json"
    dup.write_text(json.dumps({"joints": [_door().to_dict(), _door().to_dict()]}))
    with pytest.raises(InputError, match="repeated"):
        read_articulation(dup)


def test_revolute_transform_fixes_the_axis_line_and_rotates():
    axis, origin = np.array([0.0, 0.0, 1.0]), np.array([1.0, 2.0, 0.0])
    T = joint_transform("revolute", axis, origin, math.pi / 2)
    on_axis = np.array([1.0, 2.0, 5.0, 1.0])
    np.testing.assert_allclose(T @ on_axis, on_axis, atol=1e-12)
    p = np.array([2.0, 2.0, 0.0, 1.0])                       # 1 m along +x from the axis
    np.testing.assert_allclose(T @ p, [1.0, 3.0, 0.0, 1.0], atol=1e-12)
    R = rotation_about_axis([1, 1, 0], 0.7)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)


def test_prismatic_transform_translates_along_axis():
    T = Joint("d", "prismatic", [0, 3, 0], [5, 5, 5]).transform(0.25)
    np.testing.assert_allclose(T[:3, 3], [0, 0.25, 0])
    np.testing.assert_allclose(T[:3, :3], np.eye(3))


def test_a_handle_is_approached_against_the_motion_that_opens_its_part():
    """A door on a vertical hinge at x = 0, handle at x = 0.5 on its front (y = 0): opened by a
    positive angle the handle first moves to +y, so the gripper comes from +y towards -y;
    opened by a negative one, the other way; a handle on the hinge's line has no such
    direction, nor does a part that never opens."""
    from artgs.core.model.joints import opening_approach

    axis, origin, handle = np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0.5, 0.0, 0.3])
    assert np.allclose(opening_approach("revolute", axis, origin, handle, 1.2), [0, -1, 0])
    assert np.allclose(opening_approach("revolute", axis, origin, handle, -1.2), [0, 1, 0])
    assert np.allclose(opening_approach("prismatic", [0, 2.0, 0], origin, handle, 0.3),
                       [0, -1, 0])
    assert opening_approach("revolute", axis, origin, np.array([0.0, 0.0, 0.7]), 1.0) is None
    assert opening_approach("revolute", axis, origin, handle, 0.0) is None
