"""Where the check's gripper comes from: the line the plan moves the handle, not its stored normal."""

from __future__ import annotations

import numpy as np

from artgs.core.model.joints import Joint, joint_transform, motion_direction
from artgs.core.sim.manipulate import _approaches, _facing


def test_motion_direction_is_the_handles_first_motion():
    door = Joint("door", "revolute", np.array([0.0, 0.0, 2.0]), np.array([0.1, 0.2, 0.0]))
    handle = np.array([0.6, 0.2, 0.8])
    step = joint_transform(door.type, door.axis, door.origin, 1e-6) @ np.r_[handle, 1.0]
    expected = (step[:3] - handle) / np.linalg.norm(step[:3] - handle)
    assert np.allclose(motion_direction(door.type, door.axis, door.origin, handle), expected,
                       atol=1e-6)
    assert motion_direction(door.type, door.axis, door.origin, np.array([0.1, 0.2, 0.5])) is None
    slide = motion_direction("prismatic", np.array([0.0, -3.0, 0.0]), np.zeros(3), handle)
    assert np.allclose(slide, [0.0, -1.0, 0.0])


def test_a_lid_is_approached_from_above_by_a_robot_facing_its_hinge():
    """A lid hinged along x at the back (y = 0.4), handle at its front edge: the plan lifts the
    handle, so the gripper first comes down onto it (then from below, pushing); the robot
    stands beyond the handle, facing the hinge, whatever the stored approach says."""
    lid = Joint("lid", "revolute", np.array([-1.0, 0.0, 0.0]), np.array([0.0, 0.4, 0.5]),
                limit=(0.0, 1.5))
    handle = np.array([0.0, -0.1, 0.5])
    first, second = _approaches(lid, handle, 1.0, np.array([0.0, 1.0, 0.0]))
    assert np.allclose(first, [0.0, 0.0, -1.0]) and np.allclose(second, [0.0, 0.0, 1.0])
    assert np.allclose(_facing(lid, handle, first), [0.0, 1.0, 0.0])
    on_axis = _approaches(lid, np.array([0.3, 0.4, 0.5]), 1.0, np.array([0.0, 2.0, 0.0]))
    assert len(on_axis) == 1 and np.allclose(on_axis[0], [0.0, 1.0, 0.0])
