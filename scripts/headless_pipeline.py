"""Run the ArtGS pipeline headless through the add-on's operators.

    blender --background --python scripts/headless_pipeline.py -- CAPTURE OUT [options]
    python scripts/headless_pipeline.py CAPTURE OUT [options]        (bpy as a module)

Imports the capture, reconstructs the splat, proposes the joints as an armature, optimises them,
exports the URDF and lets a robot check it (each stage in the engine worker, as in the UI; stop
earlier with ``--until``), then writes OUT/scene.blend and OUT/preview.png (the engine's
labelled contact sheet of every stage) next to the engine's outputs. Inside Blender the enabled extension whose module ends in ``.artgs`` is used
(enabled first if installed but off); with bpy as a module the ``artgs`` package is enabled.
Exits 1 with the engine's message if a stage fails.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import bpy  # first: with bpy as a module, importing it puts addon_utils on the path
import addon_utils  # noqa: E402


#: Engine stages from the proposals on (the registry's names), in order, as the add-on's
#: operators run them.
UNTIL = ("propose", "optimise", "export", "check")


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
    p.add_argument("--optimise-iterations", type=int, default=0,
                   help="steps of the joint optimisation's main fit (0: the engine's default)")
    p.add_argument("--until", choices=UNTIL, default=UNTIL[-1],
                   help="last stage to run (default: all of them)")
    p.add_argument("--engine", default="", help="engine interpreter (default: the preference)")
    p.add_argument("--preview-size", type=int, default=240,
                   help="width of one panel of preview.png (the contact sheet), pixels")
    p.add_argument("--panels", type=Path, default=None,
                   help="also write each labelled panel of the contact sheet as PANELS/<stage>.png")
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
    if not op.poll():
        sys.exit(f"error: {label} cannot start: {not_ready()}")
    try:
        result = op(**kwargs)
    except RuntimeError as exc:  # the operator reported an error: the engine's message
        sys.exit(f"error: {label} failed: {str(exc).removeprefix('Error: ').strip()}")
    if "FINISHED" not in result:
        sys.exit(f"error: {label} did not finish ({', '.join(result)})")
    print(f"{label}: {time.perf_counter() - t0:.1f} s", flush=True)


def not_ready() -> str:
    """Why an engine operator's poll refuses: the scene's folders and the stages' states (an
    operator cannot start while another job runs or without a capture and output folder)."""
    settings = bpy.context.scene.artgs
    capture = settings.capture_path
    states = "; ".join(f"{name} {settings.stage(name).text}"
                       for name in ("capture", "reconstruct", "propose"))
    return (f"capture folder {capture} (transforms.json "
            f"{'found' if capture and (capture / 'transforms.json').is_file() else 'MISSING'}), "
            f"output folder {settings.output_path}; stages: {states}")


def contact_sheet(module: str, capture: Path, out: Path, width: int,
                  panels: Path | None) -> None:
    """OUT/preview.png: the engine's labelled contact sheet of every stage's result
    (``artgs contact-sheet``), with the interpreter the add-on uses."""
    engine = sys.modules[f"{module}.artgs_addon.preferences"].engine_python()
    argv = [engine, "-m", "artgs", "contact-sheet", str(out), "--capture", str(capture),
            "--width", str(width), "--quiet"] + (["--panels", str(panels)] if panels else [])
    proc = subprocess.run(argv, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"error: contact sheet failed: {proc.stderr.strip().splitlines()[-1:]}")
    print(f"preview: {out / 'preview.png'}", flush=True)


def run(args: argparse.Namespace, module: str) -> None:
    """Every stage through the operators; save OUT/scene.blend and OUT/preview.png."""
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
    steps = UNTIL[:UNTIL.index(args.until) + 1]
    if "optimise" in steps:
        run_stage("optimise joints", bpy.ops.artgs.optimise_joints,
                  iterations=args.optimise_iterations)
    if "export" in steps:
        run_stage("export URDF", bpy.ops.artgs.export_urdf)
    if "check" in steps:
        run_stage("check manipulation", bpy.ops.artgs.check_manipulation)
    for stage in ("capture", "reconstruct", *steps):
        print(f"  {stage}: {settings.stage(stage).text}")
    contact_sheet(module, capture, out, args.preview_size, args.panels)
    bpy.ops.wm.save_as_mainfile(filepath=str(out / "scene.blend"))
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
