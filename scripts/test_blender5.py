"""The Blender 5.x half of `make test`: the Blender-side tests again, under the newest bpy 5.x.

    python scripts/test_blender5.py [PYTEST ARGS]        (run by `make test` with .venv's Python)

bpy 5.x is built for Python 3.13 only. This finds a Python 3.13 as a user's machine has it
(core/model/interpreters.py), makes or reuses ``.venv-bpy5/`` with the pins of pyproject's
``bpy5`` and ``test`` extras plus this package (no engine dependencies: Blender's process has numpy
only), and runs ``pytest --blender-only`` there. The engine those tests start is the interpreter
running this script (``ARTGS_TEST_ENGINE``). Without a Python 3.13 it says so and exits 0.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

from artgs.core.model import interpreters

ROOT = Path(__file__).resolve().parent.parent
VENV = ROOT / ".venv-bpy5"
PYTHON = (3, 13)  # bpy 5.x wheels are cp313 only


def venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def ensure_venv(base: str) -> Path:
    """``.venv-bpy5`` made by ``base`` with the pinned bpy 5.x, pytest and this package; remade
    when pyproject.toml is newer than its stamp."""
    pyproject = ROOT / "pyproject.toml"
    stamp = VENV / ".installed-stamp"
    python = venv_python(VENV)
    if stamp.is_file() and stamp.stat().st_mtime >= pyproject.stat().st_mtime and python.is_file():
        return python
    with open(pyproject, "rb") as f:
        extras = tomllib.load(f)["project"]["optional-dependencies"]
    pins = [*extras["bpy5"], *extras["test"]]
    print(f"Blender 5.x tests: making {VENV.name}/ with {base}: {', '.join(pins)}", flush=True)
    if not python.is_file():
        subprocess.run([base, "-m", "venv", str(VENV)], check=True)
    pip = [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check"]
    subprocess.run([*pip, *pins], check=True)
    # The package itself, without the engine's dependencies (they stay in .venv).
    subprocess.run([*pip, "--no-deps", "--ignore-requires-python", "-e", str(ROOT)], check=True)
    stamp.touch()
    return python


def main(argv: list[str]) -> int:
    found = interpreters.find(PYTHON, (PYTHON[0], PYTHON[1] + 1))
    if not found:
        print(f"SKIPPED the Blender 5.x half of the tests: no Python {PYTHON[0]}.{PYTHON[1]} found "
              f"(looked at {interpreters.WHERE}). Install Python {PYTHON[0]}.{PYTHON[1]} to test "
              "the add-on under bpy 5.x too.", flush=True)
        return 0
    python = ensure_venv(found[0].path)
    env = dict(os.environ, ARTGS_TEST_ENGINE=sys.executable)
    print(f"Blender 5.x tests with {found[0].label}", flush=True)
    return subprocess.call([str(python), "-m", "pytest", "-q", "--blender-only", *argv],
                           cwd=ROOT, env=env)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
