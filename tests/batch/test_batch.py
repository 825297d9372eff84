"""``artgs batch``: local pool and Ray (a private Ray on 127.0.0.1), through the real command line.

Three tiny captures, one of them bad: the good ones give the same outputs as ``artgs run``, the bad
one fails alone with its message; a second call skips what is done; a worker killed mid-way is
run again; Ctrl-C stops with 130 and the next call finishes. Each worker runs one thread (two
workers on two cores), as the ``artgs run`` reference does. With one thread the splat is byte-identical
in almost every run, but not all: once in about ten runs the last bits differed (numba's fastmath
kernels may vectorise sums differently depending on array alignment), so splats and joints are
compared with tolerances far below any meaningful difference.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from artgs.core.model.joints import read_articulation
from artgs.core.model.ply import read_ply
from artgs.core.synth.generate import generate_object

ITERATIONS = "15"
#: Tiny work per stage: few iterations, the optimisation's fit alone (its searches over types,
#: parts, edges, sides and depth, fixed costs that took 76 of a run's 102 s here, are tested with
#: the stage), few export views and hulls, a short check strip.
FAST = ("--reconstruct-iterations", ITERATIONS, "--optimise-iterations", ITERATIONS,
        "--no-optimise-types", "--no-optimise-parts", "--no-optimise-edges",
        "--no-optimise-square", "--no-optimise-depth",
        "--export-views", "8", "--export-max-hulls", "2", "--export-face-budget", "500",
        "--check-frames", "2")
OUTPUTS = ("splat.ply", "proposals.json", "articulation.json", "report.json")
BACKENDS = ("local", "ray")


def _two_cores() -> None:
    """Run the batch on two cores: two workers then get one core (one thread) each."""
    cores = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, cores[:2])


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "OMP_WAIT_POLICY": "PASSIVE", **extra}


#: A hang guard, not a speed check (benchmarks measure speed): a fresh checkout's first batch
#: compiles the kernels, and beside other jobs on 2 cores it took over 300 s.
HANG = 900


def _artgs(*args: str, env: dict | None = None, timeout: float = HANG) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "artgs", *args], capture_output=True, text=True,
                          env=env or _env(), timeout=timeout, preexec_fn=_two_cores)


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "artgs", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(), preexec_fn=_two_cores)


def _backend_flags(backend: str) -> list[str]:
    return ["--ray"] if backend == "ray" else []


@pytest.fixture(scope="module")
def captures(tmp_path_factory) -> dict[str, Path]:
    """Two good tiny captures and a bad one (a frame without its pose)."""
    root = tmp_path_factory.mktemp("caps")
    good = {name: generate_object(root / name, cat, seed, width=48, height=36, static_views=6,
                                  steps=3)
            for name, cat, seed in (("cabinet", "cabinet", 3), ("drawer", "drawer", 1))}
    bad = root / "broken"
    shutil.copytree(good["cabinet"], bad)
    tj = json.loads((bad / "transforms.json").read_text())
    del tj["frames"][1]["transform_matrix"]
    (bad / "transforms.json").write_text(json.dumps(tj))
    return {**good, "broken": bad}


@pytest.fixture(scope="module")
def reference(captures, tmp_path_factory) -> dict[str, Path]:
    """``artgs run`` on the cabinet, one thread (as each batch worker here)."""
    out = tmp_path_factory.mktemp("ref") / "cabinet"
    res = _artgs("run", str(captures["cabinet"]), "--out", str(out), *FAST,
                 "--quiet", env=_env(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1"))
    assert res.returncode == 0, res.stderr
    return {"cabinet": out}


def _summary(out: Path) -> dict[str, dict]:
    data = json.loads((out / "batch_summary.json").read_text())
    return {r["name"]: r for r in data["captures"]}


def _same_outputs(got: Path, ref: Path) -> None:
    assert {p.name for p in got.iterdir()} == {p.name for p in ref.iterdir()} >= set(OUTPUTS)
    # one thread: the splat is nearly always byte-identical, but not always (module docstring)
    a, b = read_ply(got / "splat.ply"), read_ply(ref / "splat.ply")
    for field in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        x, y = getattr(a, field), getattr(b, field)
        # float noise: a cold numba cache (first kernels of a fresh checkout) moved 12 of 4316
        # quaternion values by up to 4e-3; anything beyond that is a real difference
        assert np.isclose(x, y, rtol=1e-3, atol=1e-4).mean() >= 0.99, field
        np.testing.assert_allclose(x, y, rtol=0, atol=2e-2, err_msg=field)
    for name in ("proposals.json", "articulation.json"):
        ja, jb = read_articulation(got / name).joints, read_articulation(ref / name).joints
        assert [(j.name, j.type, j.parent, j.child) for j in ja] == \
            [(j.name, j.type, j.parent, j.child) for j in jb]
        for x, y in zip(ja, jb):
            np.testing.assert_allclose(x.axis, y.axis, atol=1e-3)
            np.testing.assert_allclose(x.origin, y.origin, atol=1e-3)
            np.testing.assert_allclose(x.limit, y.limit, atol=1e-3)
    report = json.loads((got / "report.json").read_text())
    ref_report = json.loads((ref / "report.json").read_text())
    assert set(report["stages"]) == set(ref_report["stages"])
    assert report["stages"]["reconstruct"]["gaussians"] == ref_report["stages"]["reconstruct"][
        "gaussians"]


@pytest.mark.parametrize("backend", BACKENDS)
def test_batch_runs_each_capture_like_artgs_run_and_isolates_the_bad_one(
        backend, captures, reference, tmp_path):
    out = tmp_path / "batch"
    lst = tmp_path / "captures.txt"
    lst.write_text(f"# three captures\n{captures['cabinet']}\n{captures['broken']}\n")
    res = _artgs("batch", str(captures["drawer"]), "--list", str(lst), "--out", str(out),
                 "--workers", "2", *FAST, "--json", *_backend_flags(backend))
    assert res.returncode == 1, res.stderr + res.stdout   # one capture failed
    events = [json.loads(ln) for ln in res.stdout.splitlines() if ln.startswith("{")]
    bars = [e for e in events if e["event"] == "progress" and e["stage"] == "batch"]
    assert bars[-1]["fraction"] == 1.0 and bars[-1]["figures"]["done"] == 2
    assert bars[-1]["figures"]["failed"] == 1 and bars[-1]["figures"]["running"] == 0
    assert max(e["figures"]["running"] for e in bars) >= 1
    assert events[-1]["event"] == "finished"

    rows = _summary(out)
    assert list(rows) == ["drawer", "cabinet", "broken"]
    _same_outputs(out / "cabinet", reference["cabinet"])
    for name in ("cabinet", "drawer"):
        r = rows[name]
        assert r["status"] == "ok" and r["attempts"] == 1, r
        truth = read_articulation(captures[name] / "gt.json").joints
        assert r["joints"] == len(read_articulation(out / name / "articulation.json").joints)
        assert 0.0 <= r["type_accuracy"] <= 1.0 and r["ae_max_deg"] >= r["ae_mean_deg"] >= 0.0
        assert len(truth) >= 1 and r["stage_seconds"]["reconstruct"] > 0
        assert 0.0 <= r["success"] <= 1.0     # the manipulation check's success rate
        assert "1 thread(s)" in (out / f"{name}.log").read_text()
    bad = rows["broken"]
    assert bad["status"] == "failed"
    assert "transforms.json" in bad["message"] and "frame 1" in bad["message"] \
        and "transform_matrix" in bad["message"]
    assert "transform_matrix" in (out / "broken.log").read_text()
    csv = (out / "batch_summary.csv").read_text().splitlines()
    assert csv[0].startswith("name,status") and len(csv) == 4

    # again: the finished captures are skipped, their outputs untouched
    mtimes = {n: (out / n / "splat.ply").stat().st_mtime_ns for n in ("cabinet", "drawer")}
    res = _artgs("batch", str(captures["drawer"]), str(captures["cabinet"]), "--out", str(out),
                 "--workers", "2", *FAST, *_backend_flags(backend))
    assert res.returncode == 0, res.stderr
    rows = _summary(out)
    assert rows["cabinet"]["status"] == rows["drawer"]["status"] == "skipped"
    assert mtimes == {n: (out / n / "splat.ply").stat().st_mtime_ns for n in mtimes}
    assert "2 skipped" in res.stdout                    # the printed table
    if backend == "ray":
        return
    # a changed option is a changed result: that capture runs again
    res = _artgs("batch", str(captures["drawer"]), "--out", str(out), "--workers", "2",
                 "--reconstruct-iterations", "3", *FAST[2:], "--quiet")
    assert res.returncode == 0, res.stderr
    assert _summary(out)["drawer"]["status"] == "ok"
    assert (out / "drawer" / "splat.ply").stat().st_mtime_ns > mtimes["drawer"]


def _wait_for(path: Path, text: str, proc: subprocess.Popen, timeout: float = 120) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        content = path.read_text() if path.is_file() else ""
        if text in content:
            return content
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    raise AssertionError(f"{text!r} never appeared in {path}")


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_worker_killed_mid_way_is_run_again(backend, captures, reference, tmp_path):
    out = tmp_path / "batch"
    proc = _start("batch", str(captures["cabinet"]), "--out", str(out), "--workers", "2",
                  *FAST, "--quiet", *_backend_flags(backend))
    log = _wait_for(out / "cabinet.log", "[reconstruct]", proc)
    pid = int(log.split(", pid ", 1)[1].split(",", 1)[0])
    assert pid != proc.pid
    os.kill(pid, signal.SIGKILL)
    _, stderr = proc.communicate(timeout=HANG)
    assert proc.returncode == 0, stderr
    row = _summary(out)["cabinet"]
    assert row["status"] == "ok" and row["attempts"] == 2, row
    assert (out / "cabinet.log").read_text().count("=== artgs batch attempt") == 2
    _same_outputs(out / "cabinet", reference["cabinet"])
    assert not [p for p in (out / "cabinet").iterdir() if p.name.startswith(".")]


def test_local_pool_gives_up_on_a_capture_whose_worker_keeps_dying(captures, tmp_path):
    out = tmp_path / "batch"
    proc = _start("batch", str(captures["cabinet"]), "--out", str(out), "--retries", "0",
                  *FAST, "--quiet")
    log = _wait_for(out / "cabinet.log", "[reconstruct]", proc)
    os.kill(int(log.split(", pid ", 1)[1].split(",", 1)[0]), signal.SIGKILL)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 1
    row = _summary(out)["cabinet"]
    assert row["status"] == "died" and "SIGKILL" in row["message"], row
    assert "SIGKILL" in stderr


def test_ctrl_c_stops_cleanly_and_the_next_call_resumes_after_the_finished_stage(
        captures, reference, tmp_path):
    out = tmp_path / "batch"
    args = ("batch", str(captures["cabinet"]), "--out", str(out), "--workers", "2",
            *FAST)
    proc = _start(*args)
    _wait_for(out / "cabinet.log", "[propose]", proc)
    splat_mtime = (out / "cabinet" / "splat.ply").stat().st_mtime_ns
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "cancelled" in stderr and "Traceback" not in stderr
    assert _summary(out)["cabinet"]["status"] == "cancelled"
    assert not [p for p in (out / "cabinet").iterdir() if p.name.startswith(".")]

    res = _artgs(*args)
    assert res.returncode == 0, res.stderr
    assert _summary(out)["cabinet"]["status"] == "ok"
    # reconstruct had finished: not run again
    assert (out / "cabinet" / "splat.ply").stat().st_mtime_ns == splat_mtime
    assert "reconstruct: already done" in (out / "cabinet.log").read_text()
    _same_outputs(out / "cabinet", reference["cabinet"])


def test_bad_batch_input_is_refused_before_any_work(captures, tmp_path):
    res = _artgs("batch", str(captures["cabinet"]), str(captures["broken"].parent / "cabinet"),
                 "--out", str(tmp_path / "b"))
    assert res.returncode == 2 and "two captures are named 'cabinet'" in res.stderr
    res = _artgs("batch", "--list", str(tmp_path / "missing.txt"), "--out", str(tmp_path / "b"))
    assert res.returncode == 2 and "missing.txt" in res.stderr
    res = _artgs("batch", "--out", str(tmp_path / "b"))
    assert res.returncode == 2 and "no captures" in res.stderr
    assert not (tmp_path / "b").exists()
