"""numba kernels for CPU Gaussian compositing: tile binning, blend forward and hand-written backward.

Inputs are float32 arrays of the visible Gaussians already in front-to-back order; one row of
``feats`` (M, 12) is ``mean_x, mean_y, conic_a, conic_b, conic_c, opacity, r, g, b, depth,
slope_x, slope_y`` (planar depth ``depth + slope . (p - mean)`` at pixel p).
Binning keeps that order inside every tile list (count, prefix sum, fill), so no per-tile sort.
The model is the one of core/render/reference.py (its docstring lists the rules).

The blend loops run Gaussian-outer, pixel-inner over the pixels of a tile, branch-free
(selects instead of branches, a polynomial exp), so LLVM vectorises them. A pixel that reaches
the transmittance limit stores its transmittance negated (= done). The backward pass walks each
tile's list back to front from the last contributor of any of its pixels and recovers every
pixel's transmittance before a Gaussian from the final one; per-Gaussian sums go to per-thread
buffers (no atomics).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .. import constants as model
from .jit import kernel

NF = 12  # floats per Gaussian in ``feats`` and its gradient
TILE_W, TILE_H = 4, 4  # pixels per tile; the blend loops vectorise over its TILE_W * TILE_H pixels
NPIX = TILE_W * TILE_H
f32 = np.float32
POWER_CUTOFF = f32(model.POWER_CUTOFF)
ALPHA_MIN = f32(model.ALPHA_MIN)
ALPHA_MAX = f32(model.ALPHA_MAX)
T_MIN = f32(model.T_MIN)
_ZERO, _HALF, _ONE = f32(0.0), f32(0.5), f32(1.0)
_EXP_C = tuple(f32(1.0 / c) for c in (8.0, 2.0, 6.0, 24.0, 120.0, 720.0, 5040.0))


@njit(inline="always", fastmath=True)
def exp_neg(x):
    """exp(-x) for x <= POWER_CUTOFF (larger x is treated as POWER_CUTOFF), relative error < 5e-6
    up to 4.5; vectorisable.

    exp(-x) = (e^y)^8, y = -x/8, e^y by its degree-7 Taylor polynomial in Estrin form (short
    dependency chains)."""
    y = -min(x, POWER_CUTOFF) * _EXP_C[0]
    y2 = y * y
    y4 = y2 * y2
    p = (_ONE + y) + y2 * (_EXP_C[1] + y * _EXP_C[2]) \
        + y4 * ((_EXP_C[3] + y * _EXP_C[4]) + y2 * (_EXP_C[5] + y * _EXP_C[6]))
    p = p * p
    p = p * p
    return p * p


@kernel
def spread_stride(n):
    """A stride coprime with n near 0.618 n: i -> (i * stride) % n visits 0..n-1 once each and
    spreads any contiguous run of i over the whole range. Used on rows of tiles, so prange's
    contiguous per-thread split stays balanced when the content is in one part of the image
    (tiles within a row stay in order, for cache locality)."""
    stride = max(1, int(n * 0.6180339887))
    while True:
        a, b = stride, n
        while b:
            a, b = b, a % b
        if a == 1:
            return stride
        stride += 1


@kernel
def depth_order(depths, candidates):
    """``candidates`` sorted by ``depths`` (all > 0), stable: LSD radix sort on the float bits."""
    keys = depths.view(np.uint32)
    order = candidates.copy()
    other = np.empty_like(order)
    for shift in range(0, 32, 8):
        counts = np.zeros(257, np.int64)
        for i in range(order.shape[0]):
            counts[((keys[order[i]] >> shift) & 255) + 1] += 1
        if counts.max() == order.shape[0]:
            continue  # every key has the same byte here
        pos = np.cumsum(counts)
        for i in range(order.shape[0]):
            b = (keys[order[i]] >> shift) & 255
            other[pos[b]] = order[i]
            pos[b] += 1
        order, other = other, order
    return order


@kernel
def sort_visible(proj, extent, visible):
    """The visible rows of ``proj`` (N,12) front to back: (order, feats (M,12), extent (M,2))."""
    order = depth_order(np.ascontiguousarray(proj[:, 9]), np.flatnonzero(visible))
    feats = np.empty((order.shape[0], NF), np.float32)
    ext = np.empty((order.shape[0], 2), np.float32)
    for m in range(order.shape[0]):   # element loops: row slices made this copy 0.5 of 0.6 ms
        g = order[m]
        for c in range(NF):
            feats[m, c] = proj[g, c]
        ext[m, 0] = extent[g, 0]
        ext[m, 1] = extent[g, 1]
    return order, feats, ext


@kernel
def bin_tiles(feats, extent, width, height):
    """Tile lists: ``offsets`` (tiles+1) and Gaussian ids (depth order kept inside each tile)."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    tiles_y = (height + TILE_H - 1) // TILE_H
    m = feats.shape[0]
    rect = np.empty((m, 4), np.int32)
    counts = np.zeros(tiles_x * tiles_y + 1, np.int64)
    for g in range(m):
        ex = extent[g, 0] * f32(1.0001) + f32(1e-3)
        ey = extent[g, 1] * f32(1.0001) + f32(1e-3)
        j0 = max(int(np.ceil(feats[g, 0] - ex - _HALF)), 0)
        j1 = min(int(np.floor(feats[g, 0] + ex - _HALF)), width - 1)
        i0 = max(int(np.ceil(feats[g, 1] - ey - _HALF)), 0)
        i1 = min(int(np.floor(feats[g, 1] + ey - _HALF)), height - 1)
        if j0 > j1 or i0 > i1:
            rect[g, 0], rect[g, 1] = 1, 0
            continue
        rect[g, 0], rect[g, 1] = j0 // TILE_W, j1 // TILE_W
        rect[g, 2], rect[g, 3] = i0 // TILE_H, i1 // TILE_H
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


@njit(inline="always")
def tile_at(it, tiles_x, tiles_y, stride):
    """The ``it``-th tile visited (rows spread by :func:`spread_stride`'s ``stride``): its index
    and the row and column of its first pixel."""
    t = ((it // tiles_x) * stride) % tiles_y * tiles_x + it % tiles_x
    return t, (t // tiles_x) * TILE_H, (t % tiles_x) * TILE_W


@kernel(parallel=True, fastmath=True)
def blend_forward(feats, offsets, ids, width, height, out_c, out_d, out_a, out_n):
    """Front-to-back blend: colour sum (H,W,3), depth sum, alpha, and per pixel the number of
    tile-list entries up to its last contributor."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    tiles_y = (height + TILE_H - 1) // TILE_H
    stride = spread_stride(tiles_y)
    for it in prange(tiles_x * tiles_y):
        t, i0, j0 = tile_at(it, tiles_x, tiles_y, stride)
        px = np.empty(NPIX, np.float32)
        py = np.empty(NPIX, np.float32)
        T = np.empty(NPIX, np.float32)
        acc = np.zeros((4, NPIX), np.float32)
        last = np.zeros(NPIX, np.int32)
        done = 0
        for p in range(NPIX):
            i, j = i0 + p // TILE_W, j0 + p % TILE_W
            px[p], py[p] = f32(j + 0.5), f32(i + 0.5)
            inside = i < height and j < width
            T[p] = _ONE if inside else -_ONE
            done += 0 if inside else 1
        start = offsets[t]
        for k in range(start, offsets[t + 1]):
            if done == NPIX:
                break
            g = ids[k]
            mx, my, ca, cb, cc = feats[g, 0], feats[g, 1], feats[g, 2], feats[g, 3], feats[g, 4]
            op, cr, cg, cbl, dep = feats[g, 5], feats[g, 6], feats[g, 7], feats[g, 8], feats[g, 9]
            su, sv = feats[g, 10], feats[g, 11]
            kk = np.int32(k - start + 1)
            stops = 0
            for p in range(NPIX):
                dx = px[p] - mx
                dy = py[p] - my
                power = _HALF * (ca * dx * dx + cc * dy * dy) + cb * dx * dy
                alpha = min(ALPHA_MAX, op * exp_neg(power))
                Tp = T[p]
                next_T = Tp * (_ONE - alpha)
                valid = (power <= POWER_CUTOFF) & (alpha >= ALPHA_MIN) & (Tp > _ZERO)
                stop = valid & (next_T < T_MIN)
                take = valid & (next_T >= T_MIN)
                w = alpha * Tp if take else _ZERO
                acc[0, p] += w * cr
                acc[1, p] += w * cg
                acc[2, p] += w * cbl
                acc[3, p] += w * (dep + su * dx + sv * dy)
                T[p] = next_T if take else (-Tp if stop else Tp)
                last[p] = kk if take else last[p]
                stops += 1 if stop else 0
            done += stops
        for p in range(NPIX):
            i, j = i0 + p // TILE_W, j0 + p % TILE_W
            if i < height and j < width:
                out_c[i, j, 0], out_c[i, j, 1], out_c[i, j, 2] = acc[0, p], acc[1, p], acc[2, p]
                out_d[i, j] = acc[3, p]
                out_a[i, j] = _ONE - abs(T[p])
                out_n[i, j] = last[p]


@kernel(parallel=True, fastmath=True)
def blend_backward(feats, offsets, ids, width, height, out_a, out_n, g_c, g_d, g_a, wanted,
                   grads):
    """Gradients w.r.t. ``feats`` summed into buffers ``grads`` (B, M, NF), buffer b over a
    fixed share of the tiles: a buffer per *thread* held whatever tiles that thread happened to
    run, so the float sums' order, and the gradients' last bits, changed from run to run on a
    busy machine (two optimisations on the same inputs ended 0.005 deg apart).
    ``wanted`` (M,) bool, or empty for all: the Gaussians whose gradients are used; a tile
    where none of them contributes is skipped (the others' gradients are then incomplete)."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    tiles_y = (height + TILE_H - 1) // TILE_H
    stride = spread_stride(tiles_y)
    n = tiles_x * tiles_y
    nb = grads.shape[0]
    for b in prange(nb):     # buffer b always sums the same tiles, whichever thread runs it
        buf = grads[b]
        for it in range(b * n // nb, (b + 1) * n // nb):
            t, i0, j0 = tile_at(it, tiles_x, tiles_y, stride)
            px = np.empty(NPIX, np.float32)
            py = np.empty(NPIX, np.float32)
            T = np.ones(NPIX, np.float32)
            # per pixel: dL/d colour sum (3), dL/d depth sum, dL/d alpha * final transmittance
            gpix = np.zeros((5, NPIX), np.float32)
            rest = np.zeros((4, NPIX), np.float32)   # colour/depth of what lies behind, normalised
            last = np.zeros(NPIX, np.int32)
            start = offsets[t]
            k_end = 0
            for p in range(NPIX):
                i, j = i0 + p // TILE_W, j0 + p % TILE_W
                px[p], py[p] = f32(j + 0.5), f32(i + 0.5)
                if i < height and j < width:
                    T[p] = _ONE - out_a[i, j]
                    gpix[0, p], gpix[1, p], gpix[2, p] = g_c[i, j, 0], g_c[i, j, 1], g_c[i, j, 2]
                    gpix[3, p], gpix[4, p] = g_d[i, j], g_a[i, j] * T[p]
                    last[p] = out_n[i, j]
                    k_end = max(k_end, out_n[i, j])
            if wanted.shape[0] and not _any_of(wanted, ids, start, k_end):
                continue
            for kk in range(k_end - 1, -1, -1):
                g = ids[start + kk]
                mx, my, ca, cb, cc = feats[g, 0], feats[g, 1], feats[g, 2], feats[g, 3], feats[g, 4]
                op, cr, cg, cbl = feats[g, 5], feats[g, 6], feats[g, 7], feats[g, 8]
                dep = feats[g, 9]
                su, sv = feats[g, 10], feats[g, 11]
                s_r = s_g = s_b = s_d = s_du = s_dv = s_h = s_x = s_y = s_xx = s_xy = s_yy = _ZERO
                for p in range(NPIX):
                    dx = px[p] - mx
                    dy = py[p] - my
                    power = _HALF * (ca * dx * dx + cc * dy * dy) + cb * dx * dy
                    gauss = exp_neg(power)
                    raw = op * gauss
                    alpha = min(ALPHA_MAX, raw)
                    valid = (kk < last[p]) & (power <= POWER_CUTOFF) & (alpha >= ALPHA_MIN)
                    inv = _ONE / (_ONE - alpha)
                    Tb = T[p] * inv
                    w = alpha * Tb if valid else _ZERO
                    gr, gg, gb, gd = gpix[0, p], gpix[1, p], gpix[2, p], gpix[3, p]
                    s_r += w * gr
                    s_g += w * gg
                    s_b += w * gb
                    wd = w * gd
                    s_d += wd
                    s_du += wd * dx
                    s_dv += wd * dy
                    dep_p = dep + su * dx + sv * dy
                    d_r, d_g, d_b = cr - rest[0, p], cg - rest[1, p], cbl - rest[2, p]
                    d_d = dep_p - rest[3, p]
                    g_alpha = Tb * (gr * d_r + gg * d_g + gb * d_b + gd * d_d) + gpix[4, p] * inv
                    # h = d alpha/d power * dL/d alpha / (-opacity); zero where alpha is clamped
                    h = gauss * g_alpha if valid & (raw <= ALPHA_MAX) else _ZERO
                    s_h += h
                    s_x += dx * h
                    s_y += dy * h
                    s_xx += dx * dx * h
                    s_xy += dx * dy * h
                    s_yy += dy * dy * h
                    a_v = alpha if valid else _ZERO
                    T[p] = Tb if valid else T[p]
                    rest[0, p] += a_v * d_r
                    rest[1, p] += a_v * d_g
                    rest[2, p] += a_v * d_b
                    rest[3, p] += a_v * d_d
                buf[g, 0] += op * (ca * s_x + cb * s_y) - su * s_d
                buf[g, 1] += op * (cb * s_x + cc * s_y) - sv * s_d
                buf[g, 2] -= _HALF * op * s_xx
                buf[g, 3] -= op * s_xy
                buf[g, 4] -= _HALF * op * s_yy
                buf[g, 5] += s_h
                buf[g, 6] += s_r
                buf[g, 7] += s_g
                buf[g, 8] += s_b
                buf[g, 9] += s_d
                buf[g, 10] += s_du
                buf[g, 11] += s_dv


@kernel
def _any_of(wanted, ids, start, count):
    """Whether any of the ``count`` tile-list entries from ``start`` is ``wanted``."""
    for k in range(start, start + count):
        if wanted[ids[k]]:
            return True
    return False


@kernel
def sum_thread_grads(grads, order, out):
    """out[order[m]] = sum over threads of grads[:, m] (rows of ``out`` not in order untouched).

    Serial: it is cheap, and a parallel region costs more than it saves on a busy machine."""
    for m in range(grads.shape[1]):
        for f in range(grads.shape[2]):
            s = _ZERO
            for t in range(grads.shape[0]):
                s += grads[t, m, f]
            out[order[m], f] = s
