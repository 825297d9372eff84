"""numba kernels for CPU Gaussian compositing: tile binning, blend forward and hand-written backward.

Inputs are float32 arrays of the visible Gaussians already in front-to-back order; one row of
``feats`` (M, 10) is ``mean_x, mean_y, conic_a, conic_b, conic_c, opacity, r, g, b, depth``.
Binning keeps that order inside every tile list (count, prefix sum, fill), so no per-tile sort.
The model is the one of core/raster_reference.py (its docstring lists the rules).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

NF = 10  # floats per Gaussian in ``feats`` and its gradient
POWER_CUTOFF = np.float32(4.5)
ALPHA_MIN = np.float32(1.0 / 255.0)
ALPHA_MAX = np.float32(0.99)
T_MIN = np.float32(1e-4)


@njit(cache=True)
def bin_tiles(feats, extent, width, height, tile):
    """Tile lists: ``offsets`` (tiles+1) and Gaussian ids (depth order kept inside each tile)."""
    tiles_x = (width + tile - 1) // tile
    tiles_y = (height + tile - 1) // tile
    m = feats.shape[0]
    rect = np.empty((m, 4), np.int32)
    counts = np.zeros(tiles_x * tiles_y + 1, np.int64)
    for g in range(m):
        ex = extent[g, 0] * np.float32(1.0001) + np.float32(1e-3)
        ey = extent[g, 1] * np.float32(1.0001) + np.float32(1e-3)
        j0 = max(int(np.ceil(feats[g, 0] - ex - 0.5)), 0)
        j1 = min(int(np.floor(feats[g, 0] + ex - 0.5)), width - 1)
        i0 = max(int(np.ceil(feats[g, 1] - ey - 0.5)), 0)
        i1 = min(int(np.floor(feats[g, 1] + ey - 0.5)), height - 1)
        if j0 > j1 or i0 > i1:
            rect[g, 0] = 1
            rect[g, 1] = 0
            continue
        rect[g, 0], rect[g, 1] = j0 // tile, j1 // tile
        rect[g, 2], rect[g, 3] = i0 // tile, i1 // tile
        for ty in range(rect[g, 2], rect[g, 3] + 1):
            for tx in range(rect[g, 0], rect[g, 1] + 1):
                counts[ty * tiles_x + tx + 1] += 1
    offsets = np.cumsum(counts)
    fill = offsets[:-1].copy()
    ids = np.empty(offsets[-1], np.int32)
    for g in range(m):
        if rect[g, 0] > rect[g, 1]:
            continue
        for ty in range(rect[g, 2], rect[g, 3] + 1):
            for tx in range(rect[g, 0], rect[g, 1] + 1):
                t = ty * tiles_x + tx
                ids[fill[t]] = g
                fill[t] += 1
    return offsets, ids


@njit(inline="always", fastmath=True)
def _alpha(feats, g, px, py):
    dx = px - feats[g, 0]
    dy = py - feats[g, 1]
    power = np.float32(0.5) * (feats[g, 2] * dx * dx + feats[g, 4] * dy * dy) \
        + feats[g, 3] * dx * dy
    if power > POWER_CUTOFF:
        return np.float32(0.0), np.float32(0.0), dx, dy
    gauss = np.exp(-power)
    alpha = min(ALPHA_MAX, feats[g, 5] * gauss)
    if alpha < ALPHA_MIN:
        return np.float32(0.0), gauss, dx, dy
    return alpha, gauss, dx, dy


@njit(parallel=True, fastmath=True, cache=True)
def blend_forward(feats, offsets, ids, width, height, tile, out_c, out_d, out_a, out_n):
    """Front-to-back blend per pixel: colour sum, depth sum, alpha, and list entries used."""
    tiles_x = (width + tile - 1) // tile
    tiles_y = (height + tile - 1) // tile
    for t in prange(tiles_x * tiles_y):
        ty, tx = t // tiles_x, t % tiles_x
        start, end = offsets[t], offsets[t + 1]
        for i in range(ty * tile, min(ty * tile + tile, height)):
            py = np.float32(i + 0.5)
            for j in range(tx * tile, min(tx * tile + tile, width)):
                px = np.float32(j + 0.5)
                T = np.float32(1.0)
                r = gr = b = d = np.float32(0.0)
                last = start
                for k in range(start, end):
                    g = ids[k]
                    alpha, gauss, dx, dy = _alpha(feats, g, px, py)
                    if alpha == 0.0:
                        continue
                    next_T = T * (np.float32(1.0) - alpha)
                    if next_T < T_MIN:
                        break
                    w = alpha * T
                    r += w * feats[g, 6]
                    gr += w * feats[g, 7]
                    b += w * feats[g, 8]
                    d += w * feats[g, 9]
                    T = next_T
                    last = k + 1
                out_c[i, j, 0], out_c[i, j, 1], out_c[i, j, 2] = r, gr, b
                out_d[i, j] = d
                out_a[i, j] = np.float32(1.0) - T
                out_n[i, j] = last - start


@njit(parallel=True, fastmath=True, cache=True)
def blend_backward(feats, offsets, ids, width, height, tile, out_a, out_n, g_c, g_d, g_a, grads):
    """Gradients w.r.t. ``feats`` into per-thread buffers ``grads`` (threads, M, 10).

    Each pixel walks its list back to front from its last contributor, recovering the
    transmittance before each Gaussian from the final one."""
    tiles_x = (width + tile - 1) // tile
    tiles_y = (height + tile - 1) // tile
    for t in prange(tiles_x * tiles_y):
        buf = grads[numba.get_thread_id()]
        ty, tx = t // tiles_x, t % tiles_x
        start = offsets[t]
        for i in range(ty * tile, min(ty * tile + tile, height)):
            py = np.float32(i + 0.5)
            for j in range(tx * tile, min(tx * tile + tile, width)):
                px = np.float32(j + 0.5)
                T_final = np.float32(1.0) - out_a[i, j]
                T = T_final
                gcr, gcg, gcb = g_c[i, j, 0], g_c[i, j, 1], g_c[i, j, 2]
                gd, ga = g_d[i, j], g_a[i, j]
                acc_r = acc_g = acc_b = acc_d = np.float32(0.0)
                for k in range(start + out_n[i, j] - 1, start - 1, -1):
                    g = ids[k]
                    alpha, gauss, dx, dy = _alpha(feats, g, px, py)
                    if alpha == 0.0:
                        continue
                    one_minus = np.float32(1.0) - alpha
                    T = T / one_minus
                    w = alpha * T
                    cr, cg, cb, dep = feats[g, 6], feats[g, 7], feats[g, 8], feats[g, 9]
                    buf[g, 6] += w * gcr
                    buf[g, 7] += w * gcg
                    buf[g, 8] += w * gcb
                    buf[g, 9] += w * gd
                    g_alpha = T * (gcr * (cr - acc_r) + gcg * (cg - acc_g) + gcb * (cb - acc_b)
                                   + gd * (dep - acc_d)) + ga * T_final / one_minus
                    acc_r = alpha * cr + one_minus * acc_r
                    acc_g = alpha * cg + one_minus * acc_g
                    acc_b = alpha * cb + one_minus * acc_b
                    acc_d = alpha * dep + one_minus * acc_d
                    op = feats[g, 5]
                    if op * gauss > ALPHA_MAX:
                        continue  # clamped alpha: no gradient to opacity or shape
                    buf[g, 5] += gauss * g_alpha
                    g_power = -op * gauss * g_alpha
                    buf[g, 2] += np.float32(0.5) * dx * dx * g_power
                    buf[g, 3] += dx * dy * g_power
                    buf[g, 4] += np.float32(0.5) * dy * dy * g_power
                    buf[g, 0] -= (feats[g, 2] * dx + feats[g, 3] * dy) * g_power
                    buf[g, 1] -= (feats[g, 3] * dx + feats[g, 4] * dy) * g_power


@njit(parallel=True, cache=True)
def sum_threads(grads, out):
    """out = grads.sum(axis=0), parallel over Gaussians."""
    for g in prange(grads.shape[1]):
        for f in range(grads.shape[2]):
            s = np.float32(0.0)
            for t in range(grads.shape[0]):
                s += grads[t, g, f]
            out[g, f] = s
