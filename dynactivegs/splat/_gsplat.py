"""CUDA backend: gsplat's ``rasterization`` with the conventions of :mod:`dynactivegs.splat._common`.

gsplat is optional (``pip install dynactivegs[cuda]``) and imported only here, when
``render(..., backend="cuda")`` (or ``"auto"`` on a CUDA machine) runs. Conventions mapped:

- gsplat wants ``viewmats`` = world -> camera (our ``T_world_cam`` inverted) and ``Ks`` with
  pixel centres at +0.5, batched over cameras (a leading axis of 1 here);
- activated parameters: scales = exp(log_scales), opacities = sigmoid(logits), colours =
  max(C0 sh0 + 0.5, 0) passed as post-activation RGB (``sh_degree=None``); gsplat normalises
  the quaternions itself;
- ``render_mode="RGB+ED"`` gives the expected depth sum_i w_i z_i / alpha as a 4th channel
  (background 0 there); ``rasterize_mode="classic"``, ``eps2d=0.3``, 16 px tiles;
- gsplat computes in float32: a float64 map is rendered in float32 and the outputs are cast
  back; gradients flow through the casts and the device transfer.

gsplat does not report per-Gaussian pixel counts, so ``n_touched`` is None on this backend;
``weight_sum`` (sum over pixels of each Gaussian's blending weight) is the gradient of the
summed render of a zero "colour" channel with respect to that channel, one extra
forward+backward on the GPU.
"""

from __future__ import annotations

import numpy as np
import torch

from dynactivegs.splat._common import EPS2D, TILE
from dynactivegs.splat.gaussians import Gaussians


def _radii_n2(radii: torch.Tensor, n: int) -> torch.Tensor:
    """gsplat >= 1.5 returns (1, N, 2) per-axis radii, older versions (1, N): give (N, 2) int32."""
    r = radii.reshape(n, -1)
    if r.shape[1] == 1:
        r = r.expand(n, 2)
    return r.to(torch.int32)


def rasterize_gsplat(gaussians: Gaussians, background: torch.Tensor, viewmat: np.ndarray, K: np.ndarray,
                     width: int, height: int, near_plane: float
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, None, torch.Tensor]:
    """(rgb (H, W, 3), expected depth (H, W), alpha (H, W), radii (N, 2), None, weight_sum (N,)).

    Outputs are in the Gaussians' dtype and on their device.
    """
    from gsplat import rasterization

    out_dtype, out_device = gaussians.dtype, gaussians.device
    dev = out_device if out_device.type == "cuda" else torch.device("cuda")
    g = gaussians.to(dtype=torch.float32, device=dev)
    n = len(g)
    viewmats = torch.as_tensor(viewmat, dtype=torch.float32, device=dev)[None]
    Ks = torch.as_tensor(K, dtype=torch.float32, device=dev)[None]
    common = dict(viewmats=viewmats, Ks=Ks, width=width, height=height, near_plane=near_plane, eps2d=EPS2D,
                  packed=False, tile_size=TILE, rasterize_mode="classic")
    colors, alphas, meta = rasterization(
        g.means, g.unit_quats, g.scales, g.opacities, g.rgb,
        backgrounds=background.to(dtype=torch.float32, device=dev)[None], render_mode="RGB+ED", **common)
    rgb = colors[0, :, :, :3]
    depth = colors[0, :, :, 3]
    alpha = alphas[0, :, :, 0]
    radii = _radii_n2(meta["radii"], n)

    # weight_sum: d(sum of the rendered channel) / d(channel value of Gaussian i) = sum_p w_ip
    with torch.enable_grad():
        probe = torch.zeros(n, 1, dtype=torch.float32, device=dev, requires_grad=True)
        d = g.detach()
        channel, _, _ = rasterization(d.means, d.unit_quats, d.scales, d.opacities, probe, **common)
        (weight_sum,) = torch.autograd.grad(channel.sum(), probe)

    def back(t: torch.Tensor) -> torch.Tensor:
        return t.to(dtype=out_dtype, device=out_device)

    return (back(rgb), back(depth), back(alpha), radii.to(out_device), None, back(weight_sum[:, 0]))
