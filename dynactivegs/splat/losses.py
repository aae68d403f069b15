"""Image and regularisation losses used by mapping (DESIGN.md §5, Mapping).

``L_render = (l1 * L_color + l2 * L_depth) / beta^2 + l3 * L_iso`` with
``L_color = 0.8 L1 + 0.2 (1 - SSIM)``. The per-pixel 1 / beta^2 weighting is the caller's:
every image loss takes an optional per-pixel ``weight`` (H, W) and returns the mean over
the pixels it counts of ``weight * error``; the ``*_map`` functions return the per-pixel
error itself. All are differentiable in their first argument.

Images are (H, W, 3) in [0, 1] (the layout of :class:`~dynactivegs.splat.render.RenderOut`),
depths (H, W) in metres with 0 meaning "no measurement".
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F


def _weighted_mean(err: torch.Tensor, weight: torch.Tensor | None, valid: torch.Tensor | None = None) -> torch.Tensor:
    """mean over valid pixels of weight * err; 0 (still differentiable) when no pixel is valid."""
    if weight is not None:
        assert weight.shape == err.shape, f"weight must be {tuple(err.shape)}; got {tuple(weight.shape)}"
        err = err * weight
    if valid is None:
        return err.mean()
    return (err * valid).sum() / valid.sum().clamp(min=1)


def l1_map(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(H, W) mean over channels of |pred - target| for (H, W, C) images."""
    assert pred.shape == target.shape and pred.dim() == 3, f"images must be (H, W, C); got {tuple(pred.shape)}"
    return (pred - target).abs().mean(dim=-1)


def l1(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Photometric L1: mean over pixels of weight * mean_c |pred - target|. Images (H, W, C)."""
    return _weighted_mean(l1_map(pred, target), weight)


def _gaussian_window(size: int, sigma: float, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    x = torch.arange(size, dtype=dtype, device=device) - (size - 1) / 2
    g = torch.exp(-(x * x) / (2 * sigma * sigma))
    g = g / g.sum()
    return g[:, None] * g[None, :]


def ssim_map(pred: torch.Tensor, target: torch.Tensor, *, window: int = 11, sigma: float = 1.5,
             padding: str = "same") -> torch.Tensor:
    """Per-pixel SSIM (Wang et al. 2004, eq. (13)), averaged over channels.

    Gaussian window ``window`` x ``window`` with std ``sigma`` px, C1 = 0.01^2, C2 = 0.03^2
    (dynamic range 1), as in 3DGS. ``padding="same"`` zero-pads like 3DGS's training loss
    and returns (H, W); ``"valid"`` returns (H - window + 1, W - window + 1).
    """
    assert pred.shape == target.shape and pred.dim() == 3, f"images must be (H, W, C); got {tuple(pred.shape)}"
    assert padding in ("same", "valid")
    c = pred.shape[-1]
    x = pred.permute(2, 0, 1)[None]
    y = target.permute(2, 0, 1)[None]
    win = _gaussian_window(window, sigma, pred.dtype, pred.device).expand(c, 1, window, window)
    pad = window // 2 if padding == "same" else 0

    def blur(t: torch.Tensor) -> torch.Tensor:
        return F.conv2d(t, win, padding=pad, groups=c)

    mu_x, mu_y = blur(x), blur(y)
    sxx = blur(x * x) - mu_x * mu_x
    syy = blur(y * y) - mu_y * mu_y
    sxy = blur(x * y) - mu_x * mu_y
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    s = ((2 * mu_x * mu_y + c1) * (2 * sxy + c2)) / ((mu_x * mu_x + mu_y * mu_y + c1) * (sxx + syy + c2))
    return s[0].mean(dim=0)


def ssim(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None = None) -> torch.Tensor:
    """Mean (weighted) SSIM of two (H, W, C) images; 1 for identical images."""
    return _weighted_mean(ssim_map(pred, target), weight)


def color_loss(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None = None,
               ssim_weight: float = 0.2) -> torch.Tensor:
    """L_color = (1 - ssim_weight) L1 + ssim_weight (1 - SSIM), per pixel, then the weighted mean."""
    per_pixel = (1 - ssim_weight) * l1_map(pred, target) + ssim_weight * (1 - ssim_map(pred, target))
    return _weighted_mean(per_pixel, weight)


def depth_l1(pred: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None = None,
             mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean of weight * |pred - target| (m) over pixels with a depth measurement (target > 0).

    pred, target: (H, W) z-depth in metres; mask: optional (H, W) bool restricting the pixels
    further (e.g. where the render is opaque). Returns 0 if no pixel is valid.
    """
    assert pred.shape == target.shape and pred.dim() == 2, f"depths must be (H, W); got {tuple(pred.shape)}"
    valid = (target > 0) & torch.isfinite(target)
    if mask is not None:
        assert mask.shape == target.shape and mask.dtype == torch.bool
        valid = valid & mask
    err = torch.where(valid, (pred - torch.where(valid, target, torch.zeros_like(target))).abs(),
                      torch.zeros_like(pred))
    return _weighted_mean(err, weight, valid.to(pred.dtype))


def isotropy(log_scales: torch.Tensor) -> torch.Tensor:
    """L_iso: mean over Gaussians and axes of |s - mean(s)|, s = exp(log_scales) in metres.

    Zero for spheres; discourages needle- and disc-shaped Gaussians that overfit the few views
    a robot gets (the regulariser of SplaTAM / Gaussian-SLAM). log_scales: (N, 3).
    """
    assert log_scales.dim() == 2 and log_scales.shape[1] == 3, "log_scales must be (N, 3)"
    if log_scales.shape[0] == 0:
        return log_scales.sum() * 0.0
    s = torch.exp(log_scales)
    return (s - s.mean(dim=1, keepdim=True)).abs().mean()


def psnr(pred: torch.Tensor, target: torch.Tensor) -> float:
    """Peak signal-to-noise ratio in dB for images in [0, 1] (not differentiable; for reports)."""
    mse = float(((pred.detach() - target.detach()) ** 2).mean())
    return float("inf") if mse == 0 else -10.0 * math.log10(mse)
