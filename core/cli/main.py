"""The ``artgs`` command: one sub-command per stage, plus the synthetic generator and benchmarks.

Every command takes ``--json`` (progress as JSON lines on stdout, the add-on's worker protocol) or
``--quiet``. Bad input exits with status 2 and a message naming the file and field; a cancelled run
(SIGINT/SIGTERM) exits with status 130. Stage modules are imported only when their command runs,
so ``artgs --help`` does not load torch.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
from dataclasses import fields
from typing import Callable

from ..model.errors import ArtgsError, Cancelled, InputError
from ..model.progress import Progress
from ..model.categories import EXTRA_KINDS
from ..model.regime import PRESETS, Regime
from ..render.constants import LOW_PASS

CATEGORIES = ("dishwasher", "refrigerator", "oven", "microwave", "storage", "drawer", "cabinet")

# command name -> "module:function"; the function takes (args, progress) and returns an exit code.
_COMMANDS: dict[str, str] = {
    "synth": "synth.generate:synth_command",
    "validate": "model.capture:validate_command",
    "capture-preview": "model.capture_preview:capture_preview_command",
    "run": "pipeline:run_command",
    "reconstruct": "stages.reconstruct:reconstruct_command",
    "propose": "stages.propose.stage:propose_command",
    "check-env": "model.envcheck:check_env_command",
    "bench-render": "bench.render:bench_render_command",
    "bench-reconstruct": "bench.reconstruct:bench_reconstruct_command",
    "bench-propose": "bench.propose:bench_propose_command",
}


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--json", action="store_true", help="progress as JSON lines on stdout (for the add-on)")
    g.add_argument("--quiet", action="store_true", help="print nothing but errors and warnings")


def _device(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto",
                   help="where torch work runs (auto: CUDA with gsplat if available, else CPU)")


def _regime(p: argparse.ArgumentParser) -> None:
    """--regime and one flag per core.model.regime.Regime field (default: the preset's value)."""
    p.add_argument("--regime", choices=tuple(PRESETS), default="tight",
                   help="capture regime preset (realistic: the benchmarks' default)")
    for f in fields(Regime):
        flag = "--" + f.name.replace("_", "-")
        preset = {name: getattr(r, f.name) for name, r in PRESETS.items()}
        help_ = f"{f.metadata['help']} (presets: " + ", ".join(
            f"{k} {_show(v)}" for k, v in preset.items()) + ")"
        if f.type in ("bool", bool):
            p.add_argument(flag, dest=f.name, action=argparse.BooleanOptionalAction, default=None,
                           help=help_)
        elif "tuple" in str(f.type):
            p.add_argument(flag, dest=f.name, type=float, nargs=2, metavar=("LOW", "HIGH"),
                           default=None, help=help_)
        else:
            kind = {"int": int, "float": float, "str": str}[str(f.type)]
            p.add_argument(flag, dest=f.name, type=kind, default=None, help=help_)


def _bench_set(p: argparse.ArgumentParser) -> None:
    """--set / --data of every benchmark command (core/bench/sets.py)."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("--set", default=None, metavar="SET",
                   help="tight | realistic | partnet:DIR (DIR/<kind>/<id>/mobility.urdf) | "
                        "data:DIR (default tight); see core/bench/sets.py")
    g.add_argument("--data", default=None, help="capture folders already made (= data:DIR)")


def _show(v) -> str:
    return "-".join(f"{x:g}" for x in v) if isinstance(v, tuple) else str(v)


def _vlm(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vlm-endpoint", default=None,
                   help="OpenAI-compatible base URL, e.g. http://127.0.0.1:8000/v1 "
                        "(default: $ARTGS_VLM_ENDPOINT)")
    p.add_argument("--vlm-model", default=None, help="model name (default: $ARTGS_VLM_MODEL)")
    p.add_argument("--vlm-timeout", type=float, default=60.0, help="seconds per request")


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (also used by the docs test)."""
    parser = argparse.ArgumentParser(prog="artgs", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("synth", help="generate synthetic articulated objects with ground truth",
                       description="Procedural objects (--category) or articulated URDF assets "
                                   "(--urdf), rendered under a regime (see core/model/regime.py).")
    p.add_argument("out", help="folder to write; one capture folder per object")
    p.add_argument("--category", action="append", choices=CATEGORIES + EXTRA_KINDS,
                   help="category to generate (repeatable; default all seven, plus "
                        f"{', '.join(EXTRA_KINDS)} in regimes with variety)")
    p.add_argument("--urdf", action="append", default=None, metavar="PATH",
                   help="render this articulated URDF (e.g. PartNet-Mobility <kind>/<id>/"
                        "mobility.urdf) instead of procedural objects (repeatable)")
    p.add_argument("--kind", default=None,
                   help="--urdf: the object's kind for its real size (default: the asset "
                        "folder's parent folder name)")
    p.add_argument("--joints", nargs="+", default=None, metavar="NAME",
                   help="--urdf: the joints that open parts (default: the rule in "
                        "core/synth/asset.py)")
    p.add_argument("--size", type=float, default=None,
                   help="--urdf: largest dimension in metres (default: drawn for the kind)")
    _regime(p)
    p.add_argument("--per-category", type=int, default=1, help="objects per category")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=160)
    p.add_argument("--height", type=int, default=120)
    p.add_argument("--static-views", type=int, default=24)
    p.add_argument("--steps", type=int, default=6, help="interaction steps per joint")
    p.add_argument("--depth-noise", type=float, default=0.0, help="depth noise std-dev, metres")
    p.add_argument("--simultaneous", action="store_true",
                   help="also move two joints at once in the interaction sequence")
    _common(p)

    p = sub.add_parser("validate", help="check a capture folder and print a summary")
    p.add_argument("capture")
    _common(p)

    p = sub.add_parser("capture-preview",
                       help="check a capture and write its cameras and point preview (.npz) "
                            "for Blender's Import Capture")
    p.add_argument("capture")
    p.add_argument("--preview", required=True, help=".npz file to write (atomically)")
    p.add_argument("--max-points", type=int, default=200_000,
                   help="most points in the preview (a deterministic random subset)")
    _common(p)

    p = sub.add_parser("run", help="the whole pipeline on one capture folder")
    p.add_argument("capture")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--method", choices=("motion", "vlm"), default="motion",
                   help="how joints are proposed")
    p.add_argument("--iterations", type=int, default=None, help="reconstruction iterations cap")
    _device(p)
    _vlm(p)
    _common(p)

    p = sub.add_parser("reconstruct", help="static Gaussian splat -> OUT/splat.ply")
    p.add_argument("out")
    p.add_argument("--capture", default=None, help="capture folder (default: the one recorded in OUT)")
    p.add_argument("--iterations", type=int, default=None, help="iteration cap (default: until converged)")
    p.add_argument("--holdout", type=int, default=0, help="static views held out for evaluation")
    _device(p)
    _common(p)

    p = sub.add_parser("propose", help="initial joints -> OUT/proposals.json")
    p.add_argument("out")
    p.add_argument("--capture", default=None, help="capture folder (default: the one recorded in OUT)")
    p.add_argument("--method", choices=("motion", "vlm"), default="motion")
    _device(p)
    _vlm(p)
    _common(p)

    p = sub.add_parser("check-env", help="check that the engine has every dependency")
    _common(p)

    p = sub.add_parser("bench-render", help="rasterizer speed benchmark")
    p.add_argument("--sizes", type=int, nargs="+", default=[128, 256])
    p.add_argument("--counts", type=int, nargs="+", default=[20000, 50000])
    p.add_argument("--runs", type=int, default=15)
    p.add_argument("--no-reference", action="store_true", help="skip the slow pure-torch reference")
    p.add_argument("--low-pass", type=float, default=LOW_PASS,
                   help=f"2D dilation in px^2 (default: the project's {LOW_PASS}; 0.3 = original 3DGS)")
    _common(p)

    p = sub.add_parser("bench-reconstruct", help="reconstruction quality/speed per category")
    _bench_set(p)
    p.add_argument("--per-category", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    _device(p)
    _common(p)

    p = sub.add_parser("bench-propose", help="proposal accuracy per category (motion route)")
    _bench_set(p)
    p.add_argument("--per-category", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--depth-noise", type=float, default=0.0)
    p.add_argument("--simultaneous", action="store_true",
                   help="generated sets: the first two joints also move together")
    p.add_argument("--category", nargs="+", choices=CATEGORIES + EXTRA_KINDS, default=None,
                   help="generated sets: only these categories")
    p.add_argument("--width", type=int, default=160, help="generated sets: image width")
    p.add_argument("--height", type=int, default=120, help="generated sets: image height")
    p.add_argument("--iterations", type=int, default=0,
                   help="optimise the static splat this many iterations (default 0: the "
                        "depth-initialised splat)")
    _device(p)
    _common(p)
    return parser


def _resolve(command: str) -> Callable[[argparse.Namespace, Progress], int | None]:
    module, func = _COMMANDS[command].split(":")
    return getattr(importlib.import_module(f"{__package__.rpartition('.')[0]}.{module}"), func)


def _terminate(signum, frame) -> None:  # noqa: ARG001
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``artgs`` command."""
    args = build_parser().parse_args(argv)
    mode = "json" if args.json else "quiet" if args.quiet else "text"
    progress = Progress(mode)
    # torch's OpenMP threads busy-wait between ops and starve the numba rasterizer's threads
    # (measured up to 10x slower on 2 cores); must be set before torch is imported.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    signal.signal(signal.SIGTERM, _terminate)
    try:
        code = _resolve(args.command)(args, progress)
    except InputError as exc:
        progress.error(str(exc))
        return 2
    except (KeyboardInterrupt, Cancelled):
        progress.error("cancelled")
        return 130
    except ArtgsError as exc:
        progress.error(str(exc))
        return 1
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
