"""The shared training pieces (core/train): losses, the plateau test and the loop."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch

from artgs.core.model.errors import Cancelled
from artgs.core.model.progress import Progress
from artgs.core.render.rasterize import RenderOutput
from artgs.core.train.evaluate import psnr, view_figures
from artgs.core.train.loop import Plateau, run_loop
from artgs.core.train.losses import LossWeights, alpha_l1, depth_l1, l1, view_loss
from artgs.core.train.views import View


def _view(h: int = 6, w: int = 8) -> View:
    g = torch.Generator().manual_seed(0)
    mask = torch.zeros(h, w)
    mask[1:5, 2:7] = 1
    rgb = torch.rand(h, w, 3, generator=g) * mask[..., None]
    depth = torch.where(mask > 0, torch.full((h, w), 2.0), torch.zeros(h, w))
    depth[1, 2] = 0   # one object pixel without a measurement
    return View(0, torch.eye(3), torch.eye(4), w, h, rgb, mask, depth,
                (mask > 0) & (depth > 0), int(mask.sum()))


def test_losses_against_hand_computed_values():
    v = _view()
    r = RenderOutput(v.rgb + 0.1 * v.mask[..., None], v.depth + 0.05 * (v.depth > 0),
                     0.5 * v.mask)
    # +0.1 on every channel of the 20 object pixels, per channel and object pixel
    assert float(l1(r.rgb, v.rgb, v.pixels)) == pytest.approx(0.1, rel=1e-5)
    assert float(depth_l1(r.depth, v.depth, v.depth_valid)) == pytest.approx(0.05, rel=1e-5)
    assert float(alpha_l1(r.alpha, v.mask)) == pytest.approx(0.5 * 20 / 48, rel=1e-5)
    w = LossWeights(ssim=0.0, depth=0.1, alpha=0.5)
    want = 0.1 + 0.1 / 0.01 * 0.05 + 0.5 * (0.5 * 20 / 48)
    assert float(view_loss(r, v, w, depth_unit=0.01)) == pytest.approx(want, rel=1e-5)
    perfect = RenderOutput(v.rgb, v.depth, v.mask)
    assert float(view_loss(perfect, v, LossWeights(), 0.01)) == pytest.approx(0.0, abs=1e-6)
    fig = view_figures(r, v)
    assert fig["psnr"] == pytest.approx(psnr(0.01), rel=1e-4) == pytest.approx(20.0, rel=1e-4)
    assert fig["depth_mm"] == pytest.approx(50.0, rel=1e-4)


def test_plateau_stops_when_the_window_mean_stops_falling():
    p = Plateau(window=10, tol=0.05, after=15)
    losses = [1.0] * 10 + [0.5] * 10 + [0.49] * 10 + [0.1] * 10
    stop = next(it for it, loss in enumerate(losses, 1) if p.add(it, loss))
    # window means 1.0 (it 10), 0.5 (it 20: halved), 0.49 (it 30: 2 % < 5 %, converged)
    assert stop == 30
    assert p.final_loss == pytest.approx(0.5)   # the last window that still improved
    early = Plateau(window=10, tol=0.05, after=35)
    assert next(it for it, loss in enumerate(losses + [0.1] * 10, 1) if early.add(it, loss)) == 50
    fixed = Plateau(window=10, tol=0.05, enabled=False)
    assert not any(fixed.add(it, loss) for it, loss in enumerate(losses, 1))
    assert fixed.final_loss == pytest.approx(0.1)


def test_run_loop_reports_stops_and_cancels():
    buf = io.StringIO()
    losses = iter(np.linspace(1.0, 0.5, 100))
    res = run_loop(lambda: float(next(losses)), 0, 60, Progress("json", stream=buf), "stage",
                   plateau=Plateau(20, 0.01, enabled=False), figures=lambda: {"psnr": 30.0})
    assert (res.iterations, res.stopped) == (60, "cap")
    events = [json.loads(line) for line in buf.getvalue().splitlines()]
    assert [e["fraction"] for e in events] == pytest.approx([25 / 60, 50 / 60, 1.0])
    assert all(e["figures"]["psnr"] == 30.0 and "loss" in e["figures"] for e in events)
    flat = run_loop(lambda: 1.0, 0, 1000, Progress("quiet"), "stage", plateau=Plateau(20, 0.01))
    assert (flat.iterations, flat.stopped, flat.final_loss) == (40, "converged", 1.0)
    calls = {"n": 0}

    def cancel() -> bool:
        calls["n"] += 1
        return calls["n"] > 5

    with pytest.raises(Cancelled):
        run_loop(lambda: 1.0, 0, 100, Progress("quiet", cancel=cancel), "stage",
                 plateau=Plateau(50, 0.0, enabled=False))


def test_robust_loss_follows_exposure_and_depth_noise():
    from artgs.core.train.losses import exposure_gain, robust_image_loss
    v = _view()
    v.rgb = (0.2 + 0.6 * v.rgb) * v.mask[..., None]          # no dark pixels
    perfect = RenderOutput(v.rgb.clone(), v.depth.clone(), v.mask.clone())
    # the frame 12 % brighter than the render: the gain is found and the colours then match
    bright = View(**{**v.__dict__, "rgb": v.rgb * 1.12})
    assert float(exposure_gain(perfect, bright)) == pytest.approx(1.12, rel=1e-4)
    plain = float(robust_image_loss(perfect, bright, depth_unit=0.01, lambda_ssim=0.0))
    fixed = float(robust_image_loss(perfect, bright, depth_unit=0.01, lambda_ssim=0.0,
                                    exposure=True))
    assert plain > 0.2 and fixed == pytest.approx(0.0, abs=1e-5)
    # a depth error of 5 cm: saturating at a 2 cm scale, L1-like at 3 x 5 cm of measured noise
    off = RenderOutput(v.rgb.clone(), v.depth + 0.05 * (v.depth > 0), v.mask.clone())
    quiet = float(robust_image_loss(off, v, depth_unit=0.01, lambda_ssim=0.0))
    noisy = View(**{**v.__dict__, "depth_noise": 0.05})
    loud = float(robust_image_loss(off, noisy, depth_unit=0.01, lambda_ssim=0.0, noise_sigmas=3.0))
    n = int(v.depth_valid.sum())
    assert quiet == pytest.approx(n * (2.5 / 3.5) / v.pixels, rel=1e-4)
    assert loud == pytest.approx(n * (1 / 3) / (4 / 3) / v.pixels, rel=1e-4)


def test_noise_sigma_measures_depth_noise():
    from artgs.core.geometry.noise import noise_sigma
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:60, 0:80]
    plane = 2.0 + 0.01 * xx + 0.005 * yy                      # a slanted smooth surface
    for sigma in (0.002, 0.03):
        maps = [plane + rng.normal(0, sigma, plane.shape) for _ in range(3)]
        assert noise_sigma(maps) == pytest.approx(sigma, rel=0.1)
    assert noise_sigma([np.zeros((10, 10))]) == 0.0
