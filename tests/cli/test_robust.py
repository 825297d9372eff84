"""Bad input, big input, two runs, Ctrl-C (issue 13), each through the real command line.

Every refusal: the documented exit code, one line of message naming the file (or path) and the
field, no traceback, and OUT byte-identical to before.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from http.server import BaseHTTPRequestHandler
from pathlib import Path

import cv2
import numpy as np
import pytest

from artgs.core.model import layout
from artgs.core.model.capture import load_capture
from artgs.core.model.joints import Articulation, Joint, write_articulation
from artgs.core.model.lock import LOCK
from artgs.core.model.ply import read_ply, write_ply
from artgs.core.model.progress import Progress
from artgs.core.model.protocol import EXIT_BAD_INPUT, EXIT_CANCELLED, EXIT_FAILED
from artgs.core.stages.reconstruct import reconstruct
from artgs.core.synth.generate import generate_object

from ply_poke import poke_ply  # noqa: E402 - tests/ is on sys.path under pytest
from vlm_server import Server, answer  # noqa: E402

ENV = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p),
       "OMP_WAIT_POLICY": "PASSIVE"}


def artgs(*args: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "artgs", *args], capture_output=True, text=True,
                          env=env or ENV, timeout=timeout)


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative name -> bytes); {} when it does not exist."""
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def refused(res: subprocess.CompletedProcess, code: int, *words: str) -> str:
    """Assert exit ``code`` with exactly one message line (text mode) holding ``words``."""
    lines = res.stderr.strip().splitlines()
    assert res.returncode == code, res.stderr + res.stdout
    assert "Traceback" not in res.stderr + res.stdout
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1, res.stderr
    for w in words:
        assert w in errors[0], (w, errors[0])
    return errors[0]


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    return generate_object(tmp_path_factory.mktemp("cap") / "cabinet", "cabinet", 5, width=64,
                           height=48, static_views=6, steps=2)


@pytest.fixture(scope="module")
def done(capture, tmp_path_factory) -> Path:
    """An OUT after reconstruct, with a proposals.json holding a joint the user added."""
    out = tmp_path_factory.mktemp("done") / "out"
    reconstruct(load_capture(capture), out, Progress("quiet"), iterations=3, device="cpu")
    layout.update_report(out, capture=str(capture.resolve()))
    user = Joint("door_by_hand", "revolute", [0, 0, 1], [0.1, 0.2, 0.3], (0.0, 1.2),
                 source="user")
    write_articulation(out / layout.PROPOSALS, Articulation([user], {"source": "user"}))
    return out


@pytest.fixture
def out(done, tmp_path) -> Path:
    """A fresh copy of ``done`` for one test."""
    copy = tmp_path / "out"
    shutil.copytree(done, copy)
    return copy


# --- splat.ply -----------------------------------------------------------------------------------

def test_splat_with_nan_positions_is_refused_naming_element_and_field(out):
    poke_ply(out / layout.SPLAT, 7, "y", np.nan)
    before = snapshot(out)
    res = artgs("propose", str(out))
    refused(res, EXIT_BAD_INPUT, "splat.ply", "vertex[7]", "field 'y'")
    assert snapshot(out) == before


def test_splat_with_zero_gaussians_is_refused(out):
    empty = read_ply(out / layout.SPLAT)
    write_ply(out / layout.SPLAT, type(empty)(empty.means[:0], empty.quats[:0],
                                              empty.log_scales[:0], empty.opacity_logits[:0],
                                              empty.sh[:0]))
    before = snapshot(out)
    res = artgs("propose", str(out))
    refused(res, EXIT_BAD_INPUT, "splat.ply", "no Gaussians", "field 'vertex'")
    assert snapshot(out) == before


# --- a stage that finds nothing ------------------------------------------------------------------

def test_vlm_answering_nonsense_fails_and_keeps_the_users_proposals(out):
    server = Server(answer("I like turtles. {\"parts\": 42}"))
    try:
        before = snapshot(out)
        res = artgs("propose", str(out), "--method", "vlm", "--vlm-endpoint", server.endpoint,
                    "--vlm-model", "m", "--quiet")
    finally:
        server.close()
    refused(res, EXIT_FAILED, "found no joints", "proposals.json", "left as it was")
    assert snapshot(out) == before
    assert json.loads((out / layout.PROPOSALS).read_text())["joints"][0]["source"] == "user"


def test_optimising_no_joints_without_adding_parts_is_refused(out):
    write_articulation(out / layout.PROPOSALS, Articulation([], {"source": "motion"}))
    before = snapshot(out)
    res = artgs("optimise", str(out), "--no-parts")
    refused(res, EXIT_BAD_INPUT, "proposals.json", "holds no joints", "--no-parts",
            "field 'joints'")
    assert snapshot(out) == before


def test_vlm_timeout_is_a_deadline_for_the_whole_request(out):
    def trickle(h: BaseHTTPRequestHandler, body) -> None:
        h.send_response(200)
        h.send_header("Content-Length", "100000")
        h.end_headers()
        for _ in range(100000):
            h.wfile.write(b" ")
            h.wfile.flush()
            time.sleep(0.1)

    server = Server(trickle)
    try:
        before = snapshot(out)
        res = artgs("propose", str(out), "--method", "vlm", "--vlm-endpoint", server.endpoint,
                    "--vlm-model", "m", "--vlm-timeout", "1.5", "--quiet")
        time.sleep(0.3)
    finally:
        server.close()
    refused(res, EXIT_FAILED, server.endpoint, "within 1.5 s")
    assert snapshot(out) == before
    assert len(server.requests) == 1 and server.closed
    assert server.closed[0] - server.requests[0].at < 1.5 + 0.5


# --- OUT itself ----------------------------------------------------------------------------------

def test_out_that_is_a_file_or_under_a_file_is_refused_naming_the_path(capture, tmp_path):
    file = tmp_path / "a_file"
    file.write_bytes(b"mine")
    res = artgs("reconstruct", str(file), "--capture", str(capture))
    refused(res, EXIT_BAD_INPUT, str(file), "existing file")
    res = artgs("run", str(capture), "--out", str(file / "sub" / "out"))
    refused(res, EXIT_BAD_INPUT, str(file / "sub" / "out"), f"{file} is a file")
    assert file.read_bytes() == b"mine" and sorted(tmp_path.iterdir()) == [file]


@pytest.fixture
def read_only(tmp_path):
    """Make a folder read-only, also for root (chattr +i), and writable again afterwards."""
    made: list[Path] = []

    def make(folder: Path) -> None:
        if os.geteuid() == 0:
            if shutil.which("chattr") is None or subprocess.run(
                    ["chattr", "+i", str(folder)], capture_output=True).returncode:
                pytest.skip("running as root without chattr: no way to make a folder read-only")
        else:
            folder.chmod(0o555)
        made.append(folder)

    yield make
    for folder in made:
        if os.geteuid() == 0:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        else:
            folder.chmod(0o755)


def test_read_only_out_is_refused_before_any_work(capture, tmp_path, read_only):
    out = tmp_path / "ro"
    out.mkdir()
    read_only(out)
    start = time.perf_counter()
    res = artgs("reconstruct", str(out), "--capture", str(capture), "--iterations", "500")
    refused(res, EXIT_BAD_INPUT, str(out), "cannot write")
    assert "reconstruct" not in res.stdout   # the stage never started
    assert time.perf_counter() - start < 60
    assert snapshot(out) == {}


def test_malformed_report_is_refused_naming_the_key(out):
    report = json.loads((out / layout.REPORT).read_text())
    report["capture"] = 5
    (out / layout.REPORT).write_text(json.dumps(report))
    before = snapshot(out)
    res = artgs("propose", str(out))
    refused(res, EXIT_BAD_INPUT, "report.json", "field 'capture'")
    assert snapshot(out) == before
    report["capture"], report["stages"] = str(Path(__file__)), ["not", "a", "dict"]
    (out / layout.REPORT).write_text(json.dumps(report))
    refused(artgs("reconstruct", str(out)), EXIT_BAD_INPUT, "report.json", "field 'stages'")


def test_reconstruct_records_the_capture_only_after_the_work(capture, tmp_path):
    out = tmp_path / "out"
    res = artgs("reconstruct", str(out), "--capture", str(capture), "--holdout", "99")
    refused(res, EXIT_BAD_INPUT, "holdout")
    assert snapshot(out) == {}     # not even the folder: a refused first run leaves nothing
    assert artgs("reconstruct", str(out), "--capture", str(capture), "--iterations", "2",
                 "--quiet").returncode == 0
    report = json.loads((out / layout.REPORT).read_text())
    assert report["capture"] == str(capture.resolve()) and "reconstruct" in report["stages"]


# --- big frames ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def big_capture(capture, tmp_path_factory) -> Path:
    """The capture with every image upscaled 15x (64x48 -> 960x720), intrinsics with it."""
    big = tmp_path_factory.mktemp("big") / "cabinet"
    shutil.copytree(capture, big)
    tj = json.loads((big / "transforms.json").read_text())
    for holder in [tj] + tj["frames"]:
        for key in ("fl_x", "fl_y", "cx", "cy", "w", "h"):
            if key in holder:
                holder[key] = holder[key] * 15
        for key, interp in (("file_path", cv2.INTER_LINEAR), ("mask_path", cv2.INTER_NEAREST)):
            if key in holder:
                path = big / holder[key]
                img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
                cv2.imwrite(str(path), cv2.resize(img, None, fx=15, fy=15, interpolation=interp))
        if "depth_file_path" in holder:   # float metres (.npy) -> 16-bit millimetre PNG
            depth = np.load(big / holder["depth_file_path"])
            holder["depth_file_path"] = holder["depth_file_path"].replace(".npy", ".png")
            mm = np.round(np.nan_to_num(depth) * 1000).astype(np.uint16)
            cv2.imwrite(str(big / holder["depth_file_path"]),
                        cv2.resize(mm, None, fx=15, fy=15, interpolation=cv2.INTER_NEAREST))
    (big / "transforms.json").write_text(json.dumps(tj))
    return big


def test_big_frames_run_at_the_working_resolution(big_capture, tmp_path):
    out = tmp_path / "out"
    res = artgs("reconstruct", str(out), "--capture", str(big_capture), "--iterations", "2",
                "--max-side", "96")
    assert res.returncode == 0, res.stderr
    assert "working resolution 96x72 (--max-side 96" in res.stderr and "960x720" in res.stderr
    splat = read_ply(out / layout.SPLAT)
    small = load_capture(big_capture, max_side=96)
    assert small.frames[0].camera.width == 96 and small.frames[0].rgb.shape == (72, 96, 3)
    full = json.loads((big_capture / "transforms.json").read_text())
    fx = full["frames"][0].get("fl_x", full.get("fl_x"))
    assert small.frames[0].camera.K[0, 0] == pytest.approx(fx / 10)
    assert len(splat) > 100


def test_big_frames_that_would_not_fit_are_refused_before_work(big_capture, tmp_path):
    out = tmp_path / "out"
    res = artgs("reconstruct", str(out), "--capture", str(big_capture), "--max-side", "0",
                env={**ENV, "ARTGS_MEMORY_LIMIT": "400M"})
    refused(res, EXIT_BAD_INPUT, "--max-side", "960x720", "GB")
    assert snapshot(out) == {}


# --- two runs, Ctrl-C, SIGKILL -------------------------------------------------------------------

def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "artgs", *args, "--json"], env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_iterations(proc: subprocess.Popen, stage: str = "reconstruct") -> None:
    """Read JSON lines until ``stage`` reports optimisation progress (the rasterizer runs)."""
    for line in proc.stdout:
        event = json.loads(line)
        if event.get("stage") == stage and event.get("fraction", 0) > 0:
            return
    raise AssertionError(f"{stage} never reported progress: {proc.stderr.read()}")


def _finish(proc: subprocess.Popen) -> tuple[int, list[dict], str]:
    stdout, stderr = proc.communicate(timeout=120)
    return proc.returncode, [json.loads(line) for line in stdout.splitlines()], stderr


def test_second_run_into_the_same_out_is_refused_naming_the_first(capture, out):
    before = snapshot(out)
    first = _start("reconstruct", str(out), "--iterations", "100000")
    try:
        _wait_for_iterations(first)
        res = artgs("run", str(capture), "--out", str(out))
        refused(res, EXIT_BAD_INPUT, LOCK, f"pid {first.pid}")
    finally:
        first.send_signal(signal.SIGINT)
        code, events, stderr = _finish(first)
    assert code == EXIT_CANCELLED and stderr == ""
    assert [e["event"] for e in events if e["event"] == "error"] == ["error"]
    assert snapshot(out) == before


@pytest.mark.parametrize("delay", [0.0, 0.3, 0.7])
def test_ctrl_c_in_the_rasterizer_exits_130_with_out_as_before(out, delay):
    before = snapshot(out)
    proc = _start("reconstruct", str(out), "--iterations", "100000")
    _wait_for_iterations(proc)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    code, events, stderr = _finish(proc)
    assert code == EXIT_CANCELLED, stderr
    assert stderr == ""    # no traceback, no SystemError
    errors = [e for e in events if e["event"] == "error"]
    assert len(errors) == 1 and "cancelled" in errors[0]["message"]
    assert snapshot(out) == before


def test_lock_and_temporaries_of_a_killed_run_are_taken_over(capture, out):
    killed = subprocess.run([sys.executable, "-c", (
        "import os, signal, sys\n"
        "from artgs.core.model.lock import out_lock\n"
        "from artgs.core.model.atomic import atomic_path\n"
        "with out_lock(sys.argv[1], 'artgs reconstruct'):\n"
        "    with atomic_path(os.path.join(sys.argv[1], 'splat.ply')) as tmp:\n"
        "        tmp.write_bytes(b'half a splat')\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"), str(out)], env=ENV)
    assert killed.returncode == -signal.SIGKILL
    stale = [p.name for p in out.iterdir() if ".tmp" in p.name]
    assert (out / LOCK).exists() and len(stale) == 1
    (out / ".notes.tmp").write_text("the user's own file")   # not ours: kept
    res = artgs("reconstruct", str(out), "--iterations", "2", "--quiet")
    assert res.returncode == 0, res.stderr
    names = {p.name for p in out.iterdir()}
    assert not names & set(stale) and LOCK not in names and ".notes.tmp" in names
    read_ply(out / layout.SPLAT)


def test_nothing_is_run_twice_through_the_lock_in_one_process(tmp_path):
    """``artgs run`` holds the lock while its stages take it again (re-entrant per process)."""
    from artgs.core.model.errors import InputError
    from artgs.core.model.lock import out_lock
    with out_lock(tmp_path, "outer"):
        with out_lock(tmp_path, "inner"):
            assert (tmp_path / LOCK).exists()
        assert (tmp_path / LOCK).exists()
        other = subprocess.run([sys.executable, "-c",
                                "import sys\nfrom artgs.core.model.lock import out_lock\n"
                                "with out_lock(sys.argv[1]): pass\n", str(tmp_path)],
                               env=ENV, capture_output=True, text=True)
        assert other.returncode == 1 and f"pid {os.getpid()}" in other.stderr
        assert "outer" in other.stderr and InputError.__name__ in other.stderr
    assert not (tmp_path / LOCK).exists()


def test_temporaries_are_only_removed_under_the_lock(tmp_path):
    from artgs.core.model.atomic import remove_stale_temporaries
    fd, tmp = tempfile.mkstemp(prefix=".splat.", suffix=".tmp.ply", dir=tmp_path)
    os.close(fd)
    (tmp_path / "parts").mkdir()
    fd, part = tempfile.mkstemp(prefix=".door.", suffix=".tmp.obj", dir=tmp_path / "parts")
    os.close(fd)
    keep = [tmp_path / "splat.ply", tmp_path / ".artgs.lock", tmp_path / ".x.tmp"]
    for p in keep:
        p.write_text("x")
    assert sorted(remove_stale_temporaries(tmp_path)) == sorted([Path(tmp), Path(part)])
    assert all(p.exists() for p in keep)


def test_reconstruction_that_ends_empty_or_diverged_keeps_the_last_splat():
    from artgs.core.model.errors import ArtgsError, NothingFound
    from artgs.core.model.ply import SplatArrays
    from artgs.core.stages.reconstruct import _refuse_unusable
    n = 3
    ok = SplatArrays(np.zeros((n, 3), np.float32), np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                     np.full((n, 3), -3, np.float32), np.zeros(n, np.float32),
                     np.zeros((n, 4, 3), np.float32))
    _refuse_unusable(ok, 10)
    empty = SplatArrays(ok.means[:0], ok.quats[:0], ok.log_scales[:0], ok.opacity_logits[:0],
                        ok.sh[:0])
    with pytest.raises(NothingFound, match="no Gaussians after 10 iterations.*left as it was"):
        _refuse_unusable(empty, 10)
    ok.sh[1, 2, 0] = np.nan
    with pytest.raises(ArtgsError, match=r"diverged after 10 iterations \(Gaussian 1's sh is nan"):
        _refuse_unusable(ok, 10)
