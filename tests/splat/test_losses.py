"""Image losses: values on known inputs, masking, weighting, gradients."""

from __future__ import annotations

import kornia
import pytest
import torch

from dynactivegs.splat.losses import color_loss, depth_l1, isotropy, l1, psnr, ssim, ssim_map


def _images(seed: int = 0, noise: float = 0.1):
    gen = torch.Generator().manual_seed(seed)
    a = torch.rand(30, 40, 3, generator=gen, dtype=torch.float64)
    b = (a + noise * torch.randn(30, 40, 3, generator=gen, dtype=torch.float64)).clamp(0, 1)
    return a, b


def test_l1_and_weights():
    a = torch.zeros(2, 2, 3)
    b = torch.ones(2, 2, 3)
    b[0, 0] = 0.0
    assert float(l1(a, b)) == pytest.approx(0.75)
    w = torch.tensor([[4.0, 0.0], [0.0, 0.0]])
    assert float(l1(a, b, weight=w)) == 0.0
    w = torch.tensor([[0.0, 4.0], [0.0, 0.0]])
    assert float(l1(a, b, weight=w)) == pytest.approx(1.0)


def test_ssim_is_one_for_equal_images_and_matches_kornia():
    a, b = _images()
    assert float(ssim(a, a)) == pytest.approx(1.0, abs=1e-12)
    assert float(ssim(a, b)) < 0.97
    ours = ssim_map(a, b, padding="valid")
    theirs = kornia.metrics.ssim(a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None], 11, padding="valid")
    assert torch.allclose(ours, theirs[0].mean(0), atol=1e-9)
    assert ssim_map(a, b).shape == (30, 40)


def test_ssim_and_color_loss_are_differentiable_and_fall_towards_the_target():
    a, b = _images(1)
    x = b.clone().requires_grad_()
    loss = color_loss(x, a)
    loss.backward()
    with torch.no_grad():
        stepped = x - 0.01 * x.grad / x.grad.abs().max()
    assert float(color_loss(stepped, a)) < float(loss.detach())
    assert torch.autograd.gradcheck(lambda t: ssim(t, a[:12, :12]), (b[:12, :12].clone().requires_grad_(),))


def test_depth_l1_counts_only_valid_depths():
    pred = torch.full((2, 3), 2.0, requires_grad=True)
    target = torch.tensor([[1.0, 0.0, 3.0], [0.0, 0.0, 2.5]])
    loss = depth_l1(pred, target)
    assert float(loss.detach()) == pytest.approx((1.0 + 1.0 + 0.5) / 3)
    loss.backward()
    assert pred.grad[0, 1] == 0 and pred.grad[1, 0] == 0
    mask = torch.tensor([[True, True, False], [True, True, True]])
    assert float(depth_l1(pred, target, mask=mask).detach()) == pytest.approx((1.0 + 0.5) / 2)
    none = depth_l1(pred, torch.zeros(2, 3))
    assert float(none.detach()) == 0.0 and none.requires_grad


def test_isotropy_is_zero_for_spheres_and_grows_with_anisotropy():
    sphere = torch.log(torch.full((4, 3), 0.1))
    assert float(isotropy(sphere)) == pytest.approx(0.0, abs=1e-9)
    disc = torch.log(torch.tensor([[0.1, 0.1, 0.001]]))
    needle = torch.log(torch.tensor([[1.0, 0.01, 0.01]]))
    assert 0 < float(isotropy(disc)) < float(isotropy(needle))
    x = needle.clone().requires_grad_()
    isotropy(x).backward()
    assert x.grad[0, 0] > 0 and x.grad[0, 1] < 0     # shrinks the long axis, grows the short ones


def test_psnr():
    a = torch.zeros(4, 4, 3)
    assert psnr(a, a) == float("inf")
    assert psnr(a, a + 0.1) == pytest.approx(20.0)
