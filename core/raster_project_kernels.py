"""numba EWA projection (forward and hand-written backward) for the CPU rasterizer.

Same model as core/raster_project.py (the torch version the reference renderer differentiates
by autograd; the tests compare the two). ``cam`` is float32 ``[fx, fy, cx, cy, R (9, row-major),
t (3)]`` of the OpenCV world-to-camera transform. Output rows are the blend kernels' ``feats``
layout (``mean_x, mean_y, conic a, b, c, opacity, r, g, b, depth``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import raster_model as model

f32 = np.float32
LOW_PASS = f32(model.LOW_PASS)
SIGMA = f32(model.SIGMA_CUTOFF)
_ZERO, _ONE, _TWO = f32(0.0), f32(1.0), f32(2.0)
_FOV_PAD = f32(model.FOV_PAD)


@njit(fastmath=True, cache=True)
def _rotation(qw, qx, qy, qz):
    """Normalised quaternion, its norm, and the rotation matrix (row-major 9-tuple)."""
    norm = max(np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz), f32(1e-12))
    w, x, y, z = qw / norm, qx / norm, qy / norm, qz / norm
    R = (_ONE - _TWO * (y * y + z * z), _TWO * (x * y - w * z), _TWO * (x * z + w * y),
         _TWO * (x * y + w * z), _ONE - _TWO * (x * x + z * z), _TWO * (y * z - w * x),
         _TWO * (x * z - w * y), _TWO * (y * z + w * x), _ONE - _TWO * (x * x + y * y))
    return w, x, y, z, norm, R


@njit(fastmath=True, cache=True)
def _column(cam, R, s, j, j00, j02, j11, j12):
    """Column j of A = W R S (camera-frame) and of T = J A."""
    m0, m1, m2 = R[j] * s, R[3 + j] * s, R[6 + j] * s
    a0 = cam[4] * m0 + cam[5] * m1 + cam[6] * m2
    a1 = cam[7] * m0 + cam[8] * m1 + cam[9] * m2
    a2 = cam[10] * m0 + cam[11] * m1 + cam[12] * m2
    return a0, a1, a2, j00 * a0 + j02 * a2, j11 * a1 + j12 * a2


@njit(fastmath=True, cache=True)
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


@njit(fastmath=True, cache=True)
def _limits(cam, width, height):
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    tan_x, tan_y = f32(0.5) * width / fx, f32(0.5) * height / fy
    return ((width - cx) / fx + _FOV_PAD * tan_x, cx / fx + _FOV_PAD * tan_x,
            (height - cy) / fy + _FOV_PAD * tan_y, cy / fy + _FOV_PAD * tan_y)


@njit(parallel=True, fastmath=True, cache=True)
def project_forward(means, quats, log_scales, opacity_logits, colors, cam, width, height, near,
                    out, extent, visible):
    """Fill ``out`` (N,10), ``extent`` (N,2) and ``visible`` (N,) for every Gaussian."""
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    lxp, lxn, lyp, lyn = _limits(cam, width, height)
    for n in prange(means.shape[0]):
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
        a += LOW_PASS
        c += LOW_PASS
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
        extent[n, 0], extent[n, 1] = ex, ey


@njit(parallel=True, fastmath=True, cache=True)
def project_backward(means, quats, log_scales, cam, width, height, feats, visible, grad,
                     g_means, g_quats, g_log_scales, g_logits, g_colors):
    """Gradients of the Gaussian parameters from ``grad`` (N,10), the gradient of ``feats``."""
    fx, fy = cam[0], cam[1]
    lxp, lxn, lyp, lyn = _limits(cam, width, height)
    for n in prange(means.shape[0]):
        g_means[n, :] = _ZERO
        g_quats[n, :] = _ZERO
        g_log_scales[n, :] = _ZERO
        g_logits[n] = _ZERO
        g_colors[n, :] = _ZERO
        if not visible[n]:
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

        g_z = grad[n, 9]
        g_x = fx / z * grad[n, 0]
        g_y = fy / z * grad[n, 1]
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

        # gR[i][j] = c_j[i]
        gw = _TWO * (-qz * c1[0] + qy * c2[0] + qz * c0[1] - qx * c2[1] - qy * c0[2] + qx * c1[2])
        gx = _TWO * (qy * c1[0] + qz * c2[0] + qy * c0[1] - _TWO * qx * c1[1] - w * c2[1]
                     + qz * c0[2] + w * c1[2] - _TWO * qx * c2[2])
        gy = _TWO * (-_TWO * qy * c0[0] + qx * c1[0] + w * c2[0] + qx * c0[1] + qz * c2[1]
                     - w * c0[2] + qz * c1[2] - _TWO * qy * c2[2])
        gz = _TWO * (-_TWO * qz * c0[0] - w * c1[0] + qx * c2[0] + w * c0[1] - _TWO * qz * c1[1]
                     + qy * c2[1] + qx * c0[2] + qy * c1[2])
        dot = w * gw + qx * gx + qy * gy + qz * gz
        g_quats[n, 0] = (gw - w * dot) / qnorm
        g_quats[n, 1] = (gx - qx * dot) / qnorm
        g_quats[n, 2] = (gy - qy * dot) / qnorm
        g_quats[n, 3] = (gz - qz * dot) / qnorm

        op = feats[n, 5]
        g_logits[n] = grad[n, 5] * op * (_ONE - op)
        g_colors[n, 0], g_colors[n, 1], g_colors[n, 2] = grad[n, 6], grad[n, 7], grad[n, 8]
