"""Atomic writes, progress lines and the command-line contract."""

import io
import json
import os
import subprocess
import sys

import pytest

from artgs.core.model import atomic
from artgs.core.model.errors import Cancelled
from artgs.core.model.progress import Progress


def test_atomic_write_leaves_old_file_on_failure(tmp_path):
    target = tmp_path / "splat.ply"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic.atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash mid-write")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["splat.ply"]
    atomic.write_json(target, {"a": 1})
    assert json.loads(target.read_text()) == {"a": 1}
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask     # not mkstemp's 0600


def test_json_progress_protocol_and_cancel():
    buf = io.StringIO()
    stop = {"now": False}
    p = Progress("json", stream=buf, cancel=lambda: stop["now"])
    p.start("reconstruct")
    p.update("reconstruct", 0.5, "half", loss=0.25)
    p.finish("reconstruct", psnr=31.0)
    events = [json.loads(line) for line in buf.getvalue().splitlines()]
    assert [e["event"] for e in events] == ["progress", "progress", "stage_done"]
    assert events[1]["fraction"] == 0.5 and events[1]["figures"] == {"loss": 0.25}
    assert events[2]["figures"] == {"psnr": 31.0} and events[2]["seconds"] >= 0
    stop["now"] = True
    with pytest.raises(Cancelled):
        p.update("reconstruct", 0.6)


def test_cli_help_loads_no_torch_and_bad_input_exits_2(tmp_path):
    code = ("import sys; from artgs.core.cli.app import build_parser; build_parser(); "
            "print('torch' in sys.modules, 'bpy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]
    res = subprocess.run([sys.executable, "-m", "artgs", "propose", str(tmp_path / "out"),
                          "--capture", str(tmp_path / "missing"), "--json"],
                         capture_output=True, text=True)
    assert res.returncode == 2
    last = json.loads(res.stdout.strip().splitlines()[-1])
    assert last["event"] == "error" and str(tmp_path) in last["message"]
