"""The worker client (no bpy): real ``python -m artgs`` subprocesses, progress, errors, cancel."""

from __future__ import annotations

import json
import os
import signal
import stat
import sys
import time
from pathlib import Path

import pytest

from artgs.artgs_addon.worker import Worker, parse_line, worker_command
from artgs.core.cli import check_env
from artgs.core.model.protocol import EXIT_CANCELLED as CANCELLED
from artgs.core.model import envcheck
from artgs.core.model.progress import Progress

ENGINE = sys.executable


def test_command_line_shape():
    assert worker_command("/py", "reconstruct", ["OUT", "--iterations", 5]) == \
        ["/py", "-m", "artgs", "reconstruct", "OUT", "--iterations", "5", "--json"]


def test_parse_line_events_and_stray_output():
    assert parse_line('{"event": "progress", "stage": "s", "fraction": 0.5}\n')["fraction"] == 0.5
    # C libraries print to stdout too (pybullet's banner): such lines become info logs.
    for line in ("pybullet build time: Jan 29 2025", '{"not": "an event"}', "{broken"):
        event = parse_line(line)
        assert event == {"event": "log", "level": "info", "message": line}


def test_progress_events_from_a_real_command(tmp_path):
    w = Worker(ENGINE, "synth", [tmp_path / "set", "--category", "drawer", "--per-category", "2",
                                 "--width", "48", "--height", "36", "--static-views", "3",
                                 "--steps", "2"]).start()
    seen = []
    result = w.wait(timeout=120, on_events=seen.extend)
    assert result.ok and result.returncode == 0 and result.error is None
    progress = [e for e in seen if e["event"] == "progress"]
    assert [round(e["fraction"], 2) for e in progress] == [0.0, 0.5, 1.0]
    assert progress[-1]["message"] == "drawer_01"
    assert [e["stage"] for e in seen if e["event"] == "stage_done"] == ["synth"]
    assert result.outputs["captures"] == [str(tmp_path / "set" / f"drawer_{k:02d}") for k in (0, 1)]


def test_engine_error_reaches_the_user_without_traceback(tmp_path):
    result = Worker(ENGINE, "reconstruct", [tmp_path / "out", "--capture", tmp_path / "none"]
                    ).start().wait(timeout=120)
    assert result.returncode == 2 and not result.ok
    assert result.error.startswith(str(tmp_path / "none")) and "not found" in result.error
    assert "Traceback" not in result.error


def test_engine_without_the_package_is_named(tmp_path):
    """An interpreter that cannot import artgs: the last stderr line, with the interpreter."""
    engine = tmp_path / "python-no-site"
    engine.write_text(f'#!/bin/sh\nexec "{ENGINE}" -S "$@"\n')
    engine.chmod(engine.stat().st_mode | stat.S_IEXEC)
    result = Worker(str(engine), "check-env").start().wait(timeout=60)
    assert result.returncode == 1
    assert str(engine) in result.error and "No module named artgs" in result.error


def test_missing_interpreter_names_the_preference():
    with pytest.raises(OSError, match="Engine Python"):
        Worker("/no/such/python", "check-env").start()


def test_cancel_ends_the_process(tmp_path):
    out = tmp_path / "set"
    w = Worker(ENGINE, "synth", [out, "--per-category", "50", "--width", "48", "--height", "36"],
               grace=10.0).start()
    deadline = time.monotonic() + 120
    while not any(e["event"] == "progress" and e["fraction"] > 0 for e in w.poll()):
        assert w.running and time.monotonic() < deadline
        time.sleep(0.05)
    t0 = time.monotonic()
    w.cancel()
    result = w.wait(timeout=30)
    assert time.monotonic() - t0 < 10.0
    assert not w.running and result.cancelled and not result.ok
    assert result.returncode == CANCELLED  # the engine's SIGTERM handler ran (not a kill)
    assert result.error == "cancelled"


def _handles_sigterm(pid: int) -> bool:
    """Whether process ``pid`` has installed a SIGTERM handler (Linux: SigCgt in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGTERM - 1) & 1)
    return False


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="needs Linux /proc")
@pytest.mark.parametrize("when", ["starting", "importing"])
def test_cancel_while_the_engine_starts_or_imports(tmp_path, when):
    """Cancel before the engine's SIGTERM handler exists (Python still starting: killed by the
    signal) and after it, while the stage's modules (torch ...) are imported (exit 130): both
    end cancelled, never as an engine error."""
    w = Worker(ENGINE, "reconstruct", [tmp_path / "out", "--capture", tmp_path / "none"]).start()
    if when == "importing":
        deadline = time.monotonic() + 60
        while not _handles_sigterm(w.pid):
            assert w._proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.002)
    w.cancel()
    result = w.wait(timeout=30)
    # the capture would have been refused (exit 2) had the engine got past its imports
    assert result.returncode == (-signal.SIGTERM if when == "starting" else CANCELLED)
    assert result.cancelled and not result.ok and result.error == "cancelled"
    assert not (tmp_path / "out").exists()


def test_cancel_after_the_end_keeps_the_outcome(tmp_path):
    w = Worker(ENGINE, "validate", [tmp_path / "none"]).start()
    w.wait(timeout=60)
    w.cancel()  # too late: the engine had already refused the capture
    result = w.result
    assert result.returncode == 2 and not result.cancelled
    assert result.error.startswith(str(tmp_path / "none"))


def test_check_env_reports_versions_and_missing(monkeypatch, capsys):
    assert check_env.run(None, Progress("json")) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    outputs = lines[-1]["outputs"]
    assert lines[-1]["event"] == "finished" and outputs["missing"] == []
    assert set(outputs["versions"]) == set(envcheck.DEPENDENCIES)
    assert outputs["versions"]["numpy"] == __import__("numpy").__version__
    assert outputs["cuda"] in (True, False) and outputs["python"] == sys.executable
    assert outputs["artgs"] == envcheck.package_version()

    monkeypatch.setitem(envcheck.DEPENDENCIES, "artgs_no_such_module", "no-such-dist")
    assert check_env.run(None, Progress("json")) == 1
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines[-1]["event"] == "error"
    assert "artgs_no_such_module" in lines[-1]["message"] and "pip install" in lines[-1]["message"]
    assert os.path.basename(sys.executable) in lines[-1]["message"]


def test_package_version_reads_the_manifest(tmp_path):
    (tmp_path / "blender_manifest.toml").write_text('id = "artgs"\nversion = "9.8.7"\n')
    assert envcheck.package_version(tmp_path) == "9.8.7"
    assert envcheck.package_version(Path(tmp_path / "none")) == "unknown"
