"""``artgs bench-render``: rasterizer speed on a synthetic shell of Gaussians.

Scene (fixed seed): N Gaussians on a sphere of radius 0.5 m centred 1.5 m in front of the camera;
focal 1.2 W, principal point at the image centre; scales log-normal (sigma 0.3) around 0.6x the
mean point spacing; random rotations; opacities uniform in [0.1, 0.9]; random colours as SH
degree 0. Timings are medians after warm-up with 2 torch and 2 numba threads; "fwd" is the
forward pass with autograd recording, "fwd+bwd" adds the backward of a weighted sum of rgb,
depth and alpha. Pairs = Gaussian-pixel pairs actually blended.
"""

from __future__ import annotations

import math
import os
import statistics
import time

import numba
import numpy as np
import torch

from ..render.cpu import blend_kernels as rk
from ..render.cpu.jit import kernel
from ..render.cpu.project import project
from ..render.rasterize import rasterize
from ..render.sh import rgb_to_sh0
from ..render.threads import set_threads
from .options import BenchRenderOptions

THREADS = 2
AUTOGRAD_BUDGET_BYTES = 3e9  # the reference's fwd+bwd is skipped above this estimate


def shell_scene(n: int, size: int, seed: int = 0):
    """(params list, K, w2c) of the benchmark scene at ``size`` x ``size`` pixels."""
    g = torch.Generator().manual_seed(seed)
    radius, centre = 0.5, torch.tensor([0.0, 0.0, 1.5])
    d = torch.randn(n, 3, generator=g)
    means = centre + radius * d / d.norm(dim=1, keepdim=True)
    spacing = math.sqrt(4 * math.pi * radius ** 2 / n)
    log_scales = math.log(0.6 * spacing) + 0.3 * torch.randn(n, 3, generator=g)
    quats = torch.randn(n, 4, generator=g)
    quats = quats / quats.norm(dim=1, keepdim=True)
    op = 0.1 + 0.8 * torch.rand(n, generator=g)
    sh = rgb_to_sh0(torch.rand(n, 3, generator=g))[:, None, :]
    K = np.array([[1.2 * size, 0.0, size / 2], [0.0, 1.2 * size, size / 2], [0.0, 0.0, 1.0]])
    return [means, quats, log_scales, torch.log(op / (1 - op)), sh], K, np.eye(4)


@kernel
def _count_pairs(feats, offsets, ids, width, height):
    """Gaussian-pixel pairs blended by the forward kernel (same rules)."""
    tw, th = rk.TILE_W, rk.TILE_H
    tiles_x = (width + tw - 1) // tw
    total = 0
    for t in range(len(offsets) - 1):
        ty, tx = t // tiles_x, t % tiles_x
        for i in range(ty * th, min(ty * th + th, height)):
            for j in range(tx * tw, min(tx * tw + tw, width)):
                T = np.float32(1.0)
                for k in range(offsets[t], offsets[t + 1]):
                    g = ids[k]
                    dx, dy = np.float32(j + 0.5) - feats[g, 0], np.float32(i + 0.5) - feats[g, 1]
                    power = 0.5 * (feats[g, 2] * dx * dx + feats[g, 4] * dy * dy) \
                        + feats[g, 3] * dx * dy
                    alpha = min(rk.ALPHA_MAX, feats[g, 5] * rk.exp_neg(power))
                    if power > rk.POWER_CUTOFF or alpha < rk.ALPHA_MIN:
                        continue
                    if T * (np.float32(1.0) - alpha) < rk.T_MIN:
                        break
                    T *= np.float32(1.0) - alpha
                    total += 1
    return total


def blended_pairs(params, K, w2c, size, low_pass: float) -> tuple[int, int]:
    """(blended pairs, pixels inside 3 sigma boxes of tile lists) for the scene."""
    with torch.no_grad():
        Kt, wt = torch.as_tensor(K, dtype=torch.float32), torch.as_tensor(w2c, dtype=torch.float32)
        proj = project(params[0], params[1], params[2], Kt, wt, size, size, low_pass=low_pass)
        vis = torch.nonzero(proj.visible).squeeze(1)
        order = vis[torch.argsort(proj.depths[vis], stable=True)]
        feats = torch.cat([proj.means2d[order], proj.conics[order],
                           torch.sigmoid(params[3][order, None]), torch.zeros(len(order), 3),
                           proj.depths[order, None]], 1).numpy()
        ext = np.ascontiguousarray(proj.extent[order].numpy())
    offsets, ids = rk.bin_tiles(np.ascontiguousarray(feats), ext, size, size)
    return int(_count_pairs(feats, offsets, ids, size, size)), int(offsets[-1])


def _time(fn, runs: int, warmup: int = 2) -> tuple[float, float, float]:
    """(median wall, min wall, median process CPU time over all threads) of ``fn`` in ms."""
    for _ in range(warmup):
        fn()
    wall, cpu = [], []
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return 1e3 * statistics.median(wall), 1e3 * min(wall), 1e3 * statistics.median(cpu)


def _reference_memory(params, K, w2c, size) -> float:
    """Rough autograd memory of the reference at this size (bytes): ~12 float32 per block entry."""
    from ..render.cpu.project import as_tensor
    with torch.no_grad():
        p = project(params[0], params[1], params[2], as_tensor(K, params[0]),
                    as_tensor(w2c, params[0]), size, size)
        m, e = p.means2d[p.visible], p.extent[p.visible]
        blocks = math.ceil(size / 16)
        lo = ((m - e) / 16).floor().clamp(0, blocks - 1)
        hi = ((m + e) / 16).floor().clamp(0, blocks - 1)
        n_block_pairs = float(((hi - lo + 1).prod(dim=1)).sum())
    return n_block_pairs * 256 * 12 * 4


def bench_one(size: int, n: int, backend: str, runs: int, grad: bool, low_pass: float
              ) -> tuple[float, float, float]:
    """``_time`` of the forward (grad=False) or forward+backward (grad=True) pass."""
    params, K, w2c = shell_scene(n, size)
    ps = [p.clone().requires_grad_(True) for p in params]
    g = torch.Generator().manual_seed(1)
    wc = torch.rand(size, size, 3, generator=g)

    def step():
        out = rasterize(*ps, K, w2c, size, size, background=[0.0, 0.0, 0.0], backend=backend,
                        low_pass=low_pass)
        if grad:
            loss = (out.rgb * wc).sum() + out.depth.sum() + out.alpha.sum()
            loss.backward()
            for p in ps:
                p.grad = None
    return _time(step, runs)


def bench_render(args: BenchRenderOptions, progress) -> int:
    """Print forward / forward+backward timings of the CPU kernels and the reference."""
    set_threads(THREADS)
    say = print if progress.mode == "text" else (lambda *a, **k: None)
    say(f"bench-render: shell scene, SH degree 0, low-pass {args.low_pass} px^2, threads torch={torch.get_num_threads()} "
        f"numba={numba.get_num_threads()}, median of {args.runs} runs after 2 warm-up runs; "
        f"machine load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    say("wall times: median (min) ms; cpu: median process CPU ms (all threads; less sensitive "
        "to a busy machine); pairs/s from the wall medians")
    say(f"{'size':>8} {'N':>7} {'pairs':>9} {'backend':>10} {'fwd ms':>15} {'fwd+bwd ms':>15} "
        f"{'f+b cpu':>9} {'pairs/s fwd':>12} {'pairs/s f+b':>12}")
    results = []
    cases = [(s, n) for s in args.sizes for n in args.counts]
    for idx, (size, n) in enumerate(cases):
        params, K, w2c = shell_scene(n, size)
        pairs, _ = blended_pairs(params, K, w2c, size, args.low_pass)
        rows = [("cpu", args.runs, "")]
        if not args.no_reference:
            mem = _reference_memory(params, K, w2c, size)
            note = (f"fwd+bwd skipped (autograd would need ~{mem / 1e9:.1f} GB)"
                    if mem > AUTOGRAD_BUDGET_BYTES else "")
            rows.append(("reference", max(3, args.runs // 5), note))
        for backend, runs, note in rows:
            progress.update("bench-render", idx / len(cases), f"{size}^2 N={n} {backend}")
            fwd = bench_one(size, n, backend, runs, False, args.low_pass)
            both = None if note else bench_one(size, n, backend, runs, True, args.low_pass)
            results.append({"size": size, "n": n, "pairs": pairs, "backend": backend, "runs": runs,
                            "fwd_ms": round(fwd[0], 2), "fwd_min_ms": round(fwd[1], 2),
                            "fwd_bwd_ms": None if both is None else round(both[0], 2),
                            "fwd_bwd_min_ms": None if both is None else round(both[1], 2),
                            "fwd_bwd_cpu_ms": None if both is None else round(both[2], 2)})
            fwd_s = f"{fwd[0]:.1f} ({fwd[1]:.1f})"
            both_s = "-" if both is None else f"{both[0]:.1f} ({both[1]:.1f})"
            cpu_s = "-" if both is None else f"{both[2]:.1f}"
            rate_b = "-" if both is None else f"{pairs / both[0] * 1e3:.3g}"
            say(f"{size:>6}^2 {n:>7} {pairs:>9} {backend:>10} {fwd_s:>15} {both_s:>15} {cpu_s:>9} "
                f"{pairs / fwd[0] * 1e3:>12.3g} {rate_b:>12}"
                + (f"  [{runs} runs]" if runs != args.runs else "") + (f"  {note}" if note else ""))
    progress.finished(results=results, load_average=os.getloadavg()[0])
    return 0
