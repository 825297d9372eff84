"""``artgs check-env``: is every engine dependency installed? (exit 1 if not)."""

from __future__ import annotations

import argparse

from ..model.envcheck import check_environment, missing_message
from ..model.progress import Progress

NAME = "check-env"
HELP = "check that the engine has every dependency"


def add_arguments(p: argparse.ArgumentParser) -> None:  # noqa: ARG001 - no arguments
    pass


def run(args: argparse.Namespace, progress: Progress) -> int:  # noqa: ARG001
    report = check_environment()
    for name, version in report["versions"].items():
        if version is None:
            progress.log(f"{name}: MISSING ({report['problems'][name]})", "warning")
        else:
            progress.log(f"{name} {version}")
    progress.log(f"device: {report['cuda_note']}; gsplat: {'yes' if report['gsplat'] else 'no'}")
    progress.finished(**report)
    if report["missing"]:
        progress.error(missing_message(report))
        return 1
    return 0
