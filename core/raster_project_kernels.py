"""numba EWA projection (forward and hand-written backward) for the CPU rasterizer.

Same model as core/raster_project.py (the torch version the reference renderer differentiates
by autograd; the tests compare the two). ``cam`` is float32 ``[fx, fy, cx, cy, R (9, row-major),
t (3)]`` of the OpenCV world-to-camera transform. Output rows are the blend kernels' ``feats``
layout (``mean_x, mean_y, conic a, b, c, opacity, r, g, b, depth``).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

f32 = np.float32
LOW_PASS = f32(0.3)
SIGMA = f32(3.0)
_ZERO, _ONE, _TWO = f32(0.0), f32(1.0), f32(2.0)
_FOV_PAD = f32(0.3)


@njit(inline="always", fastmath=True)
def _rotation(qw, qx, qy, qz):
    """Normalised quaternion, its norm, and the rotation matrix rows."""
    norm = max(np.sqrt(qw * qw + qx * qx + qy * qy + qz * qz), f32(1e-12))
    w, x, y, z = qw / norm, qx / norm, qy / norm, qz / norm
    R = np.empty((3, 3), np.float32)
    R[0, 0], R[0, 1], R[0, 2] = _ONE - _TWO * (y * y + z * z), _TWO * (x * y - w * z), _TWO * (x * z + w * y)
    R[1, 0], R[1, 1], R[1, 2] = _TWO * (x * y + w * z), _ONE - _TWO * (x * x + z * z), _TWO * (y * z - w * x)
    R[2, 0], R[2, 1], R[2, 2] = _TWO * (x * z - w * y), _TWO * (y * z + w * x), _ONE - _TWO * (x * x + y * y)
    return w, x, y, z, norm, R


@njit(inline="always", fastmath=True)
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
            s = np.exp(log_scales[n, j])
            m0, m1, m2 = R[0, j] * s, R[1, j] * s, R[2, j] * s
            a0 = cam[4] * m0 + cam[5] * m1 + cam[6] * m2
            a1 = cam[7] * m0 + cam[8] * m1 + cam[9] * m2
            a2 = cam[10] * m0 + cam[11] * m1 + cam[12] * m2
            t0 = j00 * a0 + j02 * a2
            t1 = j11 * a1 + j12 * a2
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
        s = np.empty(3, np.float32)
        A = np.empty((3, 3), np.float32)   # camera-frame R S
        T = np.empty((2, 3), np.float32)   # J A
        for j in range(3):
            s[j] = np.exp(log_scales[n, j])
            m0, m1, m2 = R[0, j] * s[j], R[1, j] * s[j], R[2, j] * s[j]
            A[0, j] = cam[4] * m0 + cam[5] * m1 + cam[6] * m2
            A[1, j] = cam[7] * m0 + cam[8] * m1 + cam[9] * m2
            A[2, j] = cam[10] * m0 + cam[11] * m1 + cam[12] * m2
            T[0, j] = j00 * A[0, j] + j02 * A[2, j]
            T[1, j] = j11 * A[1, j] + j12 * A[2, j]

        # conic (p, q, r) = inverse of the 2D covariance -> gradient of the covariance
        p, q, r = feats[n, 2], feats[n, 3], feats[n, 4]
        u, vv, ww = grad[n, 2], f32(0.5) * grad[n, 3], grad[n, 4]
        g_a = -(p * p * u + _TWO * p * q * vv + q * q * ww)
        g_c = -(q * q * u + _TWO * q * r * vv + r * r * ww)
        g_b = -_TWO * (p * q * u + (p * r + q * q) * vv + q * r * ww)

        g_z = grad[n, 9]
        g_x = fx / z * grad[n, 0]
        g_y = fy / z * grad[n, 1]
        g_z -= fx * x / (z * z) * grad[n, 0] + fy * y / (z * z) * grad[n, 1]
        gj00 = gj02 = gj11 = gj12 = _ZERO
        gA = np.empty((3, 3), np.float32)
        for j in range(3):
            gt0 = _TWO * g_a * T[0, j] + g_b * T[1, j]
            gt1 = g_b * T[0, j] + _TWO * g_c * T[1, j]
            gj00 += gt0 * A[0, j]
            gj02 += gt0 * A[2, j]
            gj11 += gt1 * A[1, j]
            gj12 += gt1 * A[2, j]
            gA[0, j] = j00 * gt0
            gA[1, j] = j11 * gt1
            gA[2, j] = j02 * gt0 + j12 * gt1
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

        gR = np.empty((3, 3), np.float32)
        for j in range(3):   # A = W R S
            gs = _ZERO
            for i in range(3):
                gm = cam[4 + i] * gA[0, j] + cam[7 + i] * gA[1, j] + cam[10 + i] * gA[2, j]
                gR[i, j] = gm * s[j]
                gs += gm * R[i, j]
            g_log_scales[n, j] = gs * s[j]
        gw = _TWO * (-qz * gR[0, 1] + qy * gR[0, 2] + qz * gR[1, 0] - qx * gR[1, 2]
                     - qy * gR[2, 0] + qx * gR[2, 1])
        gx = _TWO * (qy * gR[0, 1] + qz * gR[0, 2] + qy * gR[1, 0] - _TWO * qx * gR[1, 1]
                     - w * gR[1, 2] + qz * gR[2, 0] + w * gR[2, 1] - _TWO * qx * gR[2, 2])
        gy = _TWO * (-_TWO * qy * gR[0, 0] + qx * gR[0, 1] + w * gR[0, 2] + qx * gR[1, 0]
                     + qz * gR[1, 2] - w * gR[2, 0] + qz * gR[2, 1] - _TWO * qy * gR[2, 2])
        gz = _TWO * (-_TWO * qz * gR[0, 0] - w * gR[0, 1] + qx * gR[0, 2] + w * gR[1, 0]
                     - _TWO * qz * gR[1, 1] + qy * gR[1, 2] + qx * gR[2, 0] + qy * gR[2, 1])
        dot = w * gw + qx * gx + qy * gy + qz * gz
        g_quats[n, 0] = (gw - w * dot) / qnorm
        g_quats[n, 1] = (gx - qx * dot) / qnorm
        g_quats[n, 2] = (gy - qy * dot) / qnorm
        g_quats[n, 3] = (gz - qz * dot) / qnorm

        op = feats[n, 5]
        g_logits[n] = grad[n, 5] * op * (_ONE - op)
        g_colors[n, 0], g_colors[n, 1], g_colors[n, 2] = grad[n, 6], grad[n, 7], grad[n, 8]
