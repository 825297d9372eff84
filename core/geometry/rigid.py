"""Rigid motions from 3D points: robust Kabsch, point-to-plane ICP, and joint (screw) fits.

Numpy/scipy only (no torch). Transforms are 4x4 matrices acting on column points ``T @ [x, 1]``;
point arrays are (N, 3) rows, so ``apply(T, X) = X @ R.T + t``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.linalg
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

from ..model.joints import rotation_about_axis


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 rigid transform from rotation ``R`` and translation ``t``."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 rigid transform."""
    R = T[:3, :3]
    return make_transform(R.T, -R.T @ T[:3, 3])


def apply(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Transform points (N,3) by the 4x4 ``T``."""
    return X @ T[:3, :3].T + T[:3, 3]


def rotation_log(R: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit axis and angle (radians, 0..pi) of a rotation matrix (axis x for the identity)."""
    cos = float(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.acos(cos)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    n = np.linalg.norm(w)
    if n > 1e-9 and angle < math.pi - 1e-3:
        return w / n, angle
    if angle < 1e-6:
        return np.array([1.0, 0.0, 0.0]), 0.0
    # near pi: the axis is the dominant column of R + I
    B = R + np.eye(3)
    axis = B[:, int(np.argmax(np.linalg.norm(B, axis=0)))]
    return axis / np.linalg.norm(axis), angle


def kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Weighted least-squares rigid transform mapping ``src`` onto ``dst`` (both (N,3))."""
    w = np.ones(len(src)) if weights is None else np.asarray(weights, float)
    w = w / max(w.sum(), 1e-12)
    cs, cd = w @ src, w @ dst
    H = (src - cs).T @ ((dst - cd) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return make_transform(R, cd - R @ cs)


def robust_kabsch(src: np.ndarray, dst: np.ndarray, iterations: int = 20,
                  scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch by iteratively reweighted least squares (Tukey biweight); returns (T, weights).

    ``scale`` is the residual scale (default: from the median absolute residual each step).
    """
    w = np.ones(len(src))
    T = kabsch(src, dst)
    for _ in range(iterations):
        r = np.linalg.norm(apply(T, src) - dst, axis=1)
        s = scale if scale is not None else max(1.4826 * float(np.median(r)), 1e-9)
        w = tukey_weights(r, 4.685 * s)
        if w.sum() < 3:
            break
        T_new = kabsch(src, dst, w)
        if np.abs(T_new - T).max() < 1e-10:
            T = T_new
            break
        T = T_new
    return T, w


def tukey_weights(r: np.ndarray, c: float) -> np.ndarray:
    """Tukey biweight of residuals ``r`` with cut-off ``c`` (0 beyond it)."""
    u = np.clip(np.abs(r) / max(c, 1e-12), 0.0, 1.0)
    return (1.0 - u * u) ** 2


def _se3_exp(xi: np.ndarray) -> np.ndarray:
    """4x4 transform of a small twist (rx, ry, rz, tx, ty, tz) (rotation then translation)."""
    w = xi[:3]
    angle = float(np.linalg.norm(w))
    R = rotation_about_axis(w, angle) if angle > 1e-12 else np.eye(3)
    return make_transform(R, xi[3:])


@dataclass
class IcpResult:
    """Outcome of :func:`icp`: transform, robust RMS residual (m), inlier count and fraction."""

    T: np.ndarray
    rms: float
    inliers: int
    fraction: float


def icp(source: np.ndarray, target: np.ndarray, target_normals: np.ndarray, T0: np.ndarray,
        *, tree: cKDTree | None = None, max_distance: float = 0.05, min_distance: float = 0.005,
        iterations: int = 40, point_weight: float = 0.02,
        keep: Callable[[np.ndarray], np.ndarray] | None = None) -> IcpResult:
    """Robust point-to-plane ICP of ``source`` onto ``target`` (with unit ``target_normals``).

    Each iteration: transform the source, drop points ``keep`` rejects (e.g. occluded in every
    view), match nearest target points within the current cut-off distance, weight them by a Tukey
    biweight of the point-to-plane residual (scale from its median, at least ``min_distance``), and
    take one Gauss-Newton step on the point-to-plane residuals plus ``point_weight`` times the
    point-to-point ones (which keeps motion along flat faces from drifting freely).
    """
    tree = tree if tree is not None else cKDTree(target)
    T = T0.copy()
    cutoff = max_distance
    rms, n_in = math.inf, 0
    for it in range(iterations):
        Y = apply(T, source)
        ok = keep(Y) if keep is not None else np.ones(len(Y), bool)
        if ok.sum() < 6:
            break
        Yk = Y[ok]
        d, j = tree.query(Yk, distance_upper_bound=cutoff)
        hit = np.isfinite(d)
        if hit.sum() < 6:
            break
        p, q, n = Yk[hit], target[j[hit]], target_normals[j[hit]]
        diff = p - q
        c = p.mean(axis=0)
        p = p - c   # twists about the centroid: better conditioned
        r_pl = np.einsum("ij,ij->i", diff, n)
        r_pt = np.linalg.norm(diff, axis=1)
        scale = float(np.clip(4.685 * 1.4826 * np.median(np.abs(r_pl)), min_distance, max_distance))
        w = tukey_weights(r_pl, scale)
        good = w > 0
        n_in = int(good.sum())
        if n_in < 6:
            break
        rms = float(np.sqrt(np.sum(w * r_pl ** 2) / max(w.sum(), 1e-12)))
        # Jacobians of the residuals w.r.t. a twist applied on the left: dp = w x p + v
        J_pl = np.concatenate([np.cross(p, n), n], axis=1)
        A = (J_pl * w[:, None]).T @ J_pl
        b = -(J_pl * w[:, None]).T @ r_pl
        if point_weight > 0:
            pw = point_weight * w
            for k in range(3):
                e = np.zeros(3)
                e[k] = 1.0
                J = np.concatenate([np.cross(p, e), np.broadcast_to(e, p.shape)], axis=1)
                A += (J * pw[:, None]).T @ J
                b -= (J * pw[:, None]).T @ diff[:, k]
        try:   # scipy: numpy's small dense solve is slow once torch is loaded (threading)
            xi = scipy.linalg.solve(A + 1e-9 * np.eye(6), b, assume_a="pos")
        except (np.linalg.LinAlgError, ValueError):
            break
        T = make_transform(np.eye(3), c) @ _se3_exp(xi) @ make_transform(np.eye(3), -c) @ T
        cutoff = max(min(cutoff, 2.0 * float(np.percentile(r_pt[good], 90))), 2.0 * min_distance)
        if np.linalg.norm(xi[:3]) < 1e-5 and np.linalg.norm(xi[3:]) < 1e-5 and it > 3:
            break
    return IcpResult(T, rms, n_in, n_in / max(len(source), 1))


# --- joint (screw) fits ---------------------------------------------------------------------


@dataclass
class JointFit:
    """A joint fitted to a part's motions: type, unit axis, point on the axis, value per step,
    and the RMS point residuals (m) of the revolute and prismatic models."""

    type: str
    axis: np.ndarray
    origin: np.ndarray
    values: np.ndarray
    rms_revolute: float
    rms_prismatic: float
    max_angle_deg: float


def _perp_basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``a`` to an orthonormal basis."""
    h = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, h)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def screw_axis(transforms: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One rotation axis shared by all ``transforms`` (closed form): unit axis, point, angles.

    The axis spans the common null space of (R_t - I); the point solves (I - R_t) p = t_t for all
    steps jointly (least squares, taken perpendicular to the axis through the world origin).
    Angles are signed about the returned axis.
    """
    M = sum((T[:3, :3] - np.eye(3)).T @ (T[:3, :3] - np.eye(3)) for T in transforms)
    _, vecs = np.linalg.eigh(M)
    a = vecs[:, 0]
    A = np.concatenate([np.eye(3) - T[:3, :3] for T in transforms])
    b = np.concatenate([T[:3, 3] for T in transforms])
    u, v = _perp_basis(a)
    B = np.stack([u, v], axis=1)
    coef, *_ = np.linalg.lstsq(A @ B, b, rcond=None)
    p = B @ coef
    angles = np.array([_signed_angle(T[:3, :3], a) for T in transforms])
    return a, p, angles


def _signed_angle(R: np.ndarray, a: np.ndarray) -> float:
    """Angle of the rotation ``R`` about the unit axis ``a`` (its component about ``a``)."""
    u, v = _perp_basis(a)
    Ru = R @ u
    return math.atan2(float(Ru @ v), float(Ru @ u))


def by_motion(revolute: JointFit, prismatic: JointFit, min_angle_deg: float = 5.0,
              min_ratio: float = 3.0) -> JointFit:
    """The type the motions show, between the two models of :func:`fit_both`: revolute when
    the part's largest rotation reaches ``min_angle_deg`` and the slide leaves ``min_ratio``
    times the turn's RMS residual (tracking drift turns drawers by a few degrees, but a slide
    still explains them about as well), else prismatic."""
    if revolute.max_angle_deg >= min_angle_deg and \
            revolute.rms_prismatic > min_ratio * revolute.rms_revolute:
        return revolute
    return prismatic


def fit_both(points: np.ndarray, transforms: list[np.ndarray],
             weights: np.ndarray | None = None) -> tuple[JointFit, JointFit]:
    """The revolute and the prismatic joint that best explain a part's motions.

    ``points`` (N,3) are part points in the closed state; ``transforms[t]`` maps them to step t.
    Both models are fitted jointly over all steps by least squares on the moved points
    (``weights`` per step, default 1). Positive values open the part: the axis sign makes most
    values positive. :func:`by_motion` chooses between them by the motions alone."""
    X = points
    if len(X) > 400:
        X = X[np.random.default_rng(0).choice(len(X), 400, replace=False)]
    Ys = [apply(T, X) for T in transforms]
    w = np.ones(len(transforms)) if weights is None else np.asarray(weights, float)
    max_angle = math.degrees(max((rotation_log(T[:3, :3])[1] for T in transforms), default=0.0))

    # prismatic: Y_t = X + d s_t
    m = np.stack([(Y - X).mean(axis=0) for Y in Ys]) * np.sqrt(w)[:, None]
    _, _, Vt = np.linalg.svd(m, full_matrices=False)
    d = Vt[0]
    s = np.array([(Y - X).mean(axis=0) @ d for Y in Ys])
    if s.sum() < 0:
        d, s = -d, -s
    rms_p = _rms([Y - X - np.outer(np.full(len(X), 1.0), d * st) for Y, st in zip(Ys, s)], w)

    a, p, th = screw_axis(transforms)
    a, p, th = _refine_revolute(X, Ys, a, p, th, w)
    if th.sum() < 0:
        a, th = -a, -th
    rms_r = _rms([Y - _rotate(X, a, p, t) for Y, t in zip(Ys, th)], w)
    return (JointFit("revolute", a, p, th, rms_r, rms_p, max_angle),
            JointFit("prismatic", d, X.mean(axis=0), s, rms_r, rms_p, max_angle))


def _rotate(X: np.ndarray, a: np.ndarray, p: np.ndarray, theta: float) -> np.ndarray:
    R = rotation_about_axis(a, theta)
    return (X - p) @ R.T + p


def _rms(residuals: list[np.ndarray], w: np.ndarray) -> float:
    num = sum(wt * float(np.mean(np.sum(r * r, axis=1))) for r, wt in zip(residuals, w))
    return math.sqrt(num / max(float(w.sum()), 1e-12))


def _refine_revolute(X: np.ndarray, Ys: list[np.ndarray], a: np.ndarray, p: np.ndarray,
                     th: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nonlinear least squares of one axis line and per-step angles on the moved points."""
    u, v = _perp_basis(a)
    sw = np.sqrt(w)

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ax = a + x[0] * u + x[1] * v
        ax /= np.linalg.norm(ax)
        return ax, p + x[2] * u + x[3] * v

    def resid(x: np.ndarray) -> np.ndarray:
        ax, pt = unpack(x)
        return np.concatenate([(sw[k] * (Ys[k] - _rotate(X, ax, pt, x[4 + k]))).ravel()
                               for k in range(len(Ys))])

    x0 = np.concatenate([[0.0, 0.0, 0.0, 0.0], th])
    sol = least_squares(resid, x0, method="lm", max_nfev=200)
    ax, pt = unpack(sol.x)
    # the point closest to the centroid of the part, for a well-placed origin
    c = X.mean(axis=0)
    pt = pt + ((c - pt) @ ax) * ax
    return ax, pt, sol.x[4:]


@dataclass
class StepData:
    """Measured points of one step for :func:`refine_joint`: points, unit normals, KD-tree and an
    optional visibility filter of model points."""

    points: np.ndarray
    normals: np.ndarray
    tree: cKDTree
    keep: Callable[[np.ndarray], np.ndarray] | None = None


def refine_joint(fit: JointFit, points: np.ndarray, steps: list[StepData], *, rounds: int = 4,
                 min_distance: float = 0.003, max_distance: float = 0.05,
                 point_weight: float = 0.02, prior: float = 0.01) -> JointFit:
    """Refine a joint fit directly on the measurements: one axis for all steps.

    ``points`` are part points in the closed state, ``steps[k]`` the measurements at the step of
    ``fit.values[k]``. Each round matches the model-placed points to the nearest measured points
    (Tukey weights on the point-to-plane residual), then solves the point-to-plane (plus
    ``point_weight`` point-to-point) least squares for the axis (direction, and the line's
    position for revolute joints) and every step's value together. A weak pull (``prior`` per
    radian or metre, against millimetre-scale residuals of hundreds of points) to the starting
    values keeps the value of a step where the part is out of sight where tracking put it.
    """
    rev = fit.type == "revolute"
    a0, p0 = fit.axis.copy(), fit.origin.copy()
    u, v = _perp_basis(a0)
    n_geo = 4 if rev else 2
    x = np.concatenate([np.zeros(n_geo), fit.values])
    x_init = x.copy()
    cutoff = max_distance

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a = a0 + x[0] * u + x[1] * v
        a = a / np.linalg.norm(a)
        p = p0 + (x[2] * u + x[3] * v if rev else 0.0)
        return a, p

    def place(x: np.ndarray, k: int, X: np.ndarray) -> np.ndarray:
        a, p = unpack(x)
        return _rotate(X, a, p, x[n_geo + k]) if rev else X + a * x[n_geo + k]

    rms = math.inf
    for _ in range(rounds):
        matches = []
        sq, wsum = 0.0, 0.0
        for k, st in enumerate(steps):
            Y = place(x, k, points)
            ok = st.keep(Y) if st.keep is not None else np.ones(len(Y), bool)
            d, j = st.tree.query(Y, distance_upper_bound=cutoff)
            ok &= np.isfinite(d)
            if ok.sum() < 6:
                continue
            q, n = st.points[j[ok]], st.normals[j[ok]]
            r = np.einsum("ij,ij->i", Y[ok] - q, n)
            scale = max(4.685 * 1.4826 * float(np.median(np.abs(r))), min_distance)
            w = tukey_weights(r, scale)
            sel = w > 0
            matches.append((k, points[ok][sel], q[sel], n[sel], np.sqrt(w[sel])))
            sq += float(np.sum(w * r * r))
            wsum += float(w.sum())
        if not matches:
            break
        rms = math.sqrt(sq / max(wsum, 1e-12))
        pw = math.sqrt(point_weight)

        def resid(x: np.ndarray) -> np.ndarray:
            # a weak pull to the start keeps values of steps without matches in place
            out = [prior * (x - x_init)]
            for k, X, q, n, sw in matches:
                diff = place(x, k, X) - q
                out.append(sw * np.einsum("ij,ij->i", diff, n))
                out.append((pw * sw[:, None] * diff).ravel())
            return np.concatenate(out)

        # each step's value moves only that step's residuals: finite differences by groups
        rows = [np.eye(len(x), dtype=bool)]
        for k, X, *_ in matches:
            block = np.zeros((4 * len(X), len(x)), bool)
            block[:, :n_geo] = True
            block[:, n_geo + k] = True
            rows.append(block)
        sparsity = coo_matrix(np.concatenate(rows))
        x = least_squares(resid, x, method="trf", max_nfev=30, x_scale="jac",
                          jac_sparsity=sparsity, tr_options={"atol": 1e-12, "btol": 1e-12}).x
        cutoff = max(cutoff / 2, 3 * min_distance)
    a, p = unpack(x)
    values = x[n_geo:]
    if values.sum() < 0:
        a, values = -a, -values
    if rev:
        c = points.mean(axis=0)
        p = p + ((c - p) @ a) * a
        return JointFit("revolute", a, p, values, rms, fit.rms_prismatic, fit.max_angle_deg)
    return JointFit("prismatic", a, fit.origin, values, fit.rms_revolute, rms, fit.max_angle_deg)
