"""The Blender extension: manifest fields, the built zip's contents, and installing + enabling it
with bpy into a temporary user folder (a subprocess, so this process's bpy is untouched)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("bpy")
ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
build_extension = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(build_extension)


@pytest.fixture(scope="module")
def manifest() -> dict:
    with open(ROOT / "blender_manifest.toml", "rb") as f:
        return tomllib.load(f)


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    return build_extension.build(tmp_path_factory.mktemp("dist"))


def test_manifest_fields(manifest):
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["id"] == "artgs" and manifest["type"] == "add-on"
    for key in ("version", "name", "tagline", "maintainer"):
        assert isinstance(manifest[key], str) and manifest[key].strip(), key
    assert len(manifest["tagline"]) <= 64 and not manifest["tagline"].endswith(".")
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["license"] and all(x.startswith("SPDX:") for x in manifest["license"])
    assert set(manifest["permissions"]) == {"files", "network"}
    for reason in manifest["permissions"].values():  # Blender's limits for the reasons
        assert 0 < len(reason) <= 64 and not reason.endswith(".")
    with open(ROOT / "pyproject.toml", "rb") as f:
        assert tomllib.load(f)["project"]["version"] == manifest["version"]


def test_zip_contents(built, manifest):
    assert built.name == f"artgs-{manifest['version']}.zip"
    names = zipfile.ZipFile(built).namelist()
    for required in ("__init__.py", "blender_manifest.toml", "artgs_addon/__init__.py",
                     "core/cli/app.py", "operators/_job.py", "panels/pipeline.py",
                     "scripts/headless_pipeline.py"):
        assert required in names, required
    assert not [n for n in names if n.startswith(("tests/", ".venv/", ".ci/", ".git/", "dist/"))
                or "__pycache__" in n or n.endswith(".pyc") or ".egg-info" in n
                or n in ("scripts/demo.py", "scripts/build_extension.py", "scripts/bench_preview.py",
                      "Makefile")]


_INSTALL = """
import sys, bpy
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default",
                                         enable_on_install=True)
name = "bl_ext.user_default.artgs"
print("ENABLED", name in bpy.context.preferences.addons)
print("FILE", sys.modules[name].__file__)
print("OPS", sorted(dir(bpy.ops.artgs)))
print("CAP", bpy.context.preferences.addons[name].preferences.preview_cap)
import addon_utils
addon_utils.disable(name, default_set=False)
print("DISABLED", "import_capture" not in dir(bpy.ops.artgs))
"""


def test_installs_and_enables_under_bpy(built, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    proc = subprocess.run([sys.executable, "-c", _INSTALL, str(built)], capture_output=True,
                          text=True, timeout=300, env=env, cwd=tmp_path)
    out = dict(line.split(" ", 1) for line in proc.stdout.splitlines()
               if line.split(" ", 1)[0] in ("ENABLED", "FILE", "OPS", "CAP", "DISABLED"))
    assert out.get("ENABLED") == "True", proc.stdout[-2000:] + proc.stderr[-2000:]
    assert out["FILE"] == str(tmp_path / "user" / "extensions" / "user_default" / "artgs" /
                              "__init__.py")
    for op in ("import_capture", "reconstruct", "import_splat", "propose_bones", "check_engine"):
        assert f"'{op}'" in out["OPS"], op
    assert out["CAP"] == "200000" and out["DISABLED"] == "True"
