"""VLM route: answer parsing, the HTTP client against a local server, depth lifting, end to end.

The only stand-in is a small OpenAI-compatible HTTP server on 127.0.0.1 with canned answers.
"""

from __future__ import annotations

import base64
import json
import math
import time
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import pytest
import torch

from artgs.core.geometry import lift
from artgs.core.model.cameras import Camera, intrinsics, look_at
from artgs.core.model.capture import Capture
from artgs.core.model.errors import ArtgsError, InputError
from artgs.core.stages.propose.vlm.propose import box_within
from artgs.core.stages.propose.vlm.client import VlmConfig, chat, user_message, vlm_config
from artgs.core.stages.propose.vlm.parse import parse_classification, parse_handle, parse_parts, to_grid1000

from vlm_server import Server, completion, reply  # noqa: E402 - tests/ is on sys.path under pytest

W, H = 160, 120


# --- the client against a local OpenAI-compatible server (tests/vlm_server.py) -----------------

def cfg(endpoint: str, **kw) -> VlmConfig:
    kw.setdefault("timeout", 5.0)
    kw.setdefault("backoff", 0.01)
    return VlmConfig(endpoint=endpoint, model="internvl2_5-4b-artgs", **kw)


# --- parser --------------------------------------------------------------------------------------

PAPER = ("Part 1 is a door, and its joint type is revolute. The joint parameter is "
         "[[100, 200, 100, 800]]. Its bounding box is [[100, 200, 500, 800]]. "
         "Part 2 is a drawer, and its joint type is prismatic. The joint parameter is "
         "[[700, 480, 700, 520]]. Its bounding box is [[550, 300, 900, 700]].")


def test_paper_template_on_the_0_1000_grid_gives_pixel_boxes_and_points():
    parts = parse_parts(PAPER, W, H)
    assert [(p.label, p.joint_type, p.skip) for p in parts] == [
        ("door", "revolute", None), ("drawer", "prismatic", None)]
    np.testing.assert_allclose(parts[0].joint_points, [[16, 24], [16, 96]])
    np.testing.assert_allclose(parts[0].bbox, [16, 24, 80, 96])
    np.testing.assert_allclose(parts[1].bbox, [88, 36, 144, 84])


def test_internvl_ref_box_tags_are_always_on_the_grid():
    text = ("Part 1 is a <ref>door</ref>, and its joint type is revolute. The joint parameter is "
            "<box>[[500, 100, 500, 900]]</box>. Its bounding box is <box>[[500, 100, 950, 900]]</box>.")
    # tagged numbers that would also fit as pixels are still read on the 0-1000 grid
    (p,) = parse_parts(text, 1000 * 2, 1000 * 2)
    np.testing.assert_allclose(p.bbox, [1000, 200, 1900, 1800])
    np.testing.assert_allclose(p.joint_points, [[1000, 200], [1000, 1800]])
    (p,) = parse_parts("<ref>drawer</ref><box>[[100, 500, 900, 700]]</box> slides out", W, H)
    assert (p.label, p.joint_type, p.skip) == ("drawer", "prismatic", None)
    np.testing.assert_allclose(p.bbox, [16, 60, 144, 84])


def test_plain_lists_rule_pixels_vs_grid_vs_unit():
    inside = ("Part 1 is a door, and its joint type is revolute. The joint parameter is "
              "[[20, 10, 20, 100]]. Its bounding box is [[20, 10, 70, 100]].")
    # all values inside the image: ambiguous -> 0-1000 grid by default, pixels when configured
    np.testing.assert_allclose(parse_parts(inside, W, H)[0].bbox, [3.2, 1.2, 11.2, 12.0])
    np.testing.assert_allclose(parse_parts(inside, W, H, "pixels")[0].bbox, [20, 10, 70, 100])
    # a y above the image height -> the grid, for every list of the answer
    over = inside.replace("[[20, 10, 70, 100]]", "[[20, 10, 70, 130]]")
    np.testing.assert_allclose(parse_parts(over, W, H)[0].joint_points, [[3.2, 1.2], [3.2, 12.0]])
    unit = inside.replace("[[20, 10, 20, 100]]", "[[0.1, 0.1, 0.1, 0.9]]").replace(
        "[[20, 10, 70, 100]]", "[[0.1, 0.1, 0.5, 0.9]]")
    np.testing.assert_allclose(parse_parts(unit, W, H)[0].bbox, [16, 12, 80, 108])
    pairs = "Part 1 is a lid (revolute). Joint: [[10, 20], [150, 20]]; bbox: [10, 20, 150, 100]"
    np.testing.assert_allclose(parse_parts(pairs, W, H, "pixels")[0].joint_points,
                               [[10, 20], [150, 20]])


def test_qwen_json_in_a_fence_is_in_pixels():
    text = ("Here you go:\n```json\n[\n {\"bbox_2d\": [40, 10, 120, 110], \"label\": \"left door\", "
            "\"joint_type\": \"revolute\", \"joint\": [[40, 10], [40, 110]]},\n"
            " {\"bbox_2d\": [10, 10, 30, 50], \"label\": \"drawer\"}\n]\n```")
    a, b = parse_parts(text, W, H)
    assert (a.label, a.joint_type, a.skip) == ("left door", "revolute", None)
    np.testing.assert_allclose(a.bbox, [40, 10, 120, 110])
    np.testing.assert_allclose(a.joint_points, [[40, 10], [40, 110]])
    assert (b.label, b.joint_type, b.skip) == ("drawer", "prismatic", None)  # type from the name


def test_numbered_lists_and_labels_with_clauses():
    text = ("1. The left part is a door that swings open (revolute); joint [[10, 10, 10, 110]], "
            "bounding box [[10, 10, 80, 110]]\n"
            "2. Part is a drawer which slides out; axis [[120, 60, 120, 62]], box [[90, 40, 150, 80]]")
    a, b = parse_parts(text, W, H, "pixels")
    assert (a.label, a.joint_type, a.skip) == ("door", "revolute", None)
    assert (b.label, b.joint_type, b.skip) == ("drawer", "prismatic", None)
    np.testing.assert_allclose(a.joint_points, [[10, 10], [10, 110]])
    np.testing.assert_allclose(b.bbox, [90, 40, 150, 80])


def test_markdown_and_point_pairs_from_general_purpose_models():
    text = ("- **Part 1**: door (revolute), hinge from (120, 80) to (120, 600), bbox (120, 80, 480, 600)\n"
            "- **Part 2**: drawer (prismatic), bbox (120, 650, 880, 900)")
    a, b = parse_parts(text, 448, 336)
    assert (a.label, a.joint_type, a.skip, b.label, b.joint_type, b.skip) == (
        "door", "revolute", None, "drawer", "prismatic", None)
    np.testing.assert_allclose(a.joint_points, [[53.76, 26.88], [53.76, 201.6]])
    np.testing.assert_allclose(b.bbox, [53.76, 218.4, 394.24, 302.4])
    assert parse_classification("The object is a **refrigerator**. It has **2** movable parts.") == (
        "refrigerator", 2)


def test_handle_answers_in_each_format():
    for text, want in [("Its handle is [[400, 450, 450, 550]].", [64, 54, 72, 66]),
                       ("Its handle is <box>[[400, 450, 450, 550]]</box>.", [64, 54, 72, 66]),
                       ("<|box_start|>(400,450),(450,550)<|box_end|>", [64, 54, 72, 66]),
                       ('```json\n[{"bbox_2d": [64, 54, 72, 66], "label": "handle"}]\n```',
                        [64, 54, 72, 66])]:
        box, reason = parse_handle(text, W, H)
        assert reason is None, text
        np.testing.assert_allclose(box, want, err_msg=text)
    box, reason = parse_handle("There is no handle on this part.", W, H)
    assert box is None and "no handle box" in reason


def test_unusable_answers_become_skip_reasons_never_errors():
    (p,) = parse_parts("Sorry, I cannot help with that.", W, H)
    assert p.skip and "no coordinates" in p.skip
    text = PAPER.replace("[[100, 200, 500, 800]]", "[[100, 200, 1500, 800]]")
    door, drawer = parse_parts(text, W, H)
    assert door.skip and "outside" in door.skip and drawer.skip is None
    text = PAPER.replace("[[100, 200, 100, 800]]", "[[100, 200, 100, 201]]")
    assert "coincide" in parse_parts(text, W, H)[0].skip
    text = "Part 1 is a thing. The joint parameter is [[1, 2, 3, 4]]. Its bounding box is [[1, 2, 900, 900]]."
    assert "no joint type" in parse_parts(text, W, H)[0].skip
    text = "Part 1 is a door, and its joint type is revolute. Its bounding box is [[1, 2, 900, 900]]."
    assert "no joint parameter" in parse_parts(text, W, H)[0].skip
    for garbage in ["", "[[[", "```json\n{not json}\n```", "Part 1 is a door [[1, 2, 3]]"]:
        assert all(p.skip for p in parse_parts(garbage, W, H))


def test_classification_categories_synonyms_and_numbers():
    cases = {"This is a dishwasher with 1 movable part.": ("dishwasher", 1),
             "This is a fridge with two movable parts.": ("refrigerator", 2),
             "This is a microwave oven with one movable part.": ("microwave", 1),
             "This is an oven with a single movable part.": ("oven", 1),
             "This is a chest of drawers with four movable components.": ("drawer", 4),
             "This is a kitchen cabinet with one door and 2 drawers.": ("cabinet", 3),
             "This is a wardrobe with 3 movable parts": ("storage", 3),
             "I see a box.": (None, None)}
    for text, want in cases.items():
        assert parse_classification(text) == want, text


def test_grid_conversion_round_trips():
    assert to_grid1000(np.array([16, 24, 80, 96]), W, H) == [100, 200, 500, 800]


# --- client ---------------------------------------------------------------------------------------

def test_request_format_image_and_authorization(monkeypatch):
    png = cv2.imencode(".png", np.full((8, 6, 3), 77, np.uint8))[1].tobytes()
    oven = completion("This is an oven with 1 movable part.")
    with Server(reply(lambda body: (200, oven, 0))) as fake:
        monkeypatch.setenv("ARTGS_VLM_API_KEY", "sk-test-123")
        monkeypatch.setenv("ARTGS_VLM_MODEL", "internvl2_5-4b-artgs")
        config = vlm_config(fake.endpoint, None, timeout=5)
        assert "sk-test-123" not in repr(config)
        assert chat(config, [user_message("What is it?", png)]) == "This is an oven with 1 movable part."
    path, headers, body, _ = fake.requests[0]
    assert path == "/v1/chat/completions"
    assert headers["Authorization"] == "Bearer sk-test-123"
    assert body["model"] == "internvl2_5-4b-artgs" and body["temperature"] == 0
    assert body["max_tokens"] > 0
    text, image = body["messages"][0]["content"]
    assert text == {"type": "text", "text": "What is it?"}
    url = image["image_url"]["url"]
    assert url.startswith("data:image/png;base64,")
    assert base64.b64decode(url.split(",", 1)[1]) == png


def test_no_key_no_authorization_header_and_config_errors(monkeypatch):
    for var in ("ARTGS_VLM_ENDPOINT", "ARTGS_VLM_MODEL", "ARTGS_VLM_API_KEY", "ARTGS_VLM_COORDS"):
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(InputError, match="ARTGS_VLM_ENDPOINT"):
        vlm_config(None, "m")
    with pytest.raises(InputError, match="ARTGS_VLM_MODEL"):
        vlm_config("http://127.0.0.1:9/v1", None)
    with pytest.raises(InputError, match="http"):
        vlm_config("127.0.0.1:9", "m")
    monkeypatch.setenv("ARTGS_VLM_ENDPOINT", "http://example.invalid/v1/")
    monkeypatch.setenv("ARTGS_VLM_COORDS", "pixels")
    c = vlm_config(None, "m")
    assert (c.endpoint, c.api_key, c.coords) == ("http://example.invalid/v1", None, "pixels")
    with Server(reply(lambda body: (200, completion("ok"), 0))) as fake:
        assert chat(cfg(fake.endpoint), [user_message("hi")]) == "ok"
    assert "Authorization" not in fake.requests[0].headers


def test_retries_server_errors_then_succeeds():
    statuses = iter([500, 503, 200])

    def answer(body):
        s = next(statuses)
        return (s, completion("fine") if s == 200 else '{"error": "overloaded"}', 0)

    with Server(reply(answer)) as fake:
        assert chat(cfg(fake.endpoint, retries=2), [user_message("hi")]) == "fine"
    assert len(fake.requests) == 3
    with Server(reply(lambda body: (502, "bad gateway", 0))) as fake:
        with pytest.raises(ArtgsError, match=r"HTTP 502.*bad gateway.*after 2 attempts"):
            chat(cfg(fake.endpoint, retries=1), [user_message("hi")])
    assert len(fake.requests) == 2


def test_client_error_is_not_retried_and_names_endpoint_status_and_body():
    with Server(reply(lambda body: (400, '{"error": "model not found: foo"}', 0))) as fake:
        with pytest.raises(ArtgsError) as err:
            chat(cfg(fake.endpoint, retries=3), [user_message("hi")])
    msg = str(err.value)
    assert fake.endpoint in msg and "HTTP 400" in msg and "model not found" in msg
    assert len(fake.requests) == 1


def test_timeout_and_unreachable_and_bad_body_errors():
    with Server(reply(lambda body: (200, completion("late"), 1.0))) as fake:
        with pytest.raises(ArtgsError, match="no complete answer within 0.2 s"):
            chat(cfg(fake.endpoint, timeout=0.2, retries=3, backoff=0.0), [user_message("hi")])
        time.sleep(0.1)  # a retry would have arrived by now
        assert len(fake.requests) == 1  # a timed-out request is not repeated
    with Server(reply(lambda body: (200, "<html>not json</html>", 0))) as fake:
        with pytest.raises(ArtgsError, match="not a chat completion.*not json"):
            chat(cfg(fake.endpoint), [user_message("hi")])
        endpoint = fake.endpoint
    with pytest.raises(ArtgsError, match=r"unreachable.*after 2 attempts"):
        chat(cfg(endpoint, retries=1), [user_message("hi")])  # server closed: connection refused


def test_a_local_server_is_reached_without_the_environment_proxy(monkeypatch):
    monkeypatch.setenv("http_proxy", "http://127.0.0.1:9")  # nothing listens there
    monkeypatch.setenv("HTTP_PROXY", "http://127.0.0.1:9")
    monkeypatch.delenv("no_proxy", raising=False)
    monkeypatch.delenv("NO_PROXY", raising=False)
    with Server(reply(lambda body: (200, completion("direct"), 0))) as fake:
        assert chat(cfg(fake.endpoint, retries=0), [user_message("hi")]) == "direct"


# --- lifting against hand-made depth ---------------------------------------------------------------

def _plane_depth(camera: Camera, point, normal) -> np.ndarray:
    """z-depth of the plane through ``point`` with ``normal`` at every pixel."""
    rays = lift.rays(camera, np.stack(np.meshgrid(np.arange(camera.width) + 0.5,
                                                  np.arange(camera.height) + 0.5), -1).reshape(-1, 2))
    t = ((np.asarray(point) - camera.center) @ normal) / (rays @ normal)
    return t.reshape(camera.height, camera.width)


def _camera(eye, target) -> Camera:
    return Camera(intrinsics(150.0, 150.0, W / 2, H / 2), look_at(np.array(eye), np.array(target)),
                  W, H)


def test_revolute_hinge_from_exact_image_points_on_a_door_plane():
    # a door in the plane x = 0.3 (normal +x), hinge along z at y = -0.2, seen from an oblique view
    cam = _camera([1.6, 0.5, 0.9], [0.3, 0.0, 0.4])
    normal = np.array([1.0, 0, 0])
    depth = _plane_depth(cam, [0.3, 0, 0], normal)
    door = np.array([[0.3, -0.2, 0.1], [0.3, 0.25, 0.1], [0.3, 0.25, 0.7], [0.3, -0.2, 0.7]])
    uv, _ = cam.project(door)
    pix = np.stack(np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5), -1).reshape(-1, 2)
    world = lift.backproject_uv(cam, pix, depth.reshape(-1)).reshape(H, W, 3)
    depth[world[..., 1] < -0.2] = 3.0  # beyond the hinge edge: the far background (a depth edge)
    box = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
    plane = lift.fit_plane(cam, depth, box)
    assert _deg(plane.normal, normal) < 1.0
    hinge_uv, _ = cam.project(np.array([[0.3, -0.2, 0.12], [0.3, -0.2, 0.68]]))
    axis, origin, trusted = lift.revolute_axis(cam, depth, hinge_uv, plane)
    assert trusted
    assert _deg(axis, [0, 0, 1.0], signed=False) < 2.0
    assert np.linalg.norm(np.cross(origin - [0.3, -0.2, 0.4], [0, 0, 1.0])) < 0.01
    center, _, _, size = lift.box_frame(cam, box, plane)
    axis = lift.opening_sign(axis, origin, center, plane.normal)
    assert axis @ [0, 0, 1.0] < 0  # free edge at +y swings towards +x for a rotation about -z
    # no depth along the segment: the 2D segment is lifted onto the part's plane instead
    axis2, origin2, trusted2 = lift.revolute_axis(cam, np.zeros_like(depth), hinge_uv, plane)
    assert not trusted2
    assert _deg(axis2, [0, 0, 1.0], signed=False) < 1.0
    assert np.linalg.norm(np.cross(origin2 - [0.3, -0.2, 0.4], [0, 0, 1.0])) < 0.005


def _unit(v):
    return np.asarray(v) / np.linalg.norm(v)


def _deg(a, b, signed: bool = True) -> float:
    c = float(np.dot(_unit(a), _unit(b)))
    return math.degrees(math.acos(np.clip(c if signed else abs(c), -1.0, 1.0)))


def test_prismatic_normal_extent_and_handle_on_a_tilted_drawer_front():
    n = _unit([1.0, 0.4, 0.0])  # drawer front facing (1, 0.4, 0)
    cam = _camera(list(np.array([0.0, 0.0, 0.5]) + 1.4 * n + [0.3, -0.5, 0.6]), [0.0, 0.0, 0.5])
    depth = _plane_depth(cam, [0, 0, 0.5], n)
    side = _unit(np.cross([0, 0, 1.0], n))
    corners = np.array([[0, 0, 0.5] + s * 0.25 * side + t * 0.1 * np.array([0, 0, 1.0])
                        for s, t in [(-1, -1), (1, -1), (1, 1), (-1, 1)]])
    uv, _ = cam.project(corners)
    box = np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])
    # a handle bar 3 cm proud of the front in the middle of the box
    huv, _ = cam.project(np.array([[0, 0, 0.5] + 0.03 * n - 0.08 * side + [0, 0, -0.01],
                                   [0, 0, 0.5] + 0.03 * n + 0.08 * side + [0, 0, 0.01]]))
    hbox = np.array([huv[:, 0].min(), huv[:, 1].min(), huv[:, 0].max(), huv[:, 1].max()])
    i0, i1, j0, j1 = (int(hbox[1]), int(math.ceil(hbox[3])), int(hbox[0]), int(math.ceil(hbox[2])))
    handle_plane = _plane_depth(cam, np.array([0, 0, 0.5]) + 0.03 * n, n)
    depth[i0:i1, j0:j1] = handle_plane[i0:i1, j0:j1]
    plane = lift.fit_plane(cam, depth, box)
    axis = lift.prismatic_axis(cam, box, plane)
    assert _deg(axis, n) < 2.0  # pointing out of the front, towards the camera
    ext = lift.extent(cam, box, plane)
    np.testing.assert_allclose(np.abs(np.array(ext["axes"]) @ np.array(ext["axes"]).T), np.eye(3),
                               atol=1e-9)
    assert _deg(ext["axes"][2], n) < 2.0
    assert np.linalg.norm(np.array(ext["center"]) - [0, 0, 0.5] - 0.015 * n) < 0.03
    h = lift.handle(cam, depth, hbox, plane)
    assert np.linalg.norm(np.array(h["point"]) - ([0, 0, 0.5] + 0.03 * n)) < 0.02
    assert _deg(h["approach"], -n) < 2.0


def test_robust_depth_prefers_the_near_layer_at_an_edge():
    depth = np.full((10, 10), 2.0)
    depth[:, 5:] = 1.0
    depth[0, 0] = 0.0
    z = lift.robust_depth(depth, np.array([[5.2, 5.0], [2.0, 5.0], [0.5, 0.5]]), radius=2)
    np.testing.assert_allclose(z, [1.0, 2.0, 2.0])
    assert lift.robust_depth(np.zeros((4, 4)), np.array([[1.0, 1.0]]))[0] == 0.0


def test_snap_axis_only_within_its_angle():
    n, up = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    tilt = lambda deg: np.array([0, math.sin(math.radians(deg)), math.cos(math.radians(deg))])
    np.testing.assert_allclose(lift.snap_axis(tilt(5), n, up, "revolute"), up)
    np.testing.assert_allclose(lift.snap_axis(-tilt(5), n, up, "revolute"), -up)
    np.testing.assert_allclose(lift.snap_axis(tilt(12), n, up, "revolute"), tilt(12))
    np.testing.assert_allclose(lift.snap_axis(tilt(87), n, up, "revolute"), [0, 1.0, 0], atol=1e-12)
    drawer = _unit([1.0, 0, 0.1])
    np.testing.assert_allclose(lift.snap_axis(drawer, drawer, up, "prismatic"), n)
    lid = _unit([0, 0.05, 1.0])  # a lid facing up: every direction in it is level, none is snapped
    np.testing.assert_allclose(lift.snap_axis(_unit([1, 0.1, 0]), lid, up, "revolute"),
                               _unit([1, 0.1, 0]))


def test_up_direction_from_level_cameras_with_and_without_spread():
    from artgs.core.model.capture import Frame
    from artgs.core.model.joints import rotation_about_axis
    from artgs.core.stages.propose.vlm.propose import up_direction

    R = np.eye(4)
    R[:3, :3] = rotation_about_axis(np.array([0.2, 1.0, 0.4]), 2.2)  # a world that is not z-up
    up = R[:3, :3] @ [0, 0, 1.0]

    def capture(eyes):
        K = intrinsics(4.0, 4.0, 2.0, 1.5)
        frames = [Frame(k, f"f{k}", Camera(K, R @ look_at(np.array(e, float), np.zeros(3)), 4, 3),
                        np.zeros((3, 4, 3), np.uint8), None, None) for k, e in enumerate(eyes)]
        return Capture(Path("."), frames)

    around = [[2 * math.cos(a), 2 * math.sin(a), 1.0 + 0.3 * (k % 2)] for k, a in
              enumerate(np.linspace(-1.2, 1.2, 7))]
    assert _deg(up_direction(capture(around)), up) < 1e-6
    # all cameras facing one way (right axes parallel): the mean camera up, tilted by the elevation
    one_way = [[2.0, 0.0, 1.0], [3.0, 0.0, 1.5]]
    got = up_direction(capture(one_way))
    assert 20 < _deg(got, up) < 35 and got @ up > 0
    R[:3, :3] = rotation_about_axis(np.array([1.0, 0, 0]), -math.pi / 2)  # a y-up world
    assert _deg(up_direction(capture(one_way)), [0, 1.0, 0]) < 1e-6
    R[:3, :3] = np.eye(3)  # z-up
    assert _deg(up_direction(capture(one_way)), [0, 0, 1.0]) < 1e-6


# --- end to end on a synthetic object ----------------------------------------------------------------

@pytest.fixture(scope="module")
def cabinet(tmp_path_factory):
    """A synthetic cabinet (door + drawer), its ground truth and a depth-initialised static splat."""
    from artgs.core.model.capture import load_capture
    from artgs.core.render.gaussians import Gaussians
    from artgs.core.model.joints import read_articulation
    from artgs.core.stages.reconstruct import initial_splats
    from artgs.core.synth.generate import generate_object

    root = generate_object(tmp_path_factory.mktemp("vlm") / "cabinet", "cabinet", 3, width=W,
                           height=H, static_views=12, steps=2)
    capture = load_capture(root)
    splats, _ = initial_splats(capture.static)
    return capture, Gaussians.from_arrays(splats), read_articulation(root / "gt.json").joints


def _front_box(camera: Camera, joint) -> np.ndarray:
    """Pixel box of the face of the joint's extent box that faces the camera."""
    e = joint.extent
    axes, half, c = np.array(e["axes"]), np.array(e["half_size"]), np.array(e["center"])
    k = int(np.argmax(np.abs(axes @ camera.forward)))
    s = -np.sign(axes[k] @ camera.forward)
    others = [i for i in range(3) if i != k]
    corners = np.array([c + s * half[k] * axes[k] + a * half[others[0]] * axes[others[0]]
                        + b * half[others[1]] * axes[others[1]] for a in (-1, 1) for b in (-1, 1)])
    uv, _ = camera.project(corners)
    return np.concatenate([uv.min(0), uv.max(0)])


def _grid(values, camera: Camera) -> str:
    v = np.asarray(values, float).reshape(-1, 2) * 1000 / np.array([camera.width, camera.height])
    return "<box>[[" + ", ".join(str(int(round(x))) for x in v.ravel()) + "]]</box>"


def _canned_answers(camera: Camera, joints, broken: int | None = None,
                    stray_handles: bool = False, wrong_side: bool = False) -> Callable:
    """A server answering the three questions from the ground truth projected into ``camera``;
    part ``broken`` gets an unreadable box, ``stray_handles`` puts handles outside their parts,
    ``wrong_side`` puts revolute hinges on the part's opposite edge."""
    lines, boxes, handles = [], [], []
    for n, j in enumerate(joints, 1):
        box = _front_box(camera, j)
        boxes.append(box)
        hb, _ = camera.project(np.array([j.handle["point"]]))
        if stray_handles:  # the image corner farthest from the part
            hb = np.array([[4.0 if box[0] + box[2] > camera.width else camera.width - 4.0,
                            4.0 if box[1] + box[3] > camera.height else camera.height - 4.0]])
            assert not box_within(np.concatenate([hb[0] - 3, hb[0] + 3]), box)
        handles.append(np.concatenate([hb[0] - 3, hb[0] + 3]))
        if j.type == "revolute":
            e = j.extent
            reach = np.abs(np.array(e["axes"]) @ j.axis) @ np.array(e["half_size"])
            ts = (np.array(e["center"]) - j.origin) @ j.axis + np.array([-1, 1]) * reach
            offset = 2 * (np.array(e["center"]) - j.origin) if wrong_side else 0.0
            offset = offset - (offset @ j.axis) * j.axis if wrong_side else 0.0
            points, _ = camera.project(j.origin + offset + ts[:, None] * j.axis)
        else:
            points = np.array([box[:2] + box[2:], box[:2] + box[2:]]) / 2 + [[0, -1], [0, 1]]
        label = "door" if j.type == "revolute" else "drawer"
        box_text = "[[n/a]]" if n == broken else _grid(box, camera)
        lines.append(f"Part {n} is a {label}, and its joint type is {j.type}. The joint parameter "
                     f"is {_grid(points, camera)}. Its bounding box is {box_text}.")

    def answer(body):
        last = body["messages"][-1]["content"]
        text = last if isinstance(last, str) else last[0]["text"]
        if "What is the object" in text:
            said = f"This is a cabinet with {len(joints)} movable parts."
        elif "joint types" in text:
            said = " ".join(lines)
        else:
            asked = np.array([float(v) for v in text.split("[[")[1].split("]]")[0].split(",")])
            asked = asked * np.array([camera.width, camera.height] * 2) / 1000
            k = int(np.argmin([np.abs(b - asked).sum() for b in boxes]))
            said = f"Its handle is {_grid(handles[k], camera)}."
        return 200, completion(said), 0.0
    return answer


def _view(meta) -> Camera:
    v = meta["view"]
    return Camera(np.array(v["K"]), np.array(v["c2w"]), v["width"], v["height"])


def _tilted(capture, gaussians, gt, T: np.ndarray):
    """The same scene in another world frame: ``T`` (4x4 rigid) applied to cameras, splat and gt."""
    import dataclasses

    from artgs.core.render.gaussians import Gaussians
    from artgs.core.model.joints import Joint

    R, t = T[:3, :3], T[:3, 3]
    frames = [dataclasses.replace(f, camera=Camera(f.camera.K, T @ f.camera.c2w, f.camera.width,
                                                   f.camera.height)) for f in capture.frames]
    g = Gaussians(gaussians.means @ torch.as_tensor(R.T, dtype=torch.float32)
                  + torch.as_tensor(t, dtype=torch.float32), gaussians.quats,
                  gaussians.log_scales, gaussians.opacity_logits, gaussians.sh)
    joints = []
    for j in gt:
        d = j.to_dict()
        d["axis"], d["origin"] = list(R @ j.axis), list(R @ j.origin + t)
        d["extent"] = dict(d["extent"], center=list(R @ d["extent"]["center"] + t),
                           axes=(np.array(d["extent"]["axes"]) @ R.T).tolist())
        d["handle"] = {"point": list(R @ d["handle"]["point"] + t),
                       "approach": list(R @ d["handle"]["approach"])}
        joints.append(Joint.from_dict(d))
    return Capture(capture.root, frames), g, joints


def _level(v, up):
    return np.asarray(v) - (np.asarray(v) @ up) * up


@pytest.mark.parametrize("world", ["z_up", "tilted"])
def test_propose_vlm_end_to_end_recovers_the_ground_truth_joints(cabinet, world):
    import io

    from artgs.core.model.joints import rotation_about_axis
    from artgs.core.geometry.metrics import match_joints
    from artgs.core.model.progress import Progress
    from artgs.core.stages.propose.vlm.propose import frontal_camera, propose_vlm, up_direction

    capture, gaussians, gt = cabinet
    up = np.array([0, 0, 1.0])
    if world == "tilted":  # a capture whose world frame is not z-up (e.g. y-up, rotated)
        T = np.eye(4)
        T[:3, :3] = rotation_about_axis(np.array([1.0, 0.3, -0.2]), 1.9)
        T[:3, 3] = [0.4, -1.0, 2.0]
        capture, gaussians, gt = _tilted(capture, gaussians, gt, T)
        up = T[:3, :3] @ up
    assert _deg(up_direction(capture), up) < 1.0
    means = gaussians.means.numpy().astype(float)
    camera = frontal_camera(capture, means, W, H)
    # the view looks at the front: against the object's front normal (object x = gt drawer axis)
    front = next(j for j in gt if j.type == "prismatic").axis
    assert _deg(_level(camera.forward, up), -_level(front, up)) < 3.0
    assert abs(camera.c2w[:3, 0] @ up) < 1e-6  # no roll
    uv, z = camera.project(means)
    assert np.all(z > 0) and np.mean((uv >= 0).all(1) & (uv <= [W, H]).all(1)) > 0.99
    # without interaction frames the static views' side is used: the same face
    static_only = frontal_camera(Capture(capture.root, capture.static), means, W, H)
    assert _deg(_level(static_only.forward, up), -_level(front, up)) < 3.0
    with Server(reply(_canned_answers(camera, gt))) as fake:
        stream = io.StringIO()
        joints, meta = propose_vlm(capture, gaussians, Progress("json", stream=stream),
                                   VlmConfig(endpoint=fake.endpoint, model="m", width=W, height=H,
                                             timeout=10))
    np.testing.assert_allclose(_view(meta).c2w, camera.c2w)
    assert meta["category"] == "cabinet" and meta["parts_said"] == 2 and meta["skipped"] == []
    assert len(fake.requests) == 2 + len(gt)
    assert fake.requests[1].body["messages"][1]["role"] == "assistant"  # bones continues the chat
    scores = match_joints(joints, gt)
    for s in scores:
        assert s.type_correct, s
        assert s.axis_error_deg < 1.0, s
        assert s.origin_error_cm is None or s.origin_error_cm < 1.0, s
    for j in joints:
        t = next(t for t in gt if t.type == j.type)
        assert j.source == "vlm" and 0 < j.confidence <= 1
        assert np.linalg.norm(np.array(j.handle["point"]) - t.handle["point"]) < 0.04
        assert _deg(j.handle["approach"], t.handle["approach"]) < 5.0
        assert np.linalg.norm(np.array(j.extent["center"]) - t.extent["center"]) < (
            0.05 if j.type == "revolute" else 0.35)  # the drawer's gt box includes its tray
        if j.type == "revolute":  # positive angles open the door like the ground truth
            assert j.axis @ t.axis > 0


def test_propose_vlm_skips_an_unparseable_part_and_keeps_the_others(cabinet):
    import io

    from artgs.core.model.progress import Progress
    from artgs.core.stages.propose.vlm.propose import frontal_camera, propose_vlm

    capture, gaussians, gt = cabinet
    camera = frontal_camera(capture, gaussians.means.numpy().astype(float), W, H)
    broken = 1 + next(k for k, j in enumerate(gt) if j.type == "prismatic")
    with Server(reply(_canned_answers(camera, gt, broken=broken, stray_handles=True))) as fake:
        stream = io.StringIO()
        joints, meta = propose_vlm(capture, gaussians, Progress("json", stream=stream),
                                   VlmConfig(endpoint=fake.endpoint, model="m", width=W, height=H))
    assert [j.type for j in joints] == ["revolute"]
    assert len(meta["skipped"]) == 1 and f"part {broken}" in meta["skipped"][0]
    events = [json.loads(line) for line in stream.getvalue().splitlines()]
    warnings = [e["message"] for e in events if e["event"] == "log" and e["level"] == "warning"]
    assert any(f"part {broken}" in w and "no bounding box" in w for w in warnings)
    assert joints[0].handle is None  # the handle answer pointed outside the door
    assert any(e["event"] == "log" and "handle not used" in e["message"]
               and "not within the part's box" in e["message"] for e in events)


def test_a_handle_beside_the_hinge_line_lowers_confidence(cabinet):
    import io

    from artgs.core.model.progress import Progress
    from artgs.core.stages.propose.vlm.propose import frontal_camera, propose_vlm

    capture, gaussians, gt = cabinet
    camera = frontal_camera(capture, gaussians.means.numpy().astype(float), W, H)
    results = {}
    for wrong in (False, True):
        with Server(reply(_canned_answers(camera, gt, wrong_side=wrong))) as fake:
            stream = io.StringIO()
            joints, _ = propose_vlm(capture, gaussians, Progress("json", stream=stream),
                                    VlmConfig(endpoint=fake.endpoint, model="m", width=W, height=H))
        results[wrong] = ({j.type: j.confidence for j in joints}, stream.getvalue())
    (good, good_log), (bad, bad_log) = results[False], results[True]
    assert good["revolute"] > 0.8 and "beside the hinge" not in good_log
    assert bad["revolute"] < 0.55 * good["revolute"] and "beside the hinge" in bad_log
    assert bad["prismatic"] == good["prismatic"]
