"""Run the ArtGS pipeline headless through the add-on's operators.

    blender --background --python scripts/headless_pipeline.py -- CAPTURE OUT [options]
    python scripts/headless_pipeline.py CAPTURE OUT [options]        (bpy as a module)

Imports the capture, reconstructs the splat and proposes the joints as an armature (each stage in
the engine worker, as in the UI), then writes OUT/scene.blend and OUT/preview.png next to the
engine's outputs. Inside Blender the enabled extension whose module ends in ``.artgs`` is used
(enabled first if installed but off); with bpy as a module the ``artgs`` package is enabled.
Exits 1 with the engine's message if a stage fails.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import bpy  # first: with bpy as a module, importing it puts addon_utils on the path
import addon_utils  # noqa: E402


def _argv() -> list[str]:
    """The script's own arguments (after ``--`` when run by the Blender binary)."""
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def parse_args(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="headless_pipeline.py", description=__doc__.splitlines()[0])
    p.add_argument("capture", type=Path, help="capture folder (transforms.json, images/, depth/)")
    p.add_argument("out", type=Path, help="output folder")
    p.add_argument("--method", choices=("motion", "vlm"), default="motion",
                   help="joint proposal method")
    p.add_argument("--iterations", type=int, default=0,
                   help="reconstruction iteration cap (0: until converged)")
    p.add_argument("--engine", default="", help="engine interpreter (default: the preference)")
    p.add_argument("--preview-size", type=int, default=320, help="preview.png width, pixels")
    return p.parse_args(argv)


def enable_addon() -> str:
    """Module name of the enabled ArtGS add-on, enabling it if it is installed but off."""
    enabled = [name for name in bpy.context.preferences.addons.keys()
               if name == "artgs" or name.endswith(".artgs")]
    if enabled:
        return enabled[0]
    installed = [m.__name__ for m in addon_utils.modules() if m.__name__.endswith(".artgs")]
    name = installed[0] if installed else "artgs"
    if addon_utils.enable(name, default_set=True, handle_error=None) is None:
        sys.exit(f"error: the ArtGS add-on ({name}) could not be enabled; install the extension "
                 "(Edit > Preferences > Get Extensions > Install from Disk) or run with the "
                 "engine's Python, where the artgs package is installed")
    return name


def clear_scene() -> None:
    """Start from an empty scene (the default cube, light and camera go)."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)


def run_stage(label: str, op, **kwargs) -> None:
    """Run one operator synchronously; exit 1 with the engine's message on failure."""
    t0 = time.perf_counter()
    try:
        result = op(**kwargs)
    except RuntimeError as exc:  # the operator reported an error: the engine's message
        sys.exit(f"error: {label} failed: {str(exc).removeprefix('Error: ').strip()}")
    if "FINISHED" not in result:
        sys.exit(f"error: {label} did not finish ({', '.join(result)})")
    print(f"{label}: {time.perf_counter() - t0:.1f} s", flush=True)


def render_preview(scene: bpy.types.Scene, path: Path, width: int) -> None:
    """Render the scene's camera to ``path`` with Cycles on the CPU, 8 samples.

    Cycles shows the points' colour attribute and needs no GPU context (under a second at
    320x240 here); Workbench draws point clouds without their colours and EEVEE without a GPU
    falls back to software OpenGL (86 s for the same image here).
    """
    render = scene.render
    render.resolution_percentage = max(1, round(100 * width / render.resolution_x))
    render.image_settings.file_format = "PNG"
    render.filepath = str(path)
    render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 8
    scene.cycles.use_denoising = False
    scene.world = scene.world or bpy.data.worlds.new("ArtGS World")
    scene.world.color = (0.05, 0.05, 0.05)
    sys.stdout.flush()
    saved = os.dup(1)
    try:  # Cycles logs every render phase on the C stdout: keep the script's output readable
        with open(os.devnull, "wb") as devnull:
            os.dup2(devnull.fileno(), 1)
            bpy.ops.render.render(write_still=True)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    print(f"preview rendered: {path}", flush=True)


def run(args: argparse.Namespace, module: str) -> None:
    """Import, reconstruct, propose; save OUT/scene.blend and OUT/preview.png."""
    capture, out = args.capture.resolve(), args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    clear_scene()
    scene = bpy.context.scene
    settings = scene.artgs
    settings.capture_dir = str(capture)
    settings.output_dir = str(out)
    settings.proposal_method = args.method
    if args.engine:
        bpy.context.preferences.addons[module].preferences.engine_python = args.engine
    run_stage("import capture", bpy.ops.artgs.import_capture)
    run_stage("reconstruct", bpy.ops.artgs.reconstruct, iterations=args.iterations)
    run_stage("propose bones", bpy.ops.artgs.propose_bones)
    for stage in ("capture", "splat", "bones"):
        print(f"  {stage}: {settings.stage(stage).text}")
    # Render from the first capture camera, showing the splat preview (not the capture's points).
    capture_points = [o for o in scene.objects if o.type == "MESH" and o != settings.splat_object]
    for obj in capture_points:
        obj.hide_render = True
    render_preview(scene, out / "preview.png", args.preview_size)
    for obj in capture_points:
        obj.hide_render = False
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "scene.blend"))
    print(f"preview: {out / 'preview.png'}")
    print(f"scene: {out / 'scene.blend'}")


def main(argv: list[str]) -> int:
    args = parse_args(argv)
    module = enable_addon()
    try:
        run(args, module)
    finally:
        if not bpy.app.binary_path:
            # bpy as a module can hang at exit while Python-defined property groups are registered.
            addon_utils.disable(module, default_set=False, handle_error=None)
    return 0


if __name__ == "__main__":
    sys.exit(main(_argv()))
