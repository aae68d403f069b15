"""The gradients drive learning: Adam on the fast backend fits a small Gaussian set to a target render."""

from __future__ import annotations

import torch

from dynactivegs.splat import Gaussians, render
from dynactivegs.splat.losses import depth_l1, l1
from tests.splat._splat_scenes import random_scene


def test_adam_fit_reduces_loss_tenfold():
    width, height = 32, 24
    gen = torch.Generator().manual_seed(11)
    target_g, K, T = random_scene(40, width, height, gen, dtype=torch.float32, adversarial=False)
    bg = (0.0, 0.0, 0.0)
    with torch.no_grad():
        target = render(target_g, K, T, width, height, bg, backend="cpu")

    # start: centres displaced by ~5 cm, grey, half transparent, 1.5x too large, random rotations
    init = Gaussians(
        means=target_g.means + 0.05 * torch.randn(40, 3, generator=gen),
        log_scales=target_g.log_scales + 0.4,
        quats=torch.randn(40, 4, generator=gen),
        opacity_logits=torch.zeros(40),
        sh0=torch.zeros(40, 3),
    ).requires_grad_()
    opt = torch.optim.Adam([
        {"params": [init.means], "lr": 2e-3},
        {"params": [init.log_scales, init.quats, init.opacity_logits], "lr": 2e-2},
        {"params": [init.sh0], "lr": 5e-2},
    ])

    def loss_of(out):
        return (l1(out.rgb, target.rgb) + 0.1 * depth_l1(out.depth, target.depth)
                + l1(out.alpha[..., None], target.alpha[..., None]))

    losses = []
    for _ in range(300):
        out = render(init, K, T, width, height, bg, backend="cpu")
        loss = loss_of(out)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    assert losses[-1] <= losses[0] / 10, f"loss {losses[0]:.4f} -> {losses[-1]:.4f}"
