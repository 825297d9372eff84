"""Rasterizer: numba CPU backend vs the pure-torch reference (values and gradients), edge cases,
and an analytic check of the EWA projection."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from artgs.core.model.cameras import Camera, intrinsics, look_at
from artgs.core.render.device import resolve_backend, resolve_device
from artgs.core.model.errors import ArtgsError
from artgs.core.render import reference as raster_reference
from artgs.core.render.gaussians import Gaussians
from artgs.core.render.constants import LOW_PASS
from artgs.core.render.cpu.project import quat_to_rotmat
from artgs.core.render.rasterize import rasterize, render
from artgs.core.render.sh import C0, sh_basis

W, H = 32, 24
K = intrinsics(30.0, 32.0, 15.5, 12.5)
BG = [0.2, 0.4, 0.1]
DT = torch.float64


def random_scene(seed: int, n: int = 50, degree: int = 1, dtype=DT) -> list[torch.Tensor]:
    """n Gaussians 1.6..2.4 m in front of an identity camera, spread over the view."""
    g = torch.Generator().manual_seed(seed)
    u = torch.rand(n, 3, generator=g, dtype=dtype)
    means = torch.stack([(u[:, 0] - 0.5) * 1.3, (u[:, 1] - 0.5) * 1.0, 1.6 + 0.8 * u[:, 2]], 1)
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    log_scales = torch.log(0.02 + 0.1 * torch.rand(n, 3, generator=g, dtype=dtype))
    opacity_logits = 2.0 * torch.randn(n, generator=g, dtype=dtype)
    sh = 0.4 * torch.randn(n, (degree + 1) ** 2, 3, generator=g, dtype=dtype)
    return [means, quats, log_scales, opacity_logits, sh]


def render_both(params, w2c=np.eye(4), width=W, height=H, k=K, weights_seed=0,
                low_pass=LOW_PASS):
    """Renders with both backends; returns {backend: (outputs, gradients of a random loss)}."""
    gen = torch.Generator().manual_seed(weights_seed)
    wc = torch.rand(height, width, 3, generator=gen, dtype=DT)
    wd = torch.rand(height, width, generator=gen, dtype=DT)
    wa = torch.rand(height, width, generator=gen, dtype=DT)
    result = {}
    for backend in ("reference", "cpu"):
        ps = [p.detach().clone().requires_grad_(True) for p in params]
        out = rasterize(*ps, k, w2c, width, height, background=BG, backend=backend,
                        low_pass=low_pass)
        loss = (out.rgb * wc).sum() + (out.depth * wd).sum() + (out.alpha * wa).sum()
        grads = torch.autograd.grad(loss, ps, allow_unused=True)
        result[backend] = (out, [torch.zeros_like(p) if gr is None else gr
                                 for p, gr in zip(ps, grads)])
    return result


def rel_err(a: torch.Tensor, b: torch.Tensor) -> float:
    """||a - b|| / ||b||; gradients below 1e-8 (losses here are O(1..100)) count as zero."""
    return float((a - b).norm() / b.norm().clamp_min(1e-8))


def assert_match(result, grad_tol=1e-3):
    (ref, gref), (cpu, gcpu) = result["reference"], result["cpu"]
    for name in ("rgb", "depth", "alpha"):
        a, b = getattr(cpu, name), getattr(ref, name)
        assert a.shape == b.shape and a.dtype == b.dtype
        assert float((a - b).detach().abs().max()) < 1e-4, name
    names = ("means", "quats", "log_scales", "opacity_logits", "sh")
    for name, gc, gr in zip(names, gcpu, gref):
        assert torch.isfinite(gc).all(), name
        assert rel_err(gc, gr) < grad_tol, (name, rel_err(gc, gr))
        # per Gaussian: each Gaussian's gradient matches relative to the largest ones
        scale = gr.reshape(len(gr), -1).norm(dim=1).max().clamp_min(1e-8)
        assert float((gc - gr).abs().max() / scale) < grad_tol, name


@pytest.mark.parametrize("seed,degree", [(0, 0), (1, 1), (2, 2), (3, 3), (4, 3)])
def test_matches_reference(seed, degree):
    params = random_scene(seed, degree=degree)
    result = render_both(params, weights_seed=seed)
    ref = result["reference"][0]
    assert float(ref.alpha.detach().max()) > 0.9 and float(ref.alpha.detach().min()) < 0.1  # a non-trivial scene
    assert_match(result)


def test_original_3dgs_low_pass_matches_reference():
    """``low_pass=0.3`` (the original 3DGS dilation, for splats trained with it) in both backends:
    the same model, and wider footprints than the default."""
    params = random_scene(5, degree=1)
    result = render_both(params, weights_seed=5, low_pass=0.3)
    assert_match(result)
    default = rasterize(*params, K, np.eye(4), W, H, BG, backend="cpu")
    assert float(result["cpu"][0].alpha.detach().sum()) > float(default.alpha.sum()) + 1e-3


def test_matches_reference_general_camera():
    """A rotated and translated camera (w2c not the identity), non-square pixels."""
    eye, target = np.array([0.7, -2.1, 0.9]), np.array([0.05, 0.1, 0.2])
    cam = Camera(intrinsics(28.0, 33.0, 15.0, 12.5), look_at(eye, target), W, H)
    params = random_scene(31, n=60, degree=2)
    c2w_cv = torch.tensor(np.linalg.inv(cam.w2c))
    params[0] = params[0] @ c2w_cv[:3, :3].T + c2w_cv[:3, 3]
    result = render_both(params, w2c=cam.w2c, k=cam.K, weights_seed=31)
    assert float(result["reference"][0].alpha.detach().max()) > 0.9
    assert_match(result)


def test_dense_scene_early_stop(monkeypatch):
    """Many overlapping opaque Gaussians: deep stacks where the 1e-4 early stop changes the
    image, and alphas clamped at 0.99."""
    params = random_scene(7, n=120, degree=2)
    params[2] = params[2] + 1.0          # larger
    params[3] = params[3].abs() + 2.0    # opaque (some beyond the 0.99 clamp)
    result = render_both(params, weights_seed=7)
    alpha = result["reference"][0].alpha.detach()
    assert float((alpha > 0.999).double().mean()) > 0.3
    assert_match(result)
    monkeypatch.setattr(raster_reference, "T_MIN", 0.0)   # no early stop
    no_stop = rasterize(*params, K, np.eye(4), W, H, BG, backend="reference")
    assert float((no_stop.rgb - result["reference"][0].rgb.detach()).abs().max()) > 1e-4


def test_joint_transform_upstream():
    """means = R(theta) x + t, quats rotated by R(theta): theta gets the reference gradient."""
    params = random_scene(11, n=40, degree=1)
    theta0 = torch.tensor([0.3, -0.2, 0.1], dtype=DT)
    grads = {}
    for backend in ("reference", "cpu"):
        theta = theta0.clone().requires_grad_(True)
        trans = torch.tensor([0.05, -0.02, 0.1], dtype=DT, requires_grad=True)
        angle = theta.norm()
        axis = theta / angle
        Kx = torch.zeros(3, 3, dtype=DT)
        Kx[0, 1], Kx[0, 2], Kx[1, 2] = -axis[2], axis[1], -axis[0]
        Kx = Kx - Kx.T
        R = torch.eye(3, dtype=DT) + torch.sin(angle) * Kx + (1 - torch.cos(angle)) * Kx @ Kx
        centre = torch.tensor([0.0, 0.0, 2.0], dtype=DT)
        means = (params[0] - centre) @ R.T + centre + trans
        qr = torch.cat([torch.cos(angle / 2)[None], torch.sin(angle / 2) * axis])
        w1, v1 = qr[0], qr[1:]
        q = params[1] / params[1].norm(dim=1, keepdim=True)
        w2, v2 = q[:, :1], q[:, 1:]
        quats = torch.cat([w1 * w2 - (v2 * v1).sum(1, keepdim=True),
                           w1 * v2 + w2 * v1 + torch.cross(v1.expand_as(v2), v2, dim=1)], 1)
        out = rasterize(means, quats, *params[2:], K, np.eye(4), W, H, BG, backend=backend)
        target = torch.linspace(0, 1, W * H * 3, dtype=DT).reshape(H, W, 3)
        loss = ((out.rgb - target) ** 2).sum() + out.depth.sum()
        grads[backend] = torch.cat(torch.autograd.grad(loss, [theta, trans]))
    assert grads["reference"].norm() > 1e-3
    assert rel_err(grads["cpu"], grads["reference"]) < 1e-3


def test_projection_matches_analytic_isotropic_gaussian():
    """An isotropic Gaussian of std s at depth z on the axis: alpha(d) = o exp(-d^2 / 2 v),
    v = (f s / z)^2 + LOW_PASS, and zero beyond 3 sigma; its depth is z everywhere (on the axis,
    the max-density point of every pixel's ray lies at z)."""
    f, z, s, o = 30.0, 2.0, 0.1, 0.6
    k = intrinsics(f, f, 16.0, 12.0)  # the mean projects to the corner between 4 pixels
    params = [torch.tensor([[0.0, 0.0, z]], dtype=DT), torch.tensor([[0.7, 0.1, -0.3, 0.2]], dtype=DT),
              torch.full((1, 3), math.log(s), dtype=DT), torch.tensor([math.log(o / (1 - o))], dtype=DT),
              torch.full((1, 1, 3), (0.8 - 0.5) / C0, dtype=DT)]
    out = rasterize(*params, k, np.eye(4), W, H, backend="cpu")
    v = (f * s / z) ** 2 + LOW_PASS
    jj, ii = np.meshgrid(np.arange(W) + 0.5 - 16.0, np.arange(H) + 0.5 - 12.0)
    d2 = jj ** 2 + ii ** 2
    expected = o * np.exp(-0.5 * d2 / v)
    expected[(d2 > 9 * v) | (expected < 1 / 255)] = 0.0
    np.testing.assert_allclose(out.alpha.numpy(), expected, atol=2e-6)
    np.testing.assert_allclose(out.rgb.numpy()[..., 0], 0.8 * expected, atol=2e-6)
    np.testing.assert_allclose(out.depth.numpy()[expected > 0], z, rtol=1e-5)
    assert (out.depth.numpy()[expected == 0] == 0).all()


@pytest.mark.parametrize("backend", ["cpu", "reference"])
def test_flat_disc_renders_its_plane_depth(backend):
    """A flat disc on a plane slanted 30 degrees, off the optical axis: every pixel it covers
    gets the plane's depth linearised at the disc's centre (within 1e-4 m), i.e. the plane's
    exact depth up to its curvature in pixel space (< 1 cm here), where the centre depth would
    be off by up to ~8 cm."""
    f, cx, cy = 30.0, 16.0, 12.0
    k = intrinsics(f, f, cx, cy)
    mean = np.array([0.1, -0.05, 2.0])
    half = math.radians(15.0)  # rotation about y by 30 degrees: local z -> n
    n = np.array([math.sin(2 * half), 0.0, math.cos(2 * half)])
    params = [torch.tensor(mean[None], dtype=DT),
              torch.tensor([[math.cos(half), 0, math.sin(half), 0]], dtype=DT),
              torch.tensor([[math.log(0.06), math.log(0.06), -14.0]], dtype=DT),
              torch.tensor([3.0], dtype=DT), torch.zeros(1, 1, 3, dtype=DT)]
    out = rasterize(*params, k, np.eye(4), W, H, backend=backend)
    u, v = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    rays = np.stack([(u - cx) / f, (v - cy) / f, np.ones_like(u)], -1)
    plane = (n @ mean) / (rays @ n)                       # exact depth of the plane
    m2d = f * mean[:2] / mean[2] + [cx, cy]
    grad = -mean[2] ** 2 * n[:2] / (f * (n @ mean))       # d plane depth / d pixel at m2d
    linear = mean[2] + grad[0] * (u - m2d[0]) + grad[1] * (v - m2d[1])
    covered = out.alpha.detach().numpy() > 1e-3
    depth = out.depth.detach().numpy()
    assert covered.sum() > 20
    assert np.abs(depth - linear)[covered].max() < 1e-4
    assert np.abs(depth - plane)[covered].max() < 1e-2
    assert np.abs(mean[2] - plane)[covered].max() > 0.05


def stacked_on_pixel(opacities, colors, pixel=(5, 7), k=K):
    """Tiny Gaussians, one behind the other, all centred on pixel ``pixel`` (row, col).

    Anisotropic (so the planar depth's slopes depend on the rotation: for isotropic ones the
    quaternion gradient is exactly zero and float32 cancellation noise is all that is left)."""
    n = len(opacities)
    z = torch.linspace(1.0, 2.0, n, dtype=DT)
    u, v = pixel[1] + 0.5, pixel[0] + 0.5
    x = (u - k[0, 2]) / k[0, 0] * z
    y = (v - k[1, 2]) / k[1, 1] * z
    op = torch.tensor(opacities, dtype=DT)
    return [torch.stack([x, y, z], 1), torch.tensor([[1.0, 0, 0, 0]] * n, dtype=DT),
            torch.tensor([[-9.0, -8.5, -9.5]] * n, dtype=DT), torch.log(op / (1 - op)),
            ((torch.tensor(colors, dtype=DT) - 0.5) / C0)[:, None, :]]


def test_early_stop_and_alpha_clamp_exact():
    # alpha 0.95 each: T = 0.05, 0.0025, 1.25e-4, then 6.25e-6 < 1e-4 -> the 4th is not blended
    cols = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1, 1, 1]]
    params = stacked_on_pixel([0.95] * 5, cols)
    for backend in ("cpu", "reference"):
        out = rasterize(*params, K, np.eye(4), W, H, backend=backend)
        T = 0.05 ** 3
        assert abs(float(out.alpha[5, 7]) - (1 - T)) < 1e-6
        np.testing.assert_allclose(out.rgb[5, 7].numpy(), [0.95, 0.05 * 0.95, 0.0025 * 0.95],
                                   atol=1e-6)
        # the clamp: opacity 0.9999 gives alpha 0.99 at the centre
        single = stacked_on_pixel([0.9999], [[0.5, 0.5, 0.5]])
        out = rasterize(*single, K, np.eye(4), W, H, backend=backend)
        assert abs(float(out.alpha[5, 7]) - 0.99) < 1e-6
    assert_match(render_both(stacked_on_pixel([0.95, 0.9, 0.97, 0.8, 0.999], cols)))


def test_culled_gaussians_have_no_effect_and_zero_gradient():
    params = random_scene(5, n=30)
    extra = random_scene(6, n=12)
    extra[0] = extra[0].clone()
    extra[0][:4, 2] = -extra[0][:4, 2]            # behind the camera
    extra[0][4:6, 2] = 0.0                         # on the camera plane
    extra[0][6:9, 0] += 50.0                       # far off-screen right
    extra[0][9:12, 1] -= 40.0                      # far off-screen up
    both = [torch.cat([a, b]) for a, b in zip(params, extra)]
    result = render_both(both)
    assert_match(result)
    alone = rasterize(*params, K, np.eye(4), W, H, BG, backend="cpu")
    out, grads = result["cpu"]
    for name in ("rgb", "depth", "alpha"):
        assert torch.equal(getattr(out, name), getattr(alone, name))
    for gr in grads:
        assert torch.isfinite(gr).all() and (gr[30:] == 0).all()


def test_large_gaussians_beyond_the_view_edge():
    """Centres outside 1.3x the field of view (the clamped-Jacobian path) reaching into the image."""
    params = random_scene(17, n=24)
    z = params[0][:, 2]
    u = torch.linspace(-1, 1, 24, dtype=DT)
    # x/z (or y/z) about 0.85 outside the image edge: beyond the clamp limit (0.67 / 0.62)
    params[0] = torch.stack([torch.where(u > 0, 0.85, -0.85) * z * (u.abs() > 0.5),
                             torch.where(u > 0, 0.8, -0.8) * z * (u.abs() <= 0.5), z], 1)
    params[2] = torch.full_like(params[2], math.log(0.35)) + 0.2 * torch.randn(
        24, 3, generator=torch.Generator().manual_seed(3), dtype=DT)
    result = render_both(params, weights_seed=17)
    assert float(result["reference"][0].alpha.detach().max()) > 0.3
    assert_match(result)


def test_degenerate_scales():
    params = random_scene(9, n=30)
    params[2] = params[2].clone()
    params[2][:10] = -14.0                      # points: only the low-pass dilation remains
    params[2][10:20, 0] = -14.0                 # flat discs
    params[2][20:25, 1:] = -14.0                # needles
    assert_match(render_both(params))


@pytest.mark.parametrize("backend", ["cpu", "reference"])
def test_no_gaussians_gives_background(backend):
    empty = [torch.zeros(0, 3, dtype=DT), torch.zeros(0, 4, dtype=DT), torch.zeros(0, 3, dtype=DT),
             torch.zeros(0, dtype=DT), torch.zeros(0, 4, 3, dtype=DT)]
    out = rasterize(*empty, K, np.eye(4), W, H, BG, backend=backend)
    assert torch.equal(out.rgb, torch.tensor(BG, dtype=DT).expand(H, W, 3))
    assert (out.alpha == 0).all() and (out.depth == 0).all()


def test_odd_image_size():
    """Image sizes that are not a multiple of the tile size (partial tiles on both edges)."""
    k = intrinsics(20.0, 21.0, 13.0, 9.5)
    params = random_scene(21, n=40, degree=1)
    result = render_both(params, width=27, height=19, k=k)
    assert result["cpu"][0].rgb.shape == (19, 27, 3)
    assert_match(result)


def test_sh_basis_is_orthonormal():
    """Real SH up to degree 3 on a fine Fibonacci sphere: integral of Y_i Y_j = delta_ij."""
    n = 40000
    i = torch.arange(n, dtype=DT) + 0.5
    z = 1 - 2 * i / n
    phi = math.pi * (3 - math.sqrt(5)) * i
    r = torch.sqrt(1 - z * z)
    dirs = torch.stack([r * torch.cos(phi), r * torch.sin(phi), z], 1)
    Y = sh_basis(3, dirs)
    gram = Y.T @ Y * (4 * math.pi / n)
    assert torch.allclose(gram, torch.eye(16, dtype=DT), atol=2e-3)
    assert torch.allclose(Y[:, 0], torch.full((n,), C0, dtype=DT))
    # the degree-1 band is (-y, z, -x) times sqrt(3 / 4 pi), as in 3DGS
    c1 = math.sqrt(3 / (4 * math.pi))
    assert torch.allclose(Y[:, 1:4], c1 * torch.stack([-dirs[:, 1], dirs[:, 2], -dirs[:, 0]], 1))


def test_one_pixel_image():
    k = intrinsics(2.0, 2.0, 0.5, 0.5)
    params = random_scene(3, n=10, degree=2)
    params[0] = params[0] * torch.tensor([0.1, 0.1, 1.0], dtype=DT)
    result = render_both(params, width=1, height=1, k=k)
    assert result["cpu"][0].rgb.shape == (1, 1, 3)
    assert float(result["reference"][0].alpha.detach()[0, 0]) > 0.5
    assert_match(result)


def test_render_with_camera_and_gaussians():
    """render(): a world-space camera (OpenGL c2w) sees the same image as rasterize with its w2c."""
    eye, target = np.array([1.0, -2.0, 0.8]), np.array([0.0, 0.0, 0.3])
    cam = Camera(K, look_at(eye, target), W, H)
    params = random_scene(12, n=40, degree=3)
    params[2] = params[2][:, :1].expand(-1, 3)  # isotropic: orientation-free, frame-independent
    # move the scene from the identity camera's frame to the world frame of ``cam``
    c2w_cv = np.linalg.inv(cam.w2c)
    R, t = torch.tensor(c2w_cv[:3, :3]), torch.tensor(c2w_cv[:3, 3])
    means = params[0] @ R.T + t
    gs = Gaussians(means, *params[1:])
    assert gs.n == 40 and gs.sh_degree == 3
    back = Gaussians.from_arrays(gs.to_arrays(), dtype=DT)
    assert torch.allclose(back.means, gs.means, atol=1e-6)
    out = render(gs, cam, BG, backend="cpu")
    # the direction-dependent colour differs, so compare alpha and depth (view independent)
    ident = rasterize(*params, K, np.eye(4), W, H, BG, backend="cpu")
    assert float((out.alpha - ident.alpha).abs().max()) < 1e-4
    assert float((out.depth - ident.depth).abs().max()) < 1e-4
    assert float(ident.alpha.max()) > 0.9


def test_bad_shapes_are_rejected():
    params = random_scene(1, n=5)
    with pytest.raises(ValueError, match="quats"):
        rasterize(params[0], params[1][:, :3], *params[2:], K, np.eye(4), W, H)
    with pytest.raises(ValueError, match="SH coefficient count"):
        rasterize(*params[:4], torch.zeros(5, 5, 3, dtype=DT), K, np.eye(4), W, H)
    with pytest.raises(ValueError, match="image size"):
        rasterize(*params, K, np.eye(4), 0, H)


def test_device_and_backend_resolution():
    assert resolve_device("cpu") == torch.device("cpu")
    assert resolve_backend("auto", torch.device("cpu")) == "cpu"
    assert resolve_backend("reference", torch.device("cpu")) == "reference"
    with pytest.raises(ArtgsError):
        resolve_backend("nope", torch.device("cpu"))
    if not torch.cuda.is_available():
        with pytest.raises(ArtgsError, match="CUDA"):
            resolve_device("cuda")
        with pytest.raises(ArtgsError, match="gsplat"):
            resolve_backend("gsplat", torch.device("cpu"))


def test_rotation_matrix_is_orthonormal():
    R = quat_to_rotmat(torch.randn(20, 4, dtype=DT) * 3)
    assert torch.allclose(R @ R.transpose(1, 2), torch.eye(3, dtype=DT).expand(20, 3, 3), atol=1e-12)
    assert torch.allclose(torch.linalg.det(R), torch.ones(20, dtype=DT))


def test_projections_kept_between_renders_change_nothing(monkeypatch):
    """The CPU backend projects again only the Gaussians whose inputs changed since its last
    render of the camera (core/render/cpu/backend.py ``Projections``): renders and gradients
    must be bit-identical to those of a fresh backend, whatever moved, and the kept
    projections stay within their budget."""
    from artgs.core.render.cpu import backend

    def run(scenes, kept):
        """Per scene, its render's outputs (and gradients: every third has them)."""
        monkeypatch.setattr(backend, "PROJECTIONS", kept)
        out = []
        for i, params in enumerate(scenes):
            if i % 3 == 2:
                params = [p.clone().requires_grad_(True) for p in params]
                r = rasterize(*params, K, np.eye(4), W, H, BG, "cpu")
                (r.rgb.sum() + r.depth.sum() + r.alpha.sum()).backward()
                out.append(list(r) + [p.grad for p in params])
            else:
                with torch.no_grad():
                    out.append(list(rasterize(*params, K, np.eye(4), W, H, BG, "cpu")))
        return out

    base = random_scene(3, n=200, dtype=torch.float32)
    part = slice(20, 60)
    scenes = [base]
    for change in ("means", "means", "opacity", "colours", "scales", "rotation bits"):
        p = [t.clone() for t in scenes[-1]]     # one input of the part changes at a time
        if change == "means":
            p[0][part] += 0.02
        elif change == "opacity":
            p[3][part] -= 0.5
        elif change == "colours":
            p[4][part] *= 0.5
        elif change == "scales":
            p[2][part] += 0.1
        else:
            p[1] = p[1] * -1.0                  # the same rotations: only the bits differ
        scenes.append(p)
    kept = backend.Projections()
    again = run(scenes, kept)
    for i, scene in enumerate(scenes):          # each render alone, from a fresh backend
        fresh = run([scene] * (i % 3 + 1), backend.Projections())[-1]
        assert len(fresh) == len(again[i])
        for a, b in zip(fresh, again[i]):
            assert torch.equal(a, b), f"render {i} differs from a fresh backend's"
    assert len(kept.entries) == 1
    small = backend.Projections(budget=1)      # over budget: only the newest is kept
    run([base], small)
    monkeypatch.setattr(backend, "PROJECTIONS", small)
    with torch.no_grad():
        rasterize(*base, K, np.linalg.inv(look_at(np.array([0.0, 0.3, -1.0]), np.zeros(3))), W, H, BG,
                  "cpu")
    assert len(small.entries) == 1


def test_grad_rows_keep_their_gradients():
    """``grad_rows``: the listed Gaussians' gradients are those of a full backward (bit for
    bit), the others' are zero on the CPU backend."""
    base = random_scene(5, n=120, dtype=torch.float32)
    rows = torch.arange(10, 50)

    def grads(grad_rows):
        params = [p.clone().requires_grad_(True) for p in base]
        r = rasterize(*params, K, np.eye(4), W, H, BG, "cpu", grad_rows=grad_rows)
        (r.rgb.sum() + 2 * r.depth.sum() + r.alpha.sum()).backward()
        return [p.grad for p in params]

    full, some = grads(None), grads(rows)
    others = torch.ones(120, dtype=torch.bool)
    others[rows] = False
    for f, s in zip(full, some):
        assert torch.equal(f[rows], s[rows])
        assert f[others].abs().sum() > 0 and s[others].abs().sum() == 0
