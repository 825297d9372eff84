"""Parts the robot was seen opening: the joint of a run of the tool path, and whether a fitted
joint already explains it (core/stages/optimise/missed.py)."""

from __future__ import annotations

import numpy as np

from artgs.core.geometry.metrics import score_pair
from artgs.core.model.joints import Joint, joint_transform
from artgs.core.stages.optimise.missed import tool_joint


def _path(kind: str, axis, origin, values, grasp) -> np.ndarray:
    return np.array([(joint_transform(kind, np.asarray(axis, float), np.asarray(origin, float), v)
                      @ np.append(grasp, 1.0))[:3] for v in values])


def test_a_run_on_a_circle_gives_its_hinge_and_angles():
    """A grasp point carried 70 deg about a tilted hinge, with 3 mm of noise: the hinge comes
    back within 3 deg and 1 cm, its values within 2 deg of the truth, opening positive; the
    same path backwards gives the opposite axis, so the values stay positive."""
    rng = np.random.default_rng(3)
    axis = np.array([0.1, -0.05, 1.0]) / np.linalg.norm([0.1, -0.05, 1.0])
    origin = np.array([0.3, -0.4, 0.5])
    values = np.radians(np.linspace(0.0, 70.0, 8))
    path = _path("revolute", axis, origin, values, [0.75, -0.3, 0.6])
    path += rng.normal(0.0, 0.003, path.shape)
    kind, a, p, v = tool_joint(path, 1.0)
    assert kind == "revolute"
    s = score_pair(Joint(name="t", type=kind, axis=a, origin=p),
                   Joint(name="g", type="revolute", axis=axis, origin=origin))
    assert s.axis_error_deg < 3.0 and s.origin_error_cm < 1.0, s
    assert a @ axis > 0 and np.all(np.abs(v - values) < np.radians(2.0)), np.degrees(v)
    kind, b, _, w = tool_joint(path[::-1], 1.0)
    assert b @ axis < 0 and w[-1] > np.radians(65.0)


def test_a_run_on_a_line_gives_its_slide():
    """A drawer's handle pulled 30 cm: a slide along the pull within 1 deg, its values the
    distances from the first position (to 5 mm)."""
    rng = np.random.default_rng(4)
    axis = np.array([0.9, 0.3, 0.0]) / np.linalg.norm([0.9, 0.3, 0.0])
    values = np.linspace(0.0, 0.3, 7)
    path = _path("prismatic", axis, [0.0, 0.0, 0.0], values, [0.2, 0.1, 0.4])
    path += rng.normal(0.0, 0.002, path.shape)
    kind, a, _, v = tool_joint(path, 1.0)
    assert kind == "prismatic"
    assert np.degrees(np.arccos(min(1.0, a @ axis))) < 1.0
    assert np.all(np.abs(v - values) < 0.005)


def test_run_states_offer_the_ends_continued():
    """A hand that grasped between two frames: the run's first position is already one step into
    the opening and its last a step short; among the candidates is the true opening at every
    time (0 before the run, held after it)."""
    from artgs.core.stages.optimise.missed import run_states

    truth = np.array([0.0, 0.0, 0.3, 0.6, 0.9, 1.2, 1.2])
    along = np.array([0.0, 0.3, 0.6, 0.8])        # read at times 2..5, from the first position
    candidates = run_states(along, [2, 3, 4, 5], list(range(7)))
    assert len(candidates) == 4
    assert any(np.allclose(c, truth) for c in candidates)
    assert np.allclose(candidates[0], [0.0, 0.0, 0.0, 0.3, 0.6, 0.8, 0.8])


def test_a_turning_hand_on_a_short_arc_is_a_hinge():
    """12 deg of a 1.2 m wide door with 2 mm of noise: the arc is nearly a line, but the
    approach of the hand that holds the handle turned with it, so the run is the hinge, within 1 deg and 3 cm, its
    angles within 0.5 deg; the same path without the approach is a slide."""
    from artgs.core.model.joints import rotation_about_axis

    rng = np.random.default_rng(5)
    axis, origin = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.3])
    values = np.radians(np.linspace(0.0, 12.0, 6))
    path = _path("revolute", axis, origin, values, [0.3, 1.2, 0.3])
    path += rng.normal(0.0, 0.002, path.shape)
    assert tool_joint(path, 1.0)[0] == "prismatic"
    # the hand's approach turns with the door (its roll about the approach is free: ignored)
    approach = np.stack([rotation_about_axis(axis, v) @ [0.0, -0.6, 0.8] for v in values])
    kind, a, p, v = tool_joint(path, 1.0, approach)
    s = score_pair(Joint(name="t", type=kind, axis=a, origin=p),
                   Joint(name="g", type="revolute", axis=axis, origin=origin))
    assert kind == "revolute" and s.axis_error_deg < 1.0 and s.origin_error_cm < 3.0, s
    assert np.all(np.abs(v - values) < np.radians(0.5))


def _held_model(joint: Joint, times: list[int]):
    """An ArticulatedSplat of 200 random Gaussians with the one joint ``joint``."""
    import torch
    from artgs.core.model.ply import SplatArrays
    from artgs.core.stages.optimise.model import ArticulatedSplat, Splat

    rng = np.random.default_rng(6)
    n = 200
    arrays = SplatArrays(rng.normal(0, 0.2, (n, 3)), np.tile([1.0, 0, 0, 0], (n, 1)),
                         np.full((n, 3), np.log(0.03)), np.full(n, 2.0),
                         rng.normal(0, 0.5, (n, 1, 3)))
    return ArticulatedSplat(Splat.from_arrays(arrays, torch.device("cpu")), [joint], times,
                            np.arange(n) % 2, 1.0, [False])


def test_the_tool_path_term_pins_the_joint_it_held():
    """A hinge held along 60 deg of its turn: the tool path term (model.held_loss) is ~0 at the
    true joint and states, and descending it alone from a start 10 deg and 8 cm off, states
    included, brings the hinge back within 0.5 deg and 0.5 cm (gradients reach axis, point and
    states); the joint's tool residual falls from centimetres to under a millimetre. Dropping
    the joint drops what it held."""
    import torch

    axis, origin = np.array([0.0, 0.1, 1.0]) / np.linalg.norm([0.0, 0.1, 1.0]), np.array([0.3, -0.2, 0.0])
    times = list(range(7))
    values = np.radians([0.0, 0.0, 12.0, 24.0, 36.0, 48.0, 60.0])
    truth = Joint(name="door", type="revolute", axis=axis, origin=origin,
                  states=dict(zip(times, values)))
    path = _path("revolute", axis, origin, values[1:], [0.9, 0.3, 0.4])
    model = _held_model(truth, times)
    model.hold("door", times[1:], path)
    assert float(model.held_loss(0.01, 0.2)) < 1e-6 and model.held_residual(0) < 1e-5

    start = Joint(name="door", type="revolute", origin=origin + [0.05, 0.06, 0.0],
                  axis=np.array([np.sin(np.radians(10.0)), 0.1, 1.0]),
                  states=dict(zip(times, 0.8 * values)))
    model = _held_model(start, times)
    model.hold("door", times[1:], path)
    assert model.held_residual(0) > 0.02
    params = [model.axes.requires_grad_(), model.origins.requires_grad_(),
              model.states.requires_grad_()]
    opt = torch.optim.Adam(params, lr=0.003)
    for _ in range(1500):
        opt.zero_grad()
        model.held_loss(0.01, 0.2).backward()
        opt.step()
    s = score_pair(Joint(name="t", type="revolute", axis=model.joint_lines()[0][0],
                         origin=model.joint_lines()[1][0]), truth)
    assert s.axis_error_deg < 0.5 and s.origin_error_cm < 0.5, s
    assert model.held_residual(0) < 1e-3
    model.drop(0)
    assert not model.held


def test_the_hands_turn_pins_a_short_arcs_radius():
    """10 deg of a door 0.7 m wide, positions with 2 mm of noise: they fit a hinge 20 % farther
    out with angles 20 % smaller almost as well (the start below), and hinges tilted far off
    too; the hand's approach, which turned with the door by the door's angle, pins the angles
    and so the radius: descending the tool term with the approaches brings the hinge within 2
    deg and 1.5 cm (1.5 deg / 0.1 cm); without them it ends over 10 deg off (34 deg)."""
    import torch
    from artgs.core.model.joints import rotation_about_axis

    axis, origin = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 0.0])
    times = list(range(6))
    values = np.radians([0.0, 2.0, 4.0, 6.0, 8.0, 10.0])
    truth = Joint(name="door", type="revolute", axis=axis, origin=origin)
    path = _path("revolute", axis, origin, values, [0.1, 0.3, 0.7])
    path += np.random.default_rng(7).normal(0.0, 0.002, path.shape)
    approach = np.stack([rotation_about_axis(axis, v) @ [-1.0, 0.0, 0.0] for v in values])
    errors = {}
    for turns in (approach, None):
        start = Joint(name="door", type="revolute", axis=axis, origin=[-0.02, 0.0, -0.14],
                      states=dict(zip(times, values / 1.2)))
        model = _held_model(start, times)
        model.hold("door", times, path, turns)
        params = [model.axes.requires_grad_(), model.origins.requires_grad_(),
                  model.states.requires_grad_()]
        opt = torch.optim.Adam(params, lr=0.002)
        decay = torch.optim.lr_scheduler.ExponentialLR(opt, 0.997)
        for _ in range(1500):
            opt.zero_grad()
            model.held_loss(0.01, 0.2).backward()
            opt.step()
            decay.step()
        errors[turns is None] = score_pair(Joint(name="t", type="revolute",
                                                 axis=model.joint_lines()[0][0],
                                                 origin=model.joint_lines()[1][0]), truth)
    assert errors[False].axis_error_deg < 2.0 and errors[False].origin_error_cm < 1.5, errors
    assert errors[True].axis_error_deg > 10.0, errors


def test_a_joint_carries_the_runs_it_moved_along_not_a_reach():
    """A door held 40 deg along its hinge carries that run; the same door at rest does not
    carry a 4 cm reach of the hand towards its handle (within 5 % of the object's size, but
    not within half of how far the hand went), so the tool term cannot pull it along a reach;
    and it carries no run read off the path as a slide."""
    from artgs.core.stages.optimise.missed import carried_runs

    axis, origin = np.array([0.0, 0.0, 1.0]), np.array([0.3, -0.2, 0.0])
    times = list(range(10))
    values = np.radians([0.0] * 5 + [10.0, 20.0, 30.0, 40.0, 40.0])
    door = Joint(name="door", type="revolute", axis=axis, origin=origin,
                 states=dict(zip(times, values)))
    grasp = np.array([0.9, 0.3, 0.4])
    reach = grasp + np.outer(np.linspace(0.04, 0.0, 5), [0.0, -1.0, 0.0])
    path = np.concatenate([reach, _path("revolute", axis, origin, values[5:], grasp)])
    runs = [np.arange(0, 5), np.arange(4, 9)]
    errors, held = carried_runs(_held_model(door, times), runs, path, times,
                                ["prismatic", "revolute"])
    assert held.tolist() == [[False, True]], errors
    assert errors[0, 1] < 1e-6 and errors[0, 0] > 0.039
    # read off the path as a slide (a short arc whose hand did not turn): not this hinge's
    _, held = carried_runs(_held_model(door, times), runs, path, times,
                           ["prismatic", "prismatic"])
    assert not held.any()


def test_a_jump_to_another_handle_ends_a_run():
    """Two drawers pulled one after the other, 53 cm apart: their slides lie on one wide circle
    within the runs' tolerance, so only the hand's jump between the handles (a step over 5 %
    of the size and 4 times the run's longest) tells them apart: two runs, not one."""
    from artgs.core.stages.optimise.hypotheses import tool_segments

    pull = np.array([0.877, 0.481, 0.0])
    lower = np.array([0.5, 0.1, 0.27]) + np.outer(np.arange(6) * 0.005, pull)
    upper = np.array([0.5, 0.1, 0.80]) + np.outer(np.arange(6) * 0.03, pull)
    path = np.concatenate([lower, upper])
    assert len(tool_segments(path, 0.016, 0.02, np.inf)) == 1     # no jump rule: one circle
    runs = tool_segments(path, 0.016, 0.02, 0.08)
    assert [r.tolist() for r in runs] == [list(range(6)), list(range(6, 12))]


def test_a_run_is_held_once_a_fit_brings_a_joint_onto_it():
    """A run of the tool path that no joint held when the path was first read is held by the
    door once its line carries the grasp (after later fits), once only; a door 15 deg off its
    hinge does not get it."""
    from types import SimpleNamespace

    from artgs.core.model.joints import rotation_about_axis
    from artgs.core.model.progress import QUIET
    from artgs.core.stages.optimise.missed import hold_carried

    axis, origin = np.array([0.0, 0.0, 1.0]), np.array([0.3, -0.2, 0.0])
    times = list(range(10))
    values = np.radians([0.0] * 4 + [0.0, 10.0, 20.0, 30.0, 40.0, 50.0])
    grasp = np.array([0.9, 0.3, 0.4])
    tool = {}
    for t, v in zip(times[4:], values[4:]):
        M = joint_transform("revolute", axis, origin, v)
        T = np.eye(4)
        T[:3, 2] = M[:3, :3] @ np.array([-1.0, 0.0, 0.0])
        T[:3, 3] = (M @ np.append(grasp, 1.0))[:3]
        tool[t] = T
    for tilt, expected in ((0.0, ["door"]), (15.0, [])):
        door = Joint(name="door", type="revolute", origin=origin, states=dict(zip(times, values)),
                     axis=rotation_about_axis(np.array([1.0, 0.0, 0.0]), np.radians(tilt)) @ axis)
        run = SimpleNamespace(model=_held_model(door, times), frames=SimpleNamespace(tool=tool),
                              progress=QUIET)
        assert hold_carried(run) == expected
        assert len(run.model.held.get("door", [])) == len(expected)
        assert hold_carried(run) == []


def test_a_joint_takes_the_runs_of_a_piece_of_its_type_only():
    """The runs a piece was held along pass to the hinge it joins (their tool positions then
    carried by that hinge), not to a slide (they would bend it towards a line)."""
    times = list(range(4))
    door = Joint("door", "revolute", np.array([0.0, 0.0, 1.0]), np.zeros(3),
                 states={t: 0.2 * t for t in times})
    model = _held_model(door, times)
    model.harden()
    model.add("piece", "revolute", door.axis, door.origin, np.arange(200) % 4 == 1)
    model.add("slide", "prismatic", np.array([1.0, 0.0, 0.0]), np.zeros(3),
              np.arange(200) % 4 == 3)
    path = np.array([[np.cos(0.2 * t), np.sin(0.2 * t), 0.0] for t in times])
    model.hold("piece", times, path)
    model.pass_runs(1, 2)
    assert "slide" not in model.held
    model.pass_runs(1, 0)
    assert len(model.held["door"]) == 1
    assert np.allclose(model.held["door"][0][1].numpy(), path)
