"""``artgs synth OUT``: synthetic articulated objects (or rendered URDF assets) with ground truth."""

from __future__ import annotations

import argparse
from dataclasses import asdict, fields
from pathlib import Path

from ..model.progress import Progress
from ..model.regime import PRESETS, Regime, regime
from ..synth.options import SynthOptions
from .options import add_options, build

NAME = "synth"
HELP = "generate synthetic articulated objects with ground truth"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_options(p, SynthOptions)
    g = p.add_argument_group("regime settings (default: the --regime preset's)")
    for f in fields(Regime):
        flag = "--" + f.name.replace("_", "-")
        presets = ", ".join(f"{k} {_show(getattr(r, f.name))}" for k, r in PRESETS.items())
        help_ = f"{f.metadata['help']} (presets: {presets})".replace("%", "%%")
        if f.type in ("bool", bool):
            g.add_argument(flag, dest=f"regime_{f.name}", action=argparse.BooleanOptionalAction,
                           default=None, help=help_)
        elif "tuple" in str(f.type):
            g.add_argument(flag, dest=f"regime_{f.name}", type=float, nargs=2,
                           metavar=("LOW", "HIGH"), default=None, help=help_)
        else:
            g.add_argument(flag, dest=f"regime_{f.name}", default=None, help=help_,
                           metavar=f.name.upper(),
                           type={"int": int, "float": float, "str": str}[str(f.type)])


def _show(v) -> str:
    return "-".join(f"{x:g}" for x in v) if isinstance(v, tuple) else str(v)


def run(args: argparse.Namespace, progress: Progress) -> int:
    from ..synth.generate import generate_assets, generate_set

    opts = asdict(build(SynthOptions, args))
    reg = regime(opts.pop("regime"), **{f.name: getattr(args, f"regime_{f.name}")
                                        for f in fields(Regime)})
    out, seed = opts.pop("out"), opts.pop("seed")
    urdfs, kind, joints, size = (opts.pop(k) for k in ("urdf", "kind", "joints", "size"))
    category, per_category = opts.pop("category"), opts.pop("per_category")
    if urdfs:
        paths = generate_assets(out, [Path(u) for u in urdfs], seed, progress, kind=kind,
                                joints=joints, size=size, regime=reg, **opts)
    else:
        paths = generate_set(out, category, per_category, seed, progress, regime=reg, **opts)
    progress.finished(captures=[str(p) for p in paths])
    return 0
