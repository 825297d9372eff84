"""The engine's interpreter for Blender-side tests, and captures made through it.

`make test` runs the Blender-side tests twice: with bpy 4.5 in the engine's own venv, and with
bpy 5.x in a Python 3.13 venv that has numpy only (scripts/test_blender5.py). There the engine
(torch, cv2, ...) is the first venv's interpreter, named by ``ARTGS_TEST_ENGINE``; whatever needs
the engine in a test goes through it, as the add-on itself does.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
#: Set by scripts/test_blender5.py: the interpreter that has the engine's dependencies.
ENGINE_VARIABLE = "ARTGS_TEST_ENGINE"


def engine_python() -> str:
    """The interpreter with the engine: ``$ARTGS_TEST_ENGINE``, else this one."""
    return os.environ.get(ENGINE_VARIABLE) or sys.executable


def generate_capture(folder: Path, category: str, seed: int, **options) -> Path:
    """``artgs.core.synth.generate.generate_object`` run by the engine's interpreter."""
    code = ("import sys; from pathlib import Path; "
            "from artgs.core.synth.generate import generate_object; "
            f"print(generate_object(Path({str(folder)!r}), {category!r}, {seed!r}, **{options!r}))")
    proc = subprocess.run([engine_python(), "-c", code], capture_output=True, text=True,
                          timeout=600)
    if proc.returncode != 0:
        raise RuntimeError(f"generating the capture failed:\n{proc.stderr[-3000:]}")
    return Path(proc.stdout.strip().splitlines()[-1])


def engine_json(code: str):
    """Run ``code`` in the engine's interpreter; it leaves a JSON-able value in ``result``."""
    script = f"import json\n{code}\nprint('RESULT ' + json.dumps(result))"
    proc = subprocess.run([engine_python(), "-c", script], capture_output=True, text=True,
                          timeout=600)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"the engine's interpreter failed:\n{proc.stderr[-3000:]}")
    import json

    return json.loads(lines[-1][len("RESULT "):])
