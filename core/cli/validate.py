"""``artgs validate CAPTURE``: load and check a capture, print a summary."""

from __future__ import annotations

import argparse

from ..model.progress import Progress

NAME = "validate"
HELP = "check a capture folder and print a summary"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("capture")


def run(args: argparse.Namespace, progress: Progress) -> int:
    from ..model.capture import load_capture, summarize  # numpy: only when the command runs (check-env works without it)

    summary = summarize(load_capture(args.capture))
    if progress.mode == "text":
        s = summary
        sizes = ", ".join(f"{w}x{h}" for w, h in s["image_sizes"])
        depth = (f"{s['depth_min_m']:.3f} .. {s['depth_max_m']:.3f} m"
                 if s["depth_min_m"] is not None else "none")
        print(f"capture {s['capture']}: valid\n"
              f"  frames: {s['frames']} ({s['static_frames']} static, "
              f"{s['interaction_frames']} interaction)\n"
              f"  image size: {sizes}\n"
              f"  interaction times: {s['interaction_times'] or 'none'}\n"
              f"  depth: {s['frames_with_depth']} frames, range {depth}\n"
              f"  masks: {s['frames_with_mask']} frames\n"
              f"  undistorted on load: {s['undistorted_frames']} frames\n"
              f"  robot: {s['robot'] or 'none'}")
    progress.finished(**summary)
    return 0
