"""``make extension``: build dist/artgs-<version>.zip, the Blender extension, from the repo root.

    python scripts/build_extension.py [OUTPUT_DIR]        (default: dist)

Uses Blender's own extension builder (``blender --command extension build``, shipped with the
bpy module as bl_pkg/cli/blender_ext.py), so the manifest is validated and its [build]
paths_exclude_pattern is honoured exactly as Blender does.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def builder() -> Path:
    """Blender's ``blender_ext.py`` from the installed bpy module."""
    import bpy

    path = Path(bpy.utils.system_resource("SCRIPTS")) / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not path.is_file():
        sys.exit(f"error: Blender's extension builder not found at {path}")
    return path


def build(output_dir: Path) -> Path:
    """Build the extension zip into ``output_dir``; returns its path."""
    import tomllib

    with open(ROOT / "blender_manifest.toml", "rb") as f:
        manifest = tomllib.load(f)
    output_dir.mkdir(parents=True, exist_ok=True)
    target = output_dir / f"{manifest['id']}-{manifest['version']}.zip"
    subprocess.run([sys.executable, str(builder()), "build", "--source-dir", str(ROOT),
                    "--output-filepath", str(target)], check=True)
    return target


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else ROOT / "dist"
    print(build(out.resolve()))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
