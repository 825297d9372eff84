"""The articulated splat: the canonical (closed) splat, K joints, states per time, skinning.

Unknowns (torch tensors, optimised by :mod:`.fit`): per joint an axis (K,3) and a point on it
(K,3), the state of every joint at every interaction time (K,T) and per Gaussian the skinning
logits over base + K parts (N,K+1). Joint types are fixed per hypothesis (type selection compares
hypotheses, :mod:`.hypotheses`). States are stored in units of ``unit`` (1 rad for revolute joints,
half the object size for prismatic ones) so one learning rate suits both; the state at time 0 is
pinned to 0 (the canonical splat is the closed object). Locked joints keep their axis and point.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np
import torch
from scipy.spatial import cKDTree

from ...model.joints import Joint
from ...render.gaussians import Gaussians, concat
from ...render.rasterize import camera_centre, rasterize
from ...render.sh import C0, eval_sh_colors
from .kinematics import (PRISMATIC, REVOLUTE, joint_motions, part_members, quat_multiply, skew,
                         skin, skin_rigid)

HARD_LOGIT = 8.0    # logit of a hardened / box-assigned part (weight ~0.999 with 2 parts)
HELD_SLACK = 0.005  # x object size: what :meth:`ArticulatedSplat.leaves_path` lets pass


def hard_logits(labels: torch.Tensor, parts: int) -> torch.Tensor:
    """Skinning logits (N, ``parts``) that put each Gaussian in its part of ``labels`` (N,)."""
    logits = torch.zeros(len(labels), parts, dtype=torch.float32, device=labels.device)
    logits[torch.arange(len(labels), device=labels.device), labels] = HARD_LOGIT
    return logits


@dataclass
class Splat:
    """The fixed canonical Gaussians as tensors."""

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor
    #: colours per camera centre (:meth:`colours_from`)
    seen_from: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def n(self) -> int:
        return int(self.means.shape[0])

    def colours_from(self, w2c: torch.Tensor) -> torch.Tensor:
        """The Gaussians' colours seen from the camera ``w2c`` (by their canonical means) as
        degree-0 SH (N,1,3), cached per camera centre. The optimisation moves parts, not
        colours: evaluating the SH once per fixed camera, not at every render, takes a fifth
        of a render's cost and its gradients away (:meth:`ArticulatedSplat.colours` turns the
        view direction into a moved part's frame)."""
        centre = camera_centre(w2c)
        key = tuple(round(float(x), 6) for x in centre)
        if key not in self.seen_from:
            rgb = eval_sh_colors(self.sh, self.means, centre)
            self.seen_from[key] = ((rgb - 0.5) / C0)[:, None, :].detach()
        return self.seen_from[key]

    @classmethod
    def from_arrays(cls, a, device: torch.device) -> "Splat":
        def t(x):
            return torch.as_tensor(np.asarray(x), dtype=torch.float32, device=device)
        return cls(t(a.means), t(a.quats), t(a.log_scales), t(a.opacity_logits), t(a.sh))


def camera_motion(means: torch.Tensor, quats: torch.Tensor, w2c: torch.Tensor,
                  rotvec: torch.Tensor, shift: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Gaussians moved so that the camera ``w2c`` sees them as a camera corrected by the rotation
    ``rotvec`` and translation ``shift`` (m) in its own frame would: x -> W⁻¹ Δ W x, Δ = [exp(ω×) | s].
    Smooth at zero (the start), where the correction is the identity."""
    Rw, tw = w2c[:3, :3], w2c[:3, 3]
    Rd = torch.linalg.matrix_exp(skew(rotvec))
    R = Rw.T @ Rd @ Rw
    t = Rw.T @ (Rd @ tw + shift - tw)
    w = Rw.T @ rotvec                      # the same rotation as a world rotation vector
    angle = torch.sqrt((w * w).sum() + 1e-20)
    q = torch.cat([torch.cos(angle / 2)[None], 0.5 * torch.sinc(angle / (2 * torch.pi)) * w])
    return means @ R.T + t, quat_multiply(q.expand_as(quats), quats)


class ArticulatedSplat:
    """Canonical splat + joints + states + skinning; ``render(view, ti)`` poses and renders."""

    def __init__(self, splat: Splat, joints: list[Joint], times: list[int], labels: np.ndarray,
                 size: float, locked: list[bool], knn: int = 8) -> None:
        dev = splat.means.device
        self.splat, self.size, self.times = splat, size, list(times)
        self.names = [j.name for j in joints]
        self.types = [j.type for j in joints]
        self.locked = torch.tensor(locked, dtype=torch.bool, device=dev).reshape(-1)
        K, T = len(joints), len(times)
        f = dict(dtype=torch.float32, device=dev)
        self.axes = torch.tensor(np.array([j.axis for j in joints]).reshape(K, 3), **f)
        self.origins = torch.tensor(np.array([j.origin for j in joints]).reshape(K, 3), **f)
        self.axes0, self.origins0 = self.axes.clone(), self.origins.clone()
        self.states = torch.zeros(K, T, **f)
        for k, j in enumerate(joints):
            for ti, t in enumerate(times):
                if j.states and t in j.states:
                    self.states[k, ti] = j.states[t] / self.unit_of(j.type)
        self.moving = torch.tensor([t != 0 for t in times], **f)
        # per joint and time: the log of the part's brightness relative to its closed pose
        # (:meth:`shaded`), learnt when ``shading``
        self.gains = torch.zeros(K, T, **f)
        self.shading = False
        self.logits = hard_logits(torch.as_tensor(labels, device=dev), K + 1)
        self.hard: torch.Tensor | None = None
        self._members: tuple = (None, None)   # (hard labels, their part_members)
        # per fixed interaction camera: a correction (rotation vector, translation in object
        # sizes) in the camera's frame, learnt when ``refine_cameras`` (:func:`camera_motion`)
        self.camera_of: list[int] = []
        self.cameras = torch.zeros(0, 6, **f)
        self.refine_cameras = False
        # Gaussians drawn fully transparent (:func:`vanished`); part of :meth:`state`, so a
        # helper process renders them so too
        self.transparent: torch.Tensor | None = None
        #: per joint name, the runs of the robot's tool path its part was held along
        #: (:meth:`hold`, :meth:`held_loss`): (time indices, tool positions (M,3), tool
        #: approaches (M,3) or None)
        self.held: dict[str, list[tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]]] = {}
        tree = cKDTree(splat.means.cpu().numpy())
        k = min(knn + 1, splat.n)
        self.neighbours = torch.as_tensor(tree.query(splat.means.cpu().numpy(), k)[1][:, 1:],
                                          device=dev)

    # --- parameters ----------------------------------------------------------------------------
    @property
    def k(self) -> int:
        return len(self.types)

    def unit_of(self, kind: str) -> float:
        return 1.0 if kind == REVOLUTE else 0.5 * self.size

    def units(self) -> torch.Tensor:
        return torch.tensor([self.unit_of(t) for t in self.types], dtype=torch.float32,
                            device=self.axes.device)

    def params(self) -> dict[str, torch.Tensor]:
        """The tensors an optimiser updates (hardened models leave the logits out)."""
        p = {"axes": self.axes, "origins": self.origins, "states": self.states}
        if self.shading:
            p["gains"] = self.gains
        if self.hard is None:
            p["logits"] = self.logits
        if self.refine_cameras:
            p["cameras"] = self.cameras
        return p

    def use_cameras(self, camera_of: list[int]) -> None:
        """Learn a correction of each fixed interaction camera; ``camera_of[i]`` is the camera of
        the frame whose view has index ``i``."""
        self.camera_of = list(camera_of)
        self.cameras = torch.zeros(max(camera_of, default=-1) + 1, 6, dtype=torch.float32,
                                   device=self.axes.device)
        self.refine_cameras = True

    #: What never changes after construction (:meth:`state` leaves it out).
    FIXED = ("splat", "size", "times", "neighbours")

    def state(self) -> dict:
        """Everything an optimisation changes (joints, states, parts, cameras, flags), for
        :meth:`set_state` on a copy of this model in another process."""
        return {k: v for k, v in vars(self).items() if k not in self.FIXED}

    def set_state(self, state: dict) -> None:
        """Take over the :meth:`state` of a copy of this model."""
        vars(self).update(state)

    def load(self, params: dict[str, torch.Tensor]) -> None:
        """Take the optimiser's tensors as the current values."""
        for name, value in params.items():
            setattr(self, name, value)

    def joint_axes(self) -> torch.Tensor:
        a = torch.where(self.locked[:, None], self.axes0, self.axes)
        return a / a.norm(dim=-1, keepdim=True)

    def joint_origins(self) -> torch.Tensor:
        return torch.where(self.locked[:, None], self.origins0, self.origins)

    def joint_lines(self) -> tuple[np.ndarray, np.ndarray]:
        """Every joint's unit axis and point (K, 3 each) as float64 numpy, detached."""
        return (self.joint_axes().detach().cpu().numpy().astype(float),
                self.joint_origins().detach().cpu().numpy().astype(float))

    def values(self, ti: int) -> torch.Tensor:
        """Joint values (rad / m) at time index ``ti``."""
        return self.states[:, ti] * self.moving[ti] * self.units()

    def weights(self) -> torch.Tensor:
        """Skinning weights (N, K+1)."""
        if self.hard is not None:
            return torch.nn.functional.one_hot(self.hard, self.k + 1).float()
        return torch.softmax(self.logits, -1)

    def labels(self) -> np.ndarray:
        """Part label per Gaussian (0 = base, k+1 = joint k)."""
        if self.hard is not None:
            return self.hard.cpu().numpy()
        return self.logits.argmax(-1).cpu().numpy()

    def harden(self) -> None:
        """Fix each Gaussian to its most likely part (the rigid parts of the final model)."""
        self.hard = self.logits.detach().argmax(-1)

    # --- posing and rendering ------------------------------------------------------------------
    def members(self) -> tuple[torch.Tensor, torch.Tensor]:
        """:func:`.kinematics.part_members` of the hard labels (kept with them: they are
        replaced, never changed in place)."""
        if self._members[0] is not self.hard:
            self._members = (self.hard, part_members(self.hard))
        return self._members[1]

    def motions(self, ti: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The joints' rigid motions at time index ``ti`` (:func:`.kinematics.joint_motions`)."""
        return joint_motions(self.types, self.joint_axes(), self.joint_origins(), self.values(ti))

    def posed(self, ti: int, motions: tuple | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Means and rotations of the Gaussians at time index ``ti`` (``motions``: the
        joints' :meth:`motions` there, when the caller has them)."""
        s = self.splat
        if self.k == 0:
            return s.means, s.quats
        R, t, q = self.motions(ti) if motions is None else motions
        if self.hard is not None:
            return skin_rigid(s.means, s.quats, self.hard, R, t, q, self.members())
        return skin(s.means, s.quats, self.weights(), R, t, q)

    def render(self, view, ti: int, backend: str = "auto"):
        """The posed splat at time index ``ti`` seen by ``view``, with the view's known occluder
        Gaussians (a robot twin) rendered in."""
        motions = self.motions(ti) if self.k else None
        means, quats = self.posed(ti, motions)
        if self.refine_cameras:
            c = self.cameras[self.camera_of[view.index]]
            means, quats = camera_motion(means, quats, view.w2c, c[:3], c[3:] * self.size)
        s = self.splat
        opacity = s.opacity_logits if self.transparent is None else \
            s.opacity_logits.masked_fill(self.transparent, -30.0)
        g = Gaussians(means, quats, s.log_scales, opacity,
                      self.shaded(self.colours(view, ti, motions), ti))
        if view.occluder is not None:
            g = concat(g, view.occluder)
        return rasterize(g.means, g.quats, g.log_scales, g.opacity_logits, g.sh, view.K, view.w2c,
                         view.width, view.height, None, backend, grad_rows=self.grad_rows())

    def grad_rows(self) -> torch.Tensor | None:
        """The Gaussians whose render gradients reach a parameter: a hardened model's parts'
        (the base's stay put, and the splat itself is not fitted), unless the cameras are
        learnt (every Gaussian moves with its camera); None: all. (Without a backward pass
        the renderer ignores them.)"""
        if self.hard is None or self.refine_cameras:
            return None
        return self.members()[0]

    @torch.no_grad()
    def colours(self, view, ti: int, motions: tuple | None = None) -> torch.Tensor:
        """The Gaussians' colours in ``view`` at time index ``ti`` as degree-0 SH (N,1,3): the
        canonical splat's from the camera (:meth:`Splat.colours_from`), and for a hardened
        model each part's Gaussians along the view direction in the part's own frame (their SH
        turn with the part: R⁻¹(posed − c) = μ − R⁻¹(c − t)). No gradient: the fit moves parts
        by their geometry. ``motions``: the joints' :meth:`motions` at ``ti``, when known."""
        s = self.splat
        baked = s.colours_from(view.w2c)
        if self.hard is None or self.k == 0 or s.sh.shape[1] == 1:
            return baked
        idx, part = self.members()
        if not len(idx):
            return baked
        R, t, _ = self.motions(ti) if motions is None else motions
        local = torch.einsum("kji,kj->ki", R, camera_centre(view.w2c) - t)   # R_k^T (c - t_k)
        rgb = eval_sh_colors(s.sh[idx], s.means[idx], local[part])
        return baked.index_put((idx,), ((rgb - 0.5) / C0)[:, None, :])

    def shaded(self, sh: torch.Tensor, ti: int) -> torch.Tensor:
        """Colours ``sh`` (N,1,3, degree 0) with each part's brightness at time index ``ti``:
        its colours times exp(gain) wherever its joint is away from 0 (a part at rest, at its
        closed pose, keeps the splat's colours). A light fixed in the room shades a turning
        door differently at every angle (and a drawer's front falls into its own shadow); the
        splat baked the closed pose's shading, and without this the fit bends the joint to
        make up for it (a realistic washing machine's true joint explained its frames worse
        than one 2.8 deg off, by its colour)."""
        if not self.shading or self.k == 0:
            return sh
        away = (self.values(ti).detach() != 0).float()
        more = torch.exp(self.gains[:, ti] * away) - 1                     # (K,) 0: as baked
        # f·rgb as SH: sh + (f - 1)(sh + 0.5 / C0), exactly sh where f is 1
        if self.hard is not None:
            idx, part = self.members()
            if not len(idx):
                return sh
            return sh.index_put((idx,), sh[idx] + more[part, None, None] * (sh[idx] + 0.5 / C0))
        more = self.weights()[:, 1:] @ more
        return sh + more[:, None, None] * (sh + 0.5 / C0)

    def gain_prior(self) -> torch.Tensor:
        """Mean squared log brightness of the parts (keeps gains the frames do not ask for at 1)."""
        if not self.shading or self.k == 0:
            return torch.zeros((), device=self.axes.device)
        return (self.gains ** 2).mean()

    # --- regularisers --------------------------------------------------------------------------
    def skin_regularisers(self, sample: int = 2048) -> tuple[torch.Tensor, torch.Tensor]:
        """kNN smoothness (mean L1 difference of neighbours' weights) and mean entropy, estimated
        on a random ``sample`` of the Gaussians (unbiased; a step's cost stays that of the render
        whatever the splat's size)."""
        if self.hard is not None or self.k == 0:
            z = torch.zeros((), device=self.axes.device)
            return z, z
        n = self.splat.n
        idx = torch.randint(n, (sample,), device=self.logits.device) if n > sample else \
            torch.arange(n, device=self.logits.device)
        w = torch.softmax(self.logits[idx], -1)
        wn = torch.softmax(self.logits[self.neighbours[idx]], -1)
        smooth = (w[:, None, :] - wn).abs().sum(-1).mean()
        entropy = -(w * torch.log(w.clamp_min(1e-8))).sum(-1).mean()
        return smooth, entropy

    def camera_prior(self, rotation: float, translation: float) -> torch.Tensor:
        """Sum over cameras of the squared correction in units of ``rotation`` (rad) and
        ``translation`` (object sizes): keeps the cameras where the frames do not pull them."""
        if not self.refine_cameras:
            return torch.zeros((), device=self.axes.device)
        c = self.cameras
        return ((c[:, :3] / rotation) ** 2).sum() + ((c[:, 3:] / translation) ** 2).sum()

    def temporal(self) -> torch.Tensor:
        """Mean squared change of the states between consecutive times (state units)."""
        if self.states.shape[1] < 2 or self.k == 0:
            return torch.zeros((), device=self.axes.device)
        s = self.states * self.moving
        return ((s[:, 1:] - s[:, :-1]) ** 2).mean()

    def hold(self, name: str, ti: list[int], positions: np.ndarray,
             approaches: np.ndarray | None = None) -> None:
        """Record that joint ``name``'s part was held by the robot's tool at ``positions``
        (M,3), with the tool's approach directions ``approaches`` (M,3) when known, at time
        indices ``ti`` (:attr:`held`)."""
        f = dict(dtype=torch.float32, device=self.axes.device)
        if approaches is not None:
            approaches = np.asarray(approaches, float)
            approaches = approaches / np.linalg.norm(approaches, axis=1, keepdims=True)
        self.held.setdefault(name, []).append(
            (torch.as_tensor(ti, device=self.axes.device),
             torch.as_tensor(np.asarray(positions, float), **f),
             None if approaches is None else torch.as_tensor(approaches, **f)))

    def pass_runs(self, k: int, j: int) -> None:
        """Joint ``j`` also holds the runs joint ``k``'s part was held along (:attr:`held`) when
        it is of ``k``'s type (a slide's runs would bend a hinge towards a line)."""
        if self.types[j] == self.types[k]:
            self.held.setdefault(self.names[j], []).extend(self.held.get(self.names[k], []))

    def held_back(self, k: int) -> list[tuple[torch.Tensor, torch.Tensor | None]]:
        """Per run joint ``k``'s part was held along (:attr:`held`): its tool positions carried
        back to the closed pose by the joint's motion at their times (M,3; a rigid grasp
        carries back to one point), and with approaches known, how much more or less the hand
        turned from the run's first approach than the joint turns it (M, chord lengths on the
        unit sphere). The turn's size, not its direction: an arm's IK trades a degree of the
        hand's orientation for reach, which on a short arc tilts a hinge fitted to the
        directions by degrees, while the size pins the angles."""
        axes, origins = self.joint_axes()[k], self.joint_origins()[k]
        out = []
        for ti, P, A in self.held.get(self.names[k], ()):
            m = len(ti)
            values = self.states[k, ti] * self.moving[ti] * self.unit_of(self.types[k])
            R, t, _ = joint_motions([self.types[k]] * m, axes.expand(m, 3), origins.expand(m, 3),
                                    values)
            back = torch.einsum("mji,mj->mi", R, P - t)                    # R^T (p - t)
            turn = None
            if A is not None:
                carried = R @ (R[0].T @ A[0])                              # A[0] turned alike
                chord = lambda x: ((x - A[0]) ** 2).sum(-1).add(1e-12).sqrt()   # noqa: E731
                turn = chord(A) - chord(carried)
            out.append((back, turn))
        return out

    def held_loss(self, sigma: float, lever: float) -> torch.Tensor:
        """How far the joints' motions are from the robot's tool that held their parts: per run,
        the spread of :meth:`held_back`'s points about their mean plus its turn differences as
        a distance at ``lever`` m (on a short arc the positions alone leave the hinge's radius
        free, traded against the angles), robustly (Cauchy, scale ``sigma`` m: a grasp that
        slipped at a few times cannot pull the joint), mean over the run, summed over the
        runs."""
        terms = []
        for k in range(self.k):
            for p, turn in self.held_back(k):
                d2 = ((p - p.mean(0)) ** 2).sum(-1)
                if turn is not None:
                    d2 = d2 + (lever * turn) ** 2
                terms.append(torch.log1p(d2 / sigma ** 2).mean())
        return torch.stack(terms).sum() if terms else torch.zeros((), device=self.axes.device)

    @torch.no_grad()
    def held_residual(self, k: int) -> float | None:
        """RMS distance (m) of :meth:`held_back`'s points from their run's mean; None when
        joint ``k`` holds no run."""
        backs = self.held_back(k)
        if not backs:
            return None
        sq = torch.cat([((p - p.mean(0)) ** 2).sum(-1) for p, _ in backs])
        return float(sq.mean().sqrt())

    def leaves_path(self, k: int, before: float | None) -> bool:
        """Whether joint ``k`` now carries its held tool positions clearly worse than
        ``before`` (its :meth:`held_residual` then): farther by more than ``HELD_SLACK`` of the
        object's size. Steps that decide by the image loss alone (the start kept, the depth's
        last decimals, the body's box) must not trade what the robot measured for a tie of
        the image loss."""
        return farther(self.held_residual(k), before, self.size)

    def prior(self, strength: torch.Tensor) -> torch.Tensor:
        """Pull towards the start (``strength`` (K,) per joint): 1 − |cos| of the axes plus the
        squared distance of the start's point from the axis line, in object sizes."""
        if self.k == 0:
            return torch.zeros((), device=self.axes.device)
        u = self.joint_axes()
        cos = (u * self.axes0 / self.axes0.norm(dim=-1, keepdim=True)).sum(-1).abs()
        d = self.origins0 - self.joint_origins()
        d = d - (d * u).sum(-1, keepdim=True) * u
        rev = torch.tensor([t == REVOLUTE for t in self.types], device=u.device)
        dist = torch.where(rev, (d ** 2).sum(-1) / self.size ** 2, torch.zeros_like(cos))
        return (strength * (1 - cos + dist)).sum()

    # --- export --------------------------------------------------------------------------------
    def joint_values(self, k: int) -> dict[int, float]:
        """State of joint ``k`` per time (rad / m)."""
        unit = self.unit_of(self.types[k])
        return {t: float(self.states[k, ti] * self.moving[ti]) * unit
                for ti, t in enumerate(self.times)}

    def set_type(self, k: int, kind: str, axis: np.ndarray, origin: np.ndarray,
                 values: dict[int, float] | np.ndarray, shading: bool = False) -> None:
        """Replace joint ``k``'s hypothesis (type, axis, point, states in rad / m). The part's
        learnt brightness per time (:meth:`shaded`) starts again from 1, unless ``shading``
        (the same motion refined: the brightness the part shows at each time stays)."""
        assert kind in (REVOLUTE, PRISMATIC)
        with torch.no_grad():
            self.types[k] = kind
            self.axes = self.axes.detach().clone()
            self.origins = self.origins.detach().clone()
            self.states = self.states.detach().clone()
            if not shading:
                self.gains = self.gains.detach().clone()
                self.gains[k] = 0.0
            self.axes[k] = torch.as_tensor(np.asarray(axis, float), dtype=torch.float32)
            self.origins[k] = torch.as_tensor(np.asarray(origin, float), dtype=torch.float32)
            v = np.asarray([values[t] for t in self.times] if isinstance(values, dict)
                           else values, float)
            self.states[k] = torch.as_tensor(v / self.unit_of(kind), dtype=torch.float32)

    def reassign(self, members: np.ndarray, label: int) -> None:
        """Give the Gaussians ``members`` (bool, N) to part ``label`` (0 = base), in the hard
        assignment (if any) and the logits."""
        m = torch.as_tensor(members, device=self.logits.device)
        with torch.no_grad():
            self.logits = self.logits.detach().clone()
            self.logits[m] = 0.0
            self.logits[m, label] = HARD_LOGIT
            if self.hard is not None:
                h = self.hard.clone()
                h[m] = label
                self.hard = h

    def reassign_all(self, labels: np.ndarray) -> None:
        """Make ``labels`` (N,) the hard assignment (and the logits' argmax)."""
        h = torch.as_tensor(labels, device=self.logits.device)
        self.logits = hard_logits(h, self.k + 1)
        self.hard = h.clone()

    def drop(self, k: int) -> None:
        """Remove joint ``k``; its Gaussians join the base."""
        keep = [i for i in range(self.k) if i != k]
        cols = [0] + [i + 1 for i in keep]
        with torch.no_grad():
            for name in ("axes", "origins", "axes0", "origins0", "states", "gains"):
                setattr(self, name, getattr(self, name).detach()[keep].clone())
            self.locked = self.locked[keep]
            was = self.logits.detach().argmax(-1) == k + 1
            self.logits = self.logits.detach()[:, cols].clone()
            self.logits[was] = 0.0
            self.logits[was, 0] = HARD_LOGIT
            if self.hard is not None:
                h = self.hard.clone()
                h[self.hard == k + 1] = 0
                h[self.hard > k + 1] -= 1
                self.hard = h
        self.held.pop(self.names[k], None)
        del self.names[k], self.types[k]

    def add(self, name: str, kind: str, axis: np.ndarray, origin: np.ndarray,
            members: np.ndarray) -> int:
        """Append a joint whose part is the Gaussians ``members`` (bool, N); returns its index.
        Only for hardened models (the new part is a hard assignment)."""
        assert self.hard is not None
        dev = self.axes.device
        f = dict(dtype=torch.float32, device=dev)
        row = lambda v: torch.as_tensor(np.asarray(v, float), **f).reshape(1, 3)  # noqa: E731
        with torch.no_grad():
            self.axes = torch.cat([self.axes.detach(), row(axis)])
            self.origins = torch.cat([self.origins.detach(), row(origin)])
            self.axes0 = torch.cat([self.axes0, row(axis)])
            self.origins0 = torch.cat([self.origins0, row(origin)])
            self.states = torch.cat([self.states.detach(), torch.zeros(1, len(self.times), **f)])
            self.gains = torch.cat([self.gains.detach(), torch.zeros(1, len(self.times), **f)])
            self.locked = torch.cat([self.locked, torch.zeros(1, dtype=torch.bool, device=dev)])
            logits = torch.zeros(self.splat.n, 1, **f)
            self.logits = torch.cat([self.logits.detach(), logits], 1)
            m = torch.as_tensor(members, device=dev)
            self.logits[m] = 0.0
            self.logits[m, -1] = HARD_LOGIT
            h = self.hard.clone()
            h[m] = self.k + 1
            self.hard = h
        self.names.append(name)
        self.types.append(kind)
        return self.k - 1


def farther(now: float | None, before: float | None, size: float) -> bool:
    """Whether a :meth:`ArticulatedSplat.held_residual` ``now`` is farther than ``before`` by
    more than ``HELD_SLACK`` of the object's ``size`` (False when either is None)."""
    return now is not None and before is not None and now > before + HELD_SLACK * size


@contextmanager
def unshaded(model: ArticulatedSplat) -> Iterator[None]:
    """The model without its parts' brightness (:meth:`ArticulatedSplat.shaded`) for the
    duration: whether a part exists is decided by its motion alone (a brightness per time is
    free to explain exposure drift or a shadow on a piece that does not move)."""
    before = model.shading
    model.shading = False
    try:
        yield
    finally:
        model.shading = before


@contextmanager
def vanished(model: ArticulatedSplat, k: int) -> Iterator[None]:
    """Joint ``k``'s part drawn transparent for the duration (its Gaussians' opacity logits at
    -30 in :meth:`ArticulatedSplat.render`; a model attribute, not the splat, so that a helper
    process, which is sent the model's state and not its splat, renders it gone too)."""
    before = model.transparent
    model.transparent = torch.as_tensor(model.labels() == k + 1,
                                        device=model.splat.opacity_logits.device)
    try:
        yield
    finally:
        model.transparent = before


def snapshot(model: ArticulatedSplat) -> tuple:
    """The model's joint types, axes, points, states and part gains (copies), for
    :func:`restore`."""
    return (list(model.types), model.axes.detach().clone(), model.origins.detach().clone(),
            model.states.detach().clone(), model.gains.detach().clone())


def restore(model: ArticulatedSplat, snap: tuple) -> None:
    """Take back the joints of a :func:`snapshot`."""
    model.types = list(snap[0])
    model.axes, model.origins, model.states, model.gains = (t.clone() for t in snap[1:])
