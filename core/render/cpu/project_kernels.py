"""numba EWA projection (forward and hand-written backward) for the CPU rasterizer.

Same model as core/render/cpu/project.py (the torch version the reference renderer differentiates
by autograd; the tests compare the two). ``cam`` is float32 ``[fx, fy, cx, cy, R (9, row-major),
t (3)]`` of the OpenCV world-to-camera transform. Output rows are the blend kernels' ``feats``
layout (``mean_x, mean_y, conic a, b, c, opacity, r, g, b, depth, slope_x, slope_y``).
"""

from __future__ import annotations

import numpy as np
from numba import prange

from .. import constants as model
from .jit import kernel

f32 = np.float32
SIGMA = f32(model.SIGMA_CUTOFF)
_ZERO, _ONE, _TWO = f32(0.0), f32(1.0), f32(2.0)
_FOV_PAD = f32(model.FOV_PAD)
MAX_SLOPE = f32(model.MAX_SLOPE)


@kernel(fastmath=True)
def _rotation(qw, qx, qy, qz):
    """Normalised quaternion, its norm, and the rotation matrix (row-major 9-tuple)."""
    norm = max(np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz), f32(1e-12))
    w, x, y, z = qw / norm, qx / norm, qy / norm, qz / norm
    R = (_ONE - _TWO * (y * y + z * z), _TWO * (x * y - w * z), _TWO * (x * z + w * y),
         _TWO * (x * y + w * z), _ONE - _TWO * (x * x + z * z), _TWO * (y * z - w * x),
         _TWO * (x * z - w * y), _TWO * (y * z + w * x), _ONE - _TWO * (x * x + y * y))
    return w, x, y, z, norm, R


@kernel(fastmath=True)
def _column(cam, R, s, j, j00, j02, j11, j12):
    """Column j of A = W R S (camera-frame) and of T = J A."""
    m0, m1, m2 = R[j] * s, R[3 + j] * s, R[6 + j] * s
    a0 = cam[4] * m0 + cam[5] * m1 + cam[6] * m2
    a1 = cam[7] * m0 + cam[8] * m1 + cam[9] * m2
    a2 = cam[10] * m0 + cam[11] * m1 + cam[12] * m2
    return a0, a1, a2, j00 * a0 + j02 * a2, j11 * a1 + j12 * a2


@kernel(fastmath=True)
def _column_backward(cam, R, s, j, j00, j02, j11, j12, g_a, g_b, g_c):
    """Backward of column j: gradients of R[:, j], log_scale j and the Jacobian entries."""
    a0, a1, a2, t0, t1 = _column(cam, R, s, j, j00, j02, j11, j12)
    gt0 = _TWO * g_a * t0 + g_b * t1
    gt1 = g_b * t0 + _TWO * g_c * t1
    ga0, ga1, ga2 = j00 * gt0, j11 * gt1, j02 * gt0 + j12 * gt1
    gm0 = cam[4] * ga0 + cam[7] * ga1 + cam[10] * ga2
    gm1 = cam[5] * ga0 + cam[8] * ga1 + cam[11] * ga2
    gm2 = cam[6] * ga0 + cam[9] * ga1 + cam[12] * ga2
    g_ls = (gm0 * R[j] + gm1 * R[3 + j] + gm2 * R[6 + j]) * s
    return (gm0 * s, gm1 * s, gm2 * s, g_ls,
            gt0 * a0, gt0 * a2, gt1 * a1, gt1 * a2)


@kernel(fastmath=True)
def _camera_rotation(cam, R):
    """M = W R, the camera-from-Gaussian rotation (row-major 9-tuple)."""
    return (cam[4] * R[0] + cam[5] * R[3] + cam[6] * R[6],
            cam[4] * R[1] + cam[5] * R[4] + cam[6] * R[7],
            cam[4] * R[2] + cam[5] * R[5] + cam[6] * R[8],
            cam[7] * R[0] + cam[8] * R[3] + cam[9] * R[6],
            cam[7] * R[1] + cam[8] * R[4] + cam[9] * R[7],
            cam[7] * R[2] + cam[8] * R[5] + cam[9] * R[8],
            cam[10] * R[0] + cam[11] * R[3] + cam[12] * R[6],
            cam[10] * R[1] + cam[11] * R[4] + cam[12] * R[7],
            cam[10] * R[2] + cam[11] * R[5] + cam[12] * R[8])


@kernel(fastmath=True)
def _slope_terms(M, x, y, z, log_scales):
    """b = M^T t, e = b / s^2, c = M e (x, y rows) and q = b . e of the planar depth slopes."""
    b0 = M[0] * x + M[3] * y + M[6] * z
    b1 = M[1] * x + M[4] * y + M[7] * z
    b2 = M[2] * x + M[5] * y + M[8] * z
    i0, i1, i2 = (np.exp(-_TWO * log_scales[0]), np.exp(-_TWO * log_scales[1]),
                  np.exp(-_TWO * log_scales[2]))
    e0, e1, e2 = b0 * i0, b1 * i1, b2 * i2
    q = b0 * e0 + b1 * e1 + b2 * e2
    cx = M[0] * e0 + M[1] * e1 + M[2] * e2
    cy = M[3] * e0 + M[4] * e1 + M[5] * e2
    return (b0, b1, b2), (e0, e1, e2), (i0, i1, i2), cx, cy, q


@kernel(fastmath=True)
def _slopes(cam, M, x, y, z, log_scales):
    """Planar depth change per pixel (x, y), limited to MAX_SLOPE footprints (raster_model)."""
    _, _, _, cx, cy, q = _slope_terms(M, x, y, z, log_scales)
    lim_u, lim_v = MAX_SLOPE * z / cam[0], MAX_SLOPE * z / cam[1]
    a_u, a_v = -z * z * cx / (q * cam[0]), -z * z * cy / (q * cam[1])
    return min(max(a_u, -lim_u), lim_u), min(max(a_v, -lim_v), lim_v)


@kernel(fastmath=True)
def _slope_backward(c, f, z, q, g):
    """Gradients (z, q, c) of one slope ``-z^2 c / (q f)`` limited to +-MAX_SLOPE z / f, from g."""
    a = -z * z * c / (q * f)
    lim = MAX_SLOPE * z / f
    if a > lim:
        return MAX_SLOPE / f * g, _ZERO, _ZERO
    if a < -lim:
        return -MAX_SLOPE / f * g, _ZERO, _ZERO
    return _TWO * a / z * g, -a / q * g, -z * z / (q * f) * g


@kernel(fastmath=True)
def _slopes_backward(cam, M, x, y, z, log_scales, g_u, g_v):
    """Backward of :func:`_slopes`: gradients of (x, y, z), log_scales (3) and M (9, row-major)."""
    b, e, inv, cx, cy, q = _slope_terms(M, x, y, z, log_scales)
    gz_u, gq_u, g_cx = _slope_backward(cx, cam[0], z, q, g_u)
    gz_v, gq_v, g_cy = _slope_backward(cy, cam[1], z, q, g_v)
    g_z, g_q = gz_u + gz_v, gq_u + gq_v
    # c = M e (rows x, y); q = b . e; e = b * inv; b = M^T t
    ge = (M[0] * g_cx + M[3] * g_cy, M[1] * g_cx + M[4] * g_cy, M[2] * g_cx + M[5] * g_cy)
    gb = (_TWO * g_q * e[0] + ge[0] * inv[0], _TWO * g_q * e[1] + ge[1] * inv[1],
          _TWO * g_q * e[2] + ge[2] * inv[2])
    g_ls = (-_TWO * e[0] * (g_q * b[0] + ge[0]), -_TWO * e[1] * (g_q * b[1] + ge[1]),
            -_TWO * e[2] * (g_q * b[2] + ge[2]))
    g_x = M[0] * gb[0] + M[1] * gb[1] + M[2] * gb[2]
    g_y = M[3] * gb[0] + M[4] * gb[1] + M[5] * gb[2]
    g_z += M[6] * gb[0] + M[7] * gb[1] + M[8] * gb[2]
    g_M = (g_cx * e[0] + x * gb[0], g_cx * e[1] + x * gb[1], g_cx * e[2] + x * gb[2],
           g_cy * e[0] + y * gb[0], g_cy * e[1] + y * gb[1], g_cy * e[2] + y * gb[2],
           z * gb[0], z * gb[1], z * gb[2])
    return g_x, g_y, g_z, g_ls, g_M


@kernel(fastmath=True)
def _limits(cam, width, height):
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    tan_x, tan_y = f32(0.5) * width / fx, f32(0.5) * height / fy
    return ((width - cx) / fx + _FOV_PAD * tan_x, cx / fx + _FOV_PAD * tan_x,
            (height - cy) / fy + _FOV_PAD * tan_y, cy / fy + _FOV_PAD * tan_y)


@kernel
def _recall(seen, n, c, values):
    """Whether row ``n`` of ``values`` ((N, m) uint32) equals columns ``c``..``c+m`` of
    ``seen`` (N,14), the bits of the inputs the row was last projected from; where not,
    ``seen`` takes it."""
    same = True
    for i in range(values.shape[1]):
        v = values[n, i]
        if v != seen[n, c + i]:
            same = False
            seen[n, c + i] = v
    return same


@kernel(parallel=True, fastmath=True)
def project_forward(means, quats, log_scales, opacity_logits, colors, cam, width, height, near,
                    low_pass, seen, out, extent, visible):
    """Fill ``out`` (N,12), ``extent`` (N,2) and ``visible`` (N,) for every Gaussian, or, when
    ``seen`` has N rows, only for those whose inputs' bits (the five side by side) differ from
    ``seen`` (the other rows still hold their projection of those inputs; ``seen`` is
    updated). Either way every row is its own inputs' projection: no row depends on another."""
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    lxp, lxn, lyp, lyn = _limits(cam, width, height)
    recall = seen.shape[0] == means.shape[0]
    mb, qb, sb = means.view(np.uint32), quats.view(np.uint32), log_scales.view(np.uint32)
    ob, cb = opacity_logits.reshape((-1, 1)).view(np.uint32), colors.view(np.uint32)
    for n in prange(means.shape[0]):
        # `&`, not `and`: every input must be stored in ``seen``, or an input left at older bits
        # could later match them while the row holds the projection of newer ones
        if recall and (_recall(seen, n, 0, mb) & _recall(seen, n, 3, qb) & _recall(seen, n, 7, sb)
                       & _recall(seen, n, 10, ob) & _recall(seen, n, 11, cb)):
            continue
        px, py, pz = means[n, 0], means[n, 1], means[n, 2]
        x = cam[4] * px + cam[5] * py + cam[6] * pz + cam[13]
        y = cam[7] * px + cam[8] * py + cam[9] * pz + cam[14]
        z = cam[10] * px + cam[11] * py + cam[12] * pz + cam[15]
        visible[n] = False
        out[n, :] = _ZERO
        extent[n, :] = _ZERO
        if not z > near:
            continue
        _, _, _, _, _, R = _rotation(quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3])
        txc = z * min(max(x / z, -lxn), lxp)
        tyc = z * min(max(y / z, -lyn), lyp)
        j00, j02 = fx / z, -fx * txc / (z * z)
        j11, j12 = fy / z, -fy * tyc / (z * z)
        a = b = c = _ZERO
        for j in range(3):
            _, _, _, t0, t1 = _column(cam, R, np.exp(log_scales[n, j]), j, j00, j02, j11, j12)
            a += t0 * t0
            b += t0 * t1
            c += t1 * t1
        a += low_pass
        c += low_pass
        det = a * c - b * b
        if not det > _ZERO:
            continue
        u, v = fx * x / z + cx, fy * y / z + cy
        ex, ey = SIGMA * np.sqrt(a), SIGMA * np.sqrt(c)
        if not (u + ex > 0 and u - ex < width and v + ey > 0 and v - ey < height):
            continue
        visible[n] = True
        out[n, 0], out[n, 1] = u, v
        out[n, 2], out[n, 3], out[n, 4] = c / det, -b / det, a / det
        out[n, 5] = _ONE / (_ONE + np.exp(-opacity_logits[n]))
        out[n, 6], out[n, 7], out[n, 8] = colors[n, 0], colors[n, 1], colors[n, 2]
        out[n, 9] = z
        out[n, 10], out[n, 11] = _slopes(cam, _camera_rotation(cam, R), x, y, z, log_scales[n])
        extent[n, 0], extent[n, 1] = ex, ey


@kernel
def _any_nonzero(grad, n):
    """Whether row ``n`` of ``grad`` has a non-zero entry."""
    for f in range(grad.shape[1]):
        if grad[n, f] != _ZERO:
            return True
    return False


@kernel(parallel=True, fastmath=True)
def project_backward(means, quats, log_scales, cam, width, height, feats, visible, grad,
                     g_means, g_quats, g_log_scales, g_logits, g_colors):
    """Gradients of the Gaussian parameters from ``grad`` (N,12), the gradient of ``feats``."""
    fx, fy = cam[0], cam[1]
    lxp, lxn, lyp, lyn = _limits(cam, width, height)
    for n in prange(means.shape[0]):
        g_means[n, :] = _ZERO
        g_quats[n, :] = _ZERO
        g_log_scales[n, :] = _ZERO
        g_logits[n] = _ZERO
        g_colors[n, :] = _ZERO
        if not visible[n] or not _any_nonzero(grad, n):   # occluded: all its gradients are 0
            continue
        px, py, pz = means[n, 0], means[n, 1], means[n, 2]
        x = cam[4] * px + cam[5] * py + cam[6] * pz + cam[13]
        y = cam[7] * px + cam[8] * py + cam[9] * pz + cam[14]
        z = cam[10] * px + cam[11] * py + cam[12] * pz + cam[15]
        w, qx, qy, qz, qnorm, R = _rotation(quats[n, 0], quats[n, 1], quats[n, 2], quats[n, 3])
        rx, ry = x / z, y / z
        clamp_x = rx < -lxn or rx > lxp
        clamp_y = ry < -lyn or ry > lyp
        txc = z * min(max(rx, -lxn), lxp)
        tyc = z * min(max(ry, -lyn), lyp)
        j00, j02 = fx / z, -fx * txc / (z * z)
        j11, j12 = fy / z, -fy * tyc / (z * z)

        # conic (p, q, r) = inverse of the 2D covariance -> gradient of the covariance
        p, q, r = feats[n, 2], feats[n, 3], feats[n, 4]
        u, vv, ww = grad[n, 2], f32(0.5) * grad[n, 3], grad[n, 4]
        g_a = -(p * p * u + _TWO * p * q * vv + q * q * ww)
        g_c = -(q * q * u + _TWO * q * r * vv + r * r * ww)
        g_b = -_TWO * (p * q * u + (p * r + q * q) * vv + q * r * ww)

        c0 = _column_backward(cam, R, np.exp(log_scales[n, 0]), 0, j00, j02, j11, j12, g_a, g_b, g_c)
        c1 = _column_backward(cam, R, np.exp(log_scales[n, 1]), 1, j00, j02, j11, j12, g_a, g_b, g_c)
        c2 = _column_backward(cam, R, np.exp(log_scales[n, 2]), 2, j00, j02, j11, j12, g_a, g_b, g_c)
        g_log_scales[n, 0], g_log_scales[n, 1], g_log_scales[n, 2] = c0[3], c1[3], c2[3]
        gj00, gj02 = c0[4] + c1[4] + c2[4], c0[5] + c1[5] + c2[5]
        gj11, gj12 = c0[6] + c1[6] + c2[6], c0[7] + c1[7] + c2[7]

        M = _camera_rotation(cam, R)
        g_x, g_y, g_z, s_ls, s_M = _slopes_backward(cam, M, x, y, z, log_scales[n],
                                                    grad[n, 10], grad[n, 11])
        for j in range(3):
            g_log_scales[n, j] += s_ls[j]
        # M = W R  ->  dL/dR = W^T dL/dM
        sR = (cam[4] * s_M[0] + cam[7] * s_M[3] + cam[10] * s_M[6],
              cam[4] * s_M[1] + cam[7] * s_M[4] + cam[10] * s_M[7],
              cam[4] * s_M[2] + cam[7] * s_M[5] + cam[10] * s_M[8],
              cam[5] * s_M[0] + cam[8] * s_M[3] + cam[11] * s_M[6],
              cam[5] * s_M[1] + cam[8] * s_M[4] + cam[11] * s_M[7],
              cam[5] * s_M[2] + cam[8] * s_M[5] + cam[11] * s_M[8],
              cam[6] * s_M[0] + cam[9] * s_M[3] + cam[12] * s_M[6],
              cam[6] * s_M[1] + cam[9] * s_M[4] + cam[12] * s_M[7],
              cam[6] * s_M[2] + cam[9] * s_M[5] + cam[12] * s_M[8])
        g_z += grad[n, 9]
        g_x += fx / z * grad[n, 0]
        g_y += fy / z * grad[n, 1]
        g_z -= fx * x / (z * z) * grad[n, 0] + fy * y / (z * z) * grad[n, 1]
        z2 = z * z
        g_z += -fx / z2 * gj00 + _TWO * fx * txc / (z2 * z) * gj02
        g_z += -fy / z2 * gj11 + _TWO * fy * tyc / (z2 * z) * gj12
        g_txc, g_tyc = -fx / z2 * gj02, -fy / z2 * gj12
        if clamp_x:
            g_z += txc / z * g_txc
        else:
            g_x += g_txc
        if clamp_y:
            g_z += tyc / z * g_tyc
        else:
            g_y += g_tyc
        for i in range(3):   # t = W p + w  ->  dL/dp = W^T dL/dt
            g_means[n, i] = cam[4 + i] * g_x + cam[7 + i] * g_y + cam[10 + i] * g_z

        # gR[i][j] = c_j[i] (from the conic) + sR[3 i + j] (from the slopes)
        g00, g01, g02 = c0[0] + sR[0], c1[0] + sR[1], c2[0] + sR[2]
        g10, g11, g12 = c0[1] + sR[3], c1[1] + sR[4], c2[1] + sR[5]
        g20, g21, g22 = c0[2] + sR[6], c1[2] + sR[7], c2[2] + sR[8]
        gw = _TWO * (-qz * g01 + qy * g02 + qz * g10 - qx * g12 - qy * g20 + qx * g21)
        gx = _TWO * (qy * g01 + qz * g02 + qy * g10 - _TWO * qx * g11 - w * g12
                     + qz * g20 + w * g21 - _TWO * qx * g22)
        gy = _TWO * (-_TWO * qy * g00 + qx * g01 + w * g02 + qx * g10 + qz * g12
                     - w * g20 + qz * g21 - _TWO * qy * g22)
        gz = _TWO * (-_TWO * qz * g00 - w * g01 + qx * g02 + w * g10 - _TWO * qz * g11
                     + qy * g12 + qx * g20 + qy * g21)
        dot = w * gw + qx * gx + qy * gy + qz * gz
        g_quats[n, 0] = (gw - w * dot) / qnorm
        g_quats[n, 1] = (gx - qx * dot) / qnorm
        g_quats[n, 2] = (gy - qy * dot) / qnorm
        g_quats[n, 3] = (gz - qz * dot) / qnorm

        op = feats[n, 5]
        g_logits[n] = grad[n, 5] * op * (_ONE - op)
        g_colors[n, 0], g_colors[n, 1], g_colors[n, 2] = grad[n, 6], grad[n, 7], grad[n, 8]
