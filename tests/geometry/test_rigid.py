"""Rigid fitting: robust Kabsch, point-to-plane ICP and joint (screw) fits on synthetic points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from artgs.core.model.joints import joint_transform
from artgs.core.geometry.metrics import axis_error_deg, line_distance
from artgs.core.geometry.rigid import apply, by_motion, fit_both, icp, kabsch, robust_kabsch, rotation_log, screw_axis


def _box_surface(rng: np.random.Generator, size=(0.4, 0.02, 0.6), n=3000) -> np.ndarray:
    """Points on the surface of an axis-aligned box centred at the origin."""
    h = np.asarray(size) / 2
    P = rng.uniform(-h, h, size=(n, 3))
    face = rng.integers(0, 3, n)
    side = rng.choice([-1.0, 1.0], n)
    P[np.arange(n), face] = side * h[face]
    return P


def test_kabsch_exact_and_robust_with_outliers():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(200, 3))
    T = joint_transform("revolute", np.array([0.3, -0.2, 1.0]), np.array([0.5, 0.1, 0.0]), 0.7)
    Y = apply(T, X)
    assert np.allclose(kabsch(X, Y), T, atol=1e-9)
    Yn = Y + rng.normal(scale=0.002, size=Y.shape)
    bad = rng.choice(200, 50, replace=False)           # 25 % gross outliers
    Yn[bad] += rng.normal(scale=0.5, size=(50, 3))
    T_plain = kabsch(X, Yn)
    T_rob, w = robust_kabsch(X, Yn)
    ang = lambda A: math.degrees(rotation_log(A[:3, :3] @ T[:3, :3].T)[1])
    assert ang(T_rob) < 0.3 and np.linalg.norm(T_rob[:3, 3] - T[:3, 3]) < 0.005
    assert ang(T_plain) > 1.0                           # the outliers do spoil plain Kabsch
    assert w[bad].max() < 0.05 and np.median(np.delete(w, bad)) > 0.8


def test_icp_recovers_door_motion_with_noise_and_outliers():
    rng = np.random.default_rng(1)
    S = _box_surface(rng)
    normals_of = lambda P: _box_normals(P)
    T = joint_transform("revolute", np.array([0.0, 0.0, 1.0]), np.array([-0.2, 0.0, 0.0]),
                        math.radians(12.0))
    tgt = apply(T, _box_surface(rng, n=6000))
    nrm = normals_of(apply(np.linalg.inv(T), tgt)) @ T[:3, :3].T
    tgt = tgt + rng.normal(scale=0.002, size=tgt.shape)
    clutter = rng.uniform(-0.5, 0.5, size=(800, 3))    # unrelated points
    cn = rng.normal(size=(800, 3))
    target = np.concatenate([tgt, clutter])
    normals = np.concatenate([nrm, cn / np.linalg.norm(cn, axis=1, keepdims=True)])
    res = icp(S, target, normals, np.eye(4), max_distance=0.1)
    err = math.degrees(rotation_log(res.T[:3, :3] @ T[:3, :3].T)[1])
    assert err < 0.5
    assert np.abs(apply(res.T, S) - apply(T, S)).max() < 0.006


def _box_normals(P: np.ndarray, size=(0.4, 0.02, 0.6)) -> np.ndarray:
    h = np.asarray(size) / 2
    k = np.argmax(np.abs(P) / h, axis=1)
    N = np.zeros_like(P)
    N[np.arange(len(P)), k] = np.sign(P[np.arange(len(P)), k])
    return N


@pytest.mark.parametrize("noise_deg", [0.0, 0.5])
def test_screw_fit_revolute(noise_deg):
    rng = np.random.default_rng(2)
    axis = np.array([0.1, 0.05, 1.0]) / np.linalg.norm([0.1, 0.05, 1.0])
    origin = np.array([0.3, -0.1, 0.4])
    X = _box_surface(rng) + np.array([0.5, 0.0, 0.4])
    values = np.radians([10, 25, 40, 55, 70])
    Ts = []
    for v in values:
        T = joint_transform("revolute", axis, origin, v)
        # perturb each step's transform a little (per-step tracking noise)
        E = joint_transform("revolute", rng.normal(size=3), X.mean(0), math.radians(noise_deg))
        Ts.append(E @ T)
    a, p, th = screw_axis(Ts)
    assert axis_error_deg(a, axis) < 0.8 + 2 * noise_deg
    fit = by_motion(*fit_both(X, Ts))
    assert fit.type == "revolute"
    assert axis_error_deg(fit.axis, axis) < 0.2 + noise_deg
    assert 100 * line_distance(fit.origin, fit.axis, origin, axis) < 0.3 + 2 * noise_deg
    sign = np.sign(fit.axis @ axis)
    assert sign > 0 and np.all(fit.values > 0)        # positive values open the part
    assert np.allclose(fit.values, values, atol=math.radians(0.2 + noise_deg))


def test_screw_fit_prismatic_with_negative_motion_direction():
    rng = np.random.default_rng(3)
    X = _box_surface(rng)
    d = np.array([0.0, -1.0, 0.05]) / np.linalg.norm([0.0, -1.0, 0.05])
    values = np.array([0.05, 0.1, 0.15, 0.2])
    Ts = []
    for v in values:
        E = joint_transform("revolute", rng.normal(size=3), X.mean(0), math.radians(0.3))
        Ts.append(E @ joint_transform("prismatic", d, np.zeros(3), v))
    fit = by_motion(*fit_both(X, Ts))
    assert fit.type == "prismatic"
    assert axis_error_deg(fit.axis, d) < 0.5 and fit.axis @ d > 0
    assert np.allclose(fit.values, values, atol=0.003)
    assert fit.rms_prismatic < fit.rms_revolute + 1e-3
