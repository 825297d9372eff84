"""``artgs capture-preview CAPTURE --preview FILE``: cameras and a point preview for Blender."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..model.errors import InputError
from ..model.progress import Progress

NAME = "capture-preview"
HELP = "check a capture and write its cameras and point preview (.npz) for Blender's Import Capture"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("capture")
    p.add_argument("--preview", required=True, help=".npz file to write (atomically)")
    p.add_argument("--max-points", type=int, default=200_000,
                   help="most points in the preview (a deterministic random subset)")


def run(args: argparse.Namespace, progress: Progress) -> int:
    # numpy: imported when the command runs, so check-env works without it
    from ..model.capture import load_capture
    from ..model.capture_preview import write_preview

    if args.max_points < 1:
        raise InputError("--max-points", f"must be at least 1, not {args.max_points}")
    progress.start("capture", "reading the capture")
    capture = load_capture(args.capture)
    progress.update("capture", 0.7, f"{len(capture.frames)} frames read; sampling points")
    preview = write_preview(capture, args.preview, args.max_points)
    kept = len(preview.points)
    progress.finish("capture", cameras=len(capture.frames), points=kept,
                    points_total=preview.points_total)
    progress.finished(preview=str(Path(args.preview)), points=kept,
                      points_total=preview.points_total, **preview.summary)
    return 0
