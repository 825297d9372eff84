"""Set Up Engine from the installed extension, offline: the extension zip is installed into a
temporary Blender user folder, a wheel is built from the zip's own files, and the set-up makes a
real virtual environment in the extension's user folder from that wheel folder (engine only: the
dependencies are not downloaded again). The chosen engine survives disable/enable; without online
access and without a wheel folder the set-up refuses and gives the command to run by hand."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

from engine_env import ROOT, engine_python  # noqa: E402

_spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
build_extension = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_extension)

_SETUP = """
import json, sys
import bpy
import addon_utils
zip_path, base, wheels = sys.argv[1:4]
bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                         enable_on_install=True)
name = "bl_ext.user_default.artgs"
prefs_module = sys.modules[name + ".artgs_addon.preferences"]
prefs = bpy.context.preferences.addons[name].preferences
prefs.setup_python = base
try:  # no wheel folder, no online access: refused, with the command to run by hand
    bpy.ops.artgs.setup_engine(no_deps=True)
    print("REFUSED none")
except RuntimeError as exc:
    print("REFUSED " + json.dumps(str(exc)))
prefs.setup_wheels = wheels
print("RESULT " + json.dumps(sorted(bpy.ops.artgs.setup_engine(no_deps=True))))
print("FOLDER " + str(prefs_module.user_folder()))
print("ENGINE " + prefs_module.engine_python())
print("CHECK " + json.dumps(prefs_module.last_check))
print("STATE " + (prefs_module.user_folder() / "engine.json").read_text().replace("\\n", " "))
addon_utils.disable(name, default_set=True)
addon_utils.enable(name, default_set=True)
prefs_module = sys.modules[name + ".artgs_addon.preferences"]
print("AFTER " + prefs_module.engine_python())
prefs = bpy.context.preferences.addons[name].preferences
prefs.engine_python = sys.argv[4]  # chosen by hand: kept too
addon_utils.disable(name, default_set=True)
addon_utils.enable(name, default_set=True)
print("HAND " + sys.modules[name + ".artgs_addon.preferences"].engine_python())
addon_utils.disable(name, default_set=True)
"""


@pytest.fixture(scope="module")
def wheel_folder(tmp_path_factory) -> tuple[Path, Path]:
    """(the extension zip, a folder with the engine's wheel built from the zip's files alone)."""
    tmp = tmp_path_factory.mktemp("setup")
    built = build_extension.build(tmp / "dist")
    source = tmp / "source"
    zipfile.ZipFile(built).extractall(source)
    wheels = tmp / "wheels"
    subprocess.run([engine_python(), "-m", "pip", "wheel", "--quiet", "--no-deps",
                    "--no-build-isolation", "--no-index", "-w", str(wheels), str(source)],
                   check=True, capture_output=True, timeout=300)
    return built, wheels


def test_set_up_engine_from_a_wheel_folder(wheel_folder, tmp_path):
    built, wheels = wheel_folder
    assert [p.name for p in wheels.iterdir()] == ["artgs-0.1.0-py3-none-any.whl"]
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    env.pop("PYTHONPATH", None)  # the engine must come from the new environment alone
    hand = str(tmp_path / "my-python")
    proc = subprocess.run([sys.executable, "-c", _SETUP, str(built), engine_python(),
                           str(wheels), hand],
                          capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    out = dict(line.split(" ", 1) for line in proc.stdout.splitlines()
               if line.split(" ", 1)[0] in ("REFUSED", "RESULT", "FOLDER", "ENGINE", "CHECK",
                                            "STATE", "AFTER", "HAND"))
    assert out.get("HAND") == hand, proc.stdout[-3000:] + proc.stderr[-3000:]
    refused = json.loads(out["REFUSED"])
    assert "Allow Online Access" in refused and " -m venv " in refused and "pip install" in refused
    assert json.loads(out["RESULT"]) == ["FINISHED"]
    folder = Path(out["FOLDER"])
    assert folder == tmp_path / "user" / "extensions" / ".user" / "user_default" / "artgs"
    python = folder / "engine-venv" / "bin" / "python"
    assert out["ENGINE"] == str(python) == out["AFTER"]  # kept across disable/enable
    assert json.loads((folder / "engine.json").read_text())["python"] == hand
    state = json.loads(out["STATE"])
    assert state["status"] == "READY" and state["addon_version"] == "0.1.0"
    # The new environment runs the engine (installed from the wheel, not this checkout) and
    # Check Engine ran on it: the engine's version matches, its dependencies are missing.
    code = "import artgs, json; from artgs.core.model import envcheck; " \
           "print(json.dumps([artgs.__file__, envcheck.package_version()]))"
    where, version = json.loads(subprocess.run([str(python), "-c", code], capture_output=True,
                                               text=True, env=env, check=True).stdout)
    assert where.startswith(str(folder / "engine-venv")) and version == "0.1.0"
    check = json.loads(out["CHECK"])
    assert any(line.startswith(f"Python 3.11") and str(python) in line for line in check)
    assert any("missing" in line and "torch" in line for line in check)
    assert not any("Set Up Engine" in line for line in check)  # same version: no handshake note


def test_engine_of_another_version_is_reported_with_the_fix():
    from artgs.artgs_addon.engine_setup import EngineState
    from artgs.operators.engine import check_lines

    lines = check_lines({"python": "/x/python", "python_version": "3.11.7", "versions": {},
                         "artgs": "0.0.9", "root": "/x/artgs", "missing": []})
    assert any("version 0.0.9" in line and "press Set Up Engine" in line for line in lines)
    old = EngineState(python="/x/python", addon_version="0.0.9", status="READY")
    assert "press Set Up Engine" in old.version_note()
    assert EngineState(python="/x", addon_version="0.1.0", status="READY").version_note() is None


def test_zip_carries_what_the_engine_is_built_from(wheel_folder):
    names = set(zipfile.ZipFile(wheel_folder[0]).namelist())
    assert {"pyproject.toml", "README.md", "core/__init__.py", "core/model/__init__.py",
            "core/model/interpreters.py", "artgs_addon/engine_setup.py"} <= names


def test_set_up_plan_cpu_cuda_and_wheel_folder(tmp_path):
    from artgs.artgs_addon import engine_setup

    python = str(tmp_path / "engine-venv" / "bin" / "python")
    cpu = engine_setup.plan(tmp_path, "/usr/bin/python3.11", ROOT)
    assert [argv[:3] for _, argv in cpu.steps] == [
        ("/usr/bin/python3.11", "-m", "venv"), (python, "-m", "pip"), (python, "-m", "pip")]
    torch_step = cpu.steps[1][1]
    assert "torch==2.13.0" in torch_step and torch_step[-2:] == (
        "--index-url", engine_setup.TORCH_INDEX["cpu"])
    assert cpu.steps[2][1][-1] == str(tmp_path / "engine-source")  # built from the copy
    cuda = engine_setup.plan(tmp_path, "/usr/bin/python3.11", ROOT, torch="cuda")
    assert cuda.steps[1][1][-1] == engine_setup.TORCH_INDEX["cuda"] != torch_step[-1]
    # by hand: one command line, the engine built from the extension folder itself
    line = cpu.command_line(ROOT)
    assert line.count(" && ") == 2 and line.endswith(str(ROOT)) and "engine-source" not in line
    offline = engine_setup.plan(tmp_path, "/usr/bin/python3.11", ROOT, find_links=tmp_path / "w")
    for _, argv in offline.steps[1:]:
        assert argv[argv.index("--find-links") + 1] == str(tmp_path / "w") and "--no-index" in argv
        assert "--index-url" not in argv
    assert offline.steps[-1][1][-1] == "artgs==0.1.0" and offline.source is None
    with pytest.raises(ValueError, match="torch must be one of"):
        engine_setup.plan(tmp_path, "/usr/bin/python3.11", ROOT, torch="rocm")
