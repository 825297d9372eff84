"""Where torch work runs, and which rasterizer backend renders (worker side only: imports torch)."""

from __future__ import annotations

import torch

from ..model.errors import ArtgsError

BACKENDS = ("auto", "cpu", "reference", "gsplat")


def resolve_device(device: str | torch.device = "auto") -> torch.device:
    """``"auto"`` -> CUDA if available else CPU; ``"cuda"`` without CUDA raises ArtgsError."""
    if isinstance(device, torch.device):
        device = str(device)
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ArtgsError(f"device {device!r} was requested but CUDA is not available "
                             f"(torch {torch.__version__}, built with CUDA: "
                             f"{torch.version.cuda or 'no'}); use --device cpu")
        return torch.device(device)
    if device == "cpu":
        return torch.device("cpu")
    raise ArtgsError(f"unknown device {device!r}; expected auto, cpu or cuda")


def gsplat_available() -> bool:
    """True if CUDA works and the gsplat package imports."""
    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_backend(backend: str, device: torch.device) -> str:
    """Rasterizer backend for tensors on ``device``: gsplat on CUDA, the numba kernels on CPU."""
    if backend not in BACKENDS:
        raise ArtgsError(f"unknown rasterizer backend {backend!r}; expected one of {BACKENDS}")
    if backend == "auto":
        return "gsplat" if device.type == "cuda" and gsplat_available() else "cpu"
    if backend == "gsplat" and not gsplat_available():
        raise ArtgsError("rasterizer backend 'gsplat' needs CUDA and the gsplat package")
    return backend
