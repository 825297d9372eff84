"""``artgs check-env``: does this interpreter have everything the engine needs?

Run by the add-on's "Check Engine" button with the interpreter set in the preferences. Imports
each dependency (so a broken install is found, not just a missing one), reports versions, CUDA and
gsplat, and exits 1 with the list of what is missing.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import platform
import sys
import tomllib
from pathlib import Path
from typing import Any


#: import name -> distribution name (for the version and the install hint).
DEPENDENCIES = {
    "numpy": "numpy",
    "torch": "torch",
    "numba": "numba",
    "scipy": "scipy",
    "cv2": "opencv-python-headless",
    "trimesh": "trimesh",
    "yourdfpy": "yourdfpy",
    "pybullet": "pybullet",
    "skimage": "scikit-image",
    "fast_simplification": "fast-simplification",
    "coacd": "coacd",
    "mujoco": "mujoco",
}


#: The package root (the extension folder, holding blender_manifest.toml).
ROOT = Path(__file__).resolve().parents[2]


def package_version(root: Path = ROOT) -> str:
    """The version in ``blender_manifest.toml`` (the add-on and the engine must agree)."""
    try:
        with open(root / "blender_manifest.toml", "rb") as f:
            return str(tomllib.load(f)["version"])
    except (OSError, KeyError, tomllib.TOMLDecodeError):
        return "unknown"


def _version(module: Any, dist: str) -> str:
    version = getattr(module, "__version__", None)
    if isinstance(version, str):
        return version
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def check_environment() -> dict[str, Any]:
    """Versions of the dependencies (None = missing, with the import error), CUDA and gsplat."""
    versions: dict[str, str | None] = {}
    problems: dict[str, str] = {}
    for name, dist in DEPENDENCIES.items():
        try:
            versions[name] = _version(importlib.import_module(name), dist)
        except Exception as exc:  # noqa: BLE001 - a broken install counts as missing, with its reason
            versions[name] = None
            problems[name] = f"{type(exc).__name__}: {exc}"
    cuda = gsplat = False
    cuda_note = "torch missing"
    if versions["torch"] is not None:
        import torch

        cuda = bool(torch.cuda.is_available())
        cuda_note = (f"CUDA {torch.version.cuda}" if cuda else
                     f"no CUDA device (torch built with CUDA: {torch.version.cuda or 'no'})")
        if cuda:
            try:
                importlib.import_module("gsplat")
                gsplat = True
            except Exception:  # noqa: BLE001
                gsplat = False
    missing = [n for n, v in versions.items() if v is None]
    return {"python": sys.executable, "python_version": platform.python_version(),
            "root": str(ROOT), "artgs": package_version(), "versions": versions,
            "problems": problems, "missing": missing, "cuda": cuda, "cuda_note": cuda_note,
            "gsplat": gsplat}


def missing_message(report: dict[str, Any]) -> str:
    """One line naming what is missing and how to install it."""
    dists = " ".join(DEPENDENCIES[n] for n in report["missing"])
    return (f"missing in {report['python']}: {', '.join(report['missing'])} "
            f"(install with: {report['python']} -m pip install {dists})")
