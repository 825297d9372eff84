"""Differentiable joint motions and linear blend skinning of Gaussians (torch).

A revolute joint (unit axis u through point q) at angle θ moves x to R(u, θ)(x − q) + q, R by
Rodrigues; a prismatic joint moves x to x + θ·u. Part 0 is the base (identity). Skinning blends the
parts' motions with per-Gaussian weights W (N, K+1) (ArtGS eq. of LBS): means
μ' = Σ_j W_j (R_j μ + t_j); rotations r' = normalise(Σ_j W_j q_j) ⊗ r, q_j the unit quaternion of
R_j (with hard weights this is the exact rigid motion of the Gaussian's part).
"""

from __future__ import annotations

import torch

REVOLUTE, PRISMATIC = "revolute", "prismatic"


def skew(u: torch.Tensor) -> torch.Tensor:
    """(…,3) vectors -> (…,3,3) cross-product matrices."""
    z = torch.zeros_like(u[..., 0])
    return torch.stack([torch.stack([z, -u[..., 2], u[..., 1]], -1),
                        torch.stack([u[..., 2], z, -u[..., 0]], -1),
                        torch.stack([-u[..., 1], u[..., 0], z], -1)], -2)


def rodrigues(u: torch.Tensor, theta: torch.Tensor) -> torch.Tensor:
    """Rotations (…,3,3) by ``theta`` (…) about unit axes ``u`` (…,3)."""
    k = skew(u)
    s, c = torch.sin(theta)[..., None, None], torch.cos(theta)[..., None, None]
    eye = torch.eye(3, dtype=u.dtype, device=u.device).expand(k.shape)
    return eye + s * k + (1 - c) * (k @ k)


def joint_motions(types: list[str], axes: torch.Tensor, origins: torch.Tensor,
                  values: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Rigid motions of K joints at ``values`` (K,): rotations (K,3,3), translations (K,3) and
    unit quaternions w x y z (K,4). ``axes`` (K,3) need not be normalised."""
    u = axes / axes.norm(dim=-1, keepdim=True)
    revolute = torch.tensor([t == REVOLUTE for t in types], device=u.device)
    angle = torch.where(revolute, values, torch.zeros_like(values))
    R = rodrigues(u, angle)
    t_rev = origins - (R @ origins[..., None])[..., 0]
    t = torch.where(revolute[:, None], t_rev, values[:, None] * u)
    half = angle / 2
    q = torch.cat([torch.cos(half)[:, None], torch.sin(half)[:, None] * u], -1)
    return R, t, q


def quat_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product of (…,4) quaternions w x y z."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack([aw * bw - ax * bx - ay * by - az * bz,
                        aw * bx + ax * bw + ay * bz - az * by,
                        aw * by - ax * bz + ay * bw + az * bx,
                        aw * bz + ax * by - ay * bx + az * bw], -1)


def skin(means: torch.Tensor, quats: torch.Tensor, weights: torch.Tensor, R: torch.Tensor,
         t: torch.Tensor, q: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """LBS of Gaussians (means (N,3), quats (N,4)) by base + K part motions; ``weights``
    (N, K+1), column 0 the base. Returns the posed means and (unnormalised-input) quats."""
    moved = torch.einsum("kij,nj->kni", R, means) + t[:, None, :]           # (K,N,3)
    w = weights[:, 1:].T[..., None]                                          # (K,N,1)
    out_means = weights[:, :1] * means + (w * moved).sum(0)
    ident = torch.zeros(1, 4, dtype=q.dtype, device=q.device)
    ident[0, 0] = 1.0
    blend = weights @ torch.cat([ident, q], 0)                               # (N,4)
    blend = blend / blend.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    return out_means, quat_multiply(blend, quats)


def part_members(labels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The Gaussians of the parts in ``labels`` (N,) (0 = base): their indices and part (k − 1)."""
    idx = torch.nonzero(labels > 0).squeeze(1)
    return idx, labels[idx] - 1


def skin_rigid(means: torch.Tensor, quats: torch.Tensor, labels: torch.Tensor, R: torch.Tensor,
               t: torch.Tensor, q: torch.Tensor,
               members: tuple[torch.Tensor, torch.Tensor] | None = None
               ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`skin` with one-hot weights given as ``labels`` (N,) (0 = base, k = part k − 1):
    each Gaussian of a part moves rigidly with it, the base's are returned as they are. Same
    result as :func:`skin`, at a fraction of the cost (only the parts' Gaussians are touched).
    ``members``: :func:`part_members` of ``labels``, when the caller keeps them."""
    idx, part = part_members(labels) if members is None else members
    if len(idx) == 0:
        return means, quats
    moved = torch.einsum("nij,nj->ni", R[part], means[idx]) + t[part]
    turned = quat_multiply(q[part], quats[idx])
    return means.index_put((idx,), moved), quats.index_put((idx,), turned)
