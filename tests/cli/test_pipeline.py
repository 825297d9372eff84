"""``artgs run``: the whole output contract of shared/spec/outputs.md on one generated capture."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from artgs.core.model import registry
from artgs.core.model.joints import read_articulation
from artgs.core.geometry.metrics import match_joints
from artgs.core.model.ply import read_ply
from artgs.core.synth.generate import generate_object


def _artgs(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "artgs", *args], capture_output=True, text=True,
                          env=env, timeout=600)


@pytest.fixture(scope="module")
def cabinet(tmp_path_factory) -> Path:
    return generate_object(tmp_path_factory.mktemp("cap") / "cabinet", "cabinet", 3, width=96,
                           height=72, static_views=10, steps=3)


def test_run_writes_every_output_and_finds_the_joints(cabinet, tmp_path):
    out = tmp_path / "out"
    res = _artgs("run", str(cabinet), "--out", str(out), "--reconstruct-iterations", "60",
                 "--optimise-iterations", "40", "--export-views", "12", "--check-frames", "2",
                 "--json")
    assert res.returncode == 0, res.stderr + res.stdout
    events = [json.loads(line) for line in res.stdout.splitlines() if line.startswith("{")]
    stages = [e["stage"] for e in events if e["event"] == "stage_done"]
    assert stages[0] == "validate" and stages[1:] == registry.names()
    assert events[-1]["event"] == "finished"
    assert {"splat.ply", "proposals.json", "articulation.json", "part_labels.npy", "model.urdf",
            "parts", "report.json"} <= set(events[-1]["outputs"]["files"])

    splat = read_ply(out / "splat.ply")
    assert splat.means.shape[0] > 1000 and splat.sh.shape[1:] in ((1, 3), (4, 3))
    art = read_articulation(out / "articulation.json")
    assert art.meta["optimised"] is True
    assert (out / "part_labels.npy").is_file()
    gt = read_articulation(cabinet / "gt.json").joints
    for score in match_joints(art.joints, gt):
        assert score.type_correct and score.axis_error_deg < 3.0, score
        assert score.origin_error_cm is None or score.origin_error_cm < 3.0, score
    report = json.loads((out / "report.json").read_text())
    assert report["capture"] == str(cabinet.resolve())
    assert set(registry.names()) | {"run"} <= set(report["stages"])
    assert all(report["stages"][s]["seconds"] > 0 for s in registry.names() + ["run"])
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]    # no temp files left


def test_run_refuses_bad_input_before_any_work(cabinet, tmp_path):
    # a broken frame: the message names the file, the frame and the field; nothing is written
    broken = tmp_path / "broken"
    broken.mkdir()
    tj = json.loads((cabinet / "transforms.json").read_text())
    del tj["frames"][2]["transform_matrix"]
    for sub in ("images", "depth", "masks"):
        os.symlink(cabinet / sub, broken / sub)
    (broken / "transforms.json").write_text(json.dumps(tj))
    out = tmp_path / "out"
    res = _artgs("run", str(broken), "--out", str(out))
    assert res.returncode == 2
    assert "transforms.json" in res.stderr and "frame 2" in res.stderr \
        and "transform_matrix" in res.stderr
    assert not out.exists()

    # the motion route without interaction frames is refused before reconstruction starts
    tj = json.loads((cabinet / "transforms.json").read_text())
    tj["frames"] = [f for f in tj["frames"] if f.get("phase") != "interaction"]
    (broken / "transforms.json").write_text(json.dumps(tj))
    res = _artgs("run", str(broken), "--out", str(out))
    assert res.returncode == 2 and "transforms.json" in res.stderr and "interaction" in res.stderr
    assert not (out / "splat.ply").exists()

    # the VLM method without an endpoint is refused before reconstruction starts
    env = {k: v for k, v in os.environ.items() if not k.startswith("ARTGS_VLM")}
    res = _artgs("run", str(cabinet), "--out", str(out), "--method", "vlm", env=env)
    assert res.returncode == 2 and "ARTGS_VLM_ENDPOINT" in res.stderr
    assert not (out / "splat.ply").exists()


def test_run_goes_on_when_no_joint_is_proposed_and_the_optimisation_finds_the_parts(
        cabinet, tmp_path):
    """A VLM answering nonsense proposes nothing: ``artgs run`` writes proposals.json with no
    joints, says so, and the optimisation finds the moving parts in the frames (missed-part
    search), which export and check then use."""
    from vlm_server import Server, answer

    server = Server(answer("I like turtles."))
    out = tmp_path / "out"
    try:
        res = _artgs("run", str(cabinet), "--out", str(out), "--reconstruct-iterations", "60",
                     "--optimise-iterations", "40", "--export-views", "12", "--check-frames",
                     "2", "--propose-method", "vlm", "--vlm-endpoint", server.endpoint,
                     "--vlm-model", "m")
    finally:
        server.close()
    assert res.returncode == 0, res.stderr + res.stdout
    assert "vlm route found no joints" in res.stderr + res.stdout
    proposals = json.loads((out / "proposals.json").read_text())
    assert proposals["joints"] == [] and proposals["found"] == "none"
    report = json.loads((out / "report.json").read_text())
    assert report["stages"]["propose"]["found"] == "none" and "check" in report["stages"]
    art = read_articulation(out / "articulation.json")
    assert art.joints and all(j.source == "optimise" for j in art.joints)
    scores = {s.true_name: s for s in match_joints(art.joints,
                                                   read_articulation(cabinet / "gt.json").joints)}
    assert all(s.type_correct for s in scores.values()), scores
    assert scores["drawer"].axis_error_deg < 5.0, scores
    assert (out / "model.urdf").is_file()
