"""Export: meshes, URDF and its validation on a splat sampled from a synthetic cabinet, the URDF
joint frames against independently composed world motions (nested joints), object separation."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
import yourdfpy
from scipy.spatial.transform import Rotation

from artgs.core.geometry.separate import separate_object
from artgs.core.model import layout
from artgs.core.model.joints import Joint
from artgs.core.model.progress import Progress
from artgs.core.model.registry import ExportOptions
from artgs.core.sim.urdf import Box, Geometry, Link, write_urdf
from artgs.core.sim.validate import collision_check, fk_check, mujoco_check, problems
from artgs.core.stages.export.stage import link_frames, run, urdf_joint

from splat_objects import make_out

FAST = ExportOptions(views=16, max_hulls=6)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "cabinet"
    spec, art = make_out(out, "cabinet", 0)
    figures = run(out, None, FAST, Progress("quiet"))
    return out, spec, art, figures


def test_export_writes_watertight_parts_with_positive_inertia(exported):
    out, spec, art, figures = exported
    links = ["base"] + [j.child for j in art.joints]
    assert sorted(figures["links"]) == sorted(links)
    robot = yourdfpy.URDF.load(str(out / layout.URDF), load_meshes=False,
                               build_collision_scene_graph=False, load_collision_meshes=False)
    for name in links:
        visual = trimesh.load(out / "parts" / f"{name}.obj", process=True, force="mesh")
        assert visual.is_watertight and visual.volume > 0, name
        assert len(visual.faces) <= 2 * FAST.face_budget, name   # see --face-budget
        v_lines = [ln for ln in (out / "parts" / f"{name}.obj").read_text().splitlines()
                   if ln.startswith("v ")]
        assert all(len(ln.split()) == 7 for ln in v_lines)      # x y z r g b
        collision = (out / "parts" / f"{name}_collision.obj").read_text()
        assert collision.count("\no piece_") >= 1
        inertial = robot.link_map[name].inertial
        assert inertial.mass > 0
        assert np.all(np.linalg.eigvalsh(inertial.inertia) > 0), name
    # the meshes lie where the object's boxes are: every visual vertex near a box surface
    from artgs.core.synth.objects import box_distance
    base = trimesh.load(out / "parts" / "base.obj", force="mesh")
    d = box_distance(np.asarray(base.vertices), spec.boxes_at())
    assert np.median(d) < 0.02


def test_export_validation_is_recorded_and_passes(exported):
    out, _, art, figures = exported
    v = figures["validation"]
    assert v["ok"] and v["fk"]["max_error"] < 1e-6
    assert set(v["collision"]["joints"]) == {j.name for j in art.joints}
    assert v["mujoco"]["ok"] and v["mujoco"]["joints"] == len(art.joints)
    text = (out / layout.URDF).read_text()
    assert 'filename="parts/base.obj"' in text and "/tmp" not in text


def _pose(rotvec=(0, 0, 0), t=(0, 0, 0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = t
    return T


def test_urdf_fk_equals_world_joints_with_nested_parents(tmp_path):
    """A door on the base, a flap on the door and a drawer on the flap, axes not axis-aligned:
    link poses from yourdfpy equal world motions composed independently here."""
    door = Joint("door", "revolute", [0.1, 0.2, 1.0], [0.5, -0.3, 0.4], (-0.3, 1.4))
    flap = Joint("flap", "revolute", [1.0, -0.3, 0.2], [0.6, 0.1, 0.9], (0.0, 0.8),
                 parent=door.child)
    slide = Joint("slide", "prismatic", [0.3, 0.9, -0.1], [0.7, 0.2, 1.1], (0.0, 0.2),
                  parent=flap.child)
    joints = [door, flap, slide]
    frames = link_frames(joints)
    options = ExportOptions()
    links = [Link(n, collisions=[Geometry(Box((0.05, 0.05, 0.05)))]) for n in frames]
    path = tmp_path / "chain.urdf"
    path.write_text(write_urdf("chain", links, [urdf_joint(j, frames, options) for j in joints]))
    robot = yourdfpy.URDF.load(str(path))
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = {j.name: float(rng.uniform(*j.limit)) for j in joints}
        robot.update_cfg(q)
        world = {"base": np.eye(4)}
        for j in joints:    # revolute: rotate about the line through origin; prismatic: slide
            if j.type == "revolute":
                R = _pose(j.axis * q[j.name])
                M = _pose(t=j.origin) @ R @ _pose(t=-j.origin)
            else:
                M = _pose(t=j.axis * q[j.name])
            world[j.child] = world[j.parent] @ M
            got = robot.get_transform(frame_to=j.child, frame_from="base")
            np.testing.assert_allclose(got, world[j.child] @ _pose(t=j.origin), atol=1e-9)
    assert fk_check(path, joints)["max_error"] < 1e-9
    assert collision_check(path, joints)["links"] == 4
    assert mujoco_check(path)["ok"]


def test_collision_check_catches_a_part_swinging_through_the_base(tmp_path):
    """A door hinged on the wrong side of its panel swings into the body: the sweep flags it."""
    body = Link("base", collisions=[Geometry(Box((0.4, 0.6, 0.8)), _pose(t=(0, 0, 0.4)))])
    panel = Geometry(Box((0.02, 0.56, 0.76)), _pose(t=(0.0, 0.28, 0.0)))
    good = Joint("door", "revolute", [0, 0, -1], [0.215, -0.28, 0.4], (0.0, 1.5))
    bad = Joint("door", "revolute", [0, 0, 1], [0.215, -0.28, 0.4], (0.0, 1.5))
    for joint, ok in ((good, True), (bad, False)):
        frames = link_frames([joint])
        door = Link(joint.child, collisions=[panel])
        path = tmp_path / f"door_{ok}.urdf"
        path.write_text(write_urdf("c", [body, door], [urdf_joint(joint, frames, ExportOptions())]))
        result = collision_check(path, [joint])
        assert result["ok"] is ok, result
        said = problems({"fk": fk_check(path, [joint]), "collision": result,
                         "mujoco": {"ok": True}})
        if ok:
            assert said == []
        else:       # one line, naming the joint, how deep and what to do
            assert len(said) == 1 and "joint 'door'" in said[0] and "Save Joints" in said[0]
            deeper = result["joints"]["door"]["max_penetration"] - \
                result["joints"]["door"]["closed_penetration"]
            assert f"{100 * deeper:.1f} cm" in said[0]


def test_separation_keeps_the_object_and_drops_floor_and_wall():
    rng = np.random.default_rng(0)
    from splat_objects import box_surface
    obj = box_surface(_pose(t=(0, 0, 0.45)), np.array([0.3, 0.3, 0.45]), 0.025, rng)
    n_obj = len(obj)
    floor = np.c_[rng.uniform(-3, 3, (6000, 2)), rng.normal(0, 0.002, 6000)]
    wall = np.c_[rng.normal(-0.9, 0.002, 4000), rng.uniform(-3, 3, 4000), rng.uniform(0, 2.5, 4000)]
    chair = rng.uniform([0.2, 1.2, 0.0], [0.7, 1.7, 0.5], (800, 3))
    points = np.concatenate([obj, floor, wall, chair])
    from artgs.core.model.cameras import look_at
    cams = np.array([look_at(np.array([2.0 * np.cos(a), 2.0 * np.sin(a), 1.2]),
                             np.array([0, 0, 0.45])) for a in np.linspace(-1.2, 1.2, 8)])
    door = (np.array([0.3, 0.0, 0.45]), np.eye(3), np.array([0.02, 0.25, 0.4]))
    sep = separate_object(points, cams, cams[::3], [door])
    truth = np.zeros(len(points), bool)
    truth[:n_obj] = obj[:, 2] > 0.02            # the object's bottom lies in the floor band
    recall = (sep.mask & truth).sum() / truth.sum()
    precision = (sep.mask & truth).sum() / sep.mask.sum()
    assert recall > 0.95 and precision > 0.97, (recall, precision, sep.removed)
    assert sep.floor is not None and abs(sep.floor[0] @ [0, 0, 1]) > 0.99


def test_the_robot_opens_every_part_of_the_exported_model(exported):
    from artgs.core.model.registry import CheckOptions
    from artgs.core.pipeline import run_stage

    out, _, art, _ = exported
    (out / layout.PROPOSALS).write_text((out / layout.ARTICULATION).read_text())
    figures = run_stage("check", out, CheckOptions(frames=2), Progress("quiet"))
    assert figures["urdf"].endswith(layout.URDF)
    assert all(r["success"] for r in figures["joints"].values()), figures["joints"]


def test_coacd_runs_apart_and_its_failure_is_no_pieces():
    """CoACD in a child process: a concave L-shaped solid splits into several convex pieces; a
    decomposition that fails there (here CoACD's own error for a bad setting; a crash of the
    child the same way) gives no pieces instead of ending the export."""
    import trimesh

    from artgs.core.stages.export.collision import convex_parts, isolated_coacd
    ell = trimesh.boolean.union([trimesh.creation.box([1.0, 0.2, 0.2]),
                                 trimesh.creation.box([0.2, 1.0, 0.2],
                                                      trimesh.transformations.translation_matrix(
                                                          [0.4, 0.4, 0.0]))], engine="manifold")
    pieces = convex_parts(ell, max_hulls=4)
    assert len(pieces) >= 2 and sum(p.volume for p in pieces) < 1.2 * ell.volume
    assert isolated_coacd(np.asarray(ell.vertices, float), np.asarray(ell.faces, np.int64),
                          timeout=60, threshold="not a number") == []
