"""Differentiable rendering of a Gaussian map from a pinhole camera: one API, three backends.

``render(gaussians, K, T_world_cam, width, height, background)`` returns colour, expected
depth and accumulated opacity images plus per-Gaussian statistics. The image model is
gsplat's "classic" 3DGS rasterization (see :mod:`dynactivegs.splat._common` for the exact
projection, culling and compositing rules) and all backends implement it:

- ``"cpu"``: the tiled numba rasterizer with a hand-written backward
  (:mod:`dynactivegs.splat._cpu`); the default without CUDA.
- ``"cuda"``: gsplat's ``rasterization`` (needs a CUDA device and the ``[cuda]`` extra).
- ``"reference"``: the plain torch twin (:mod:`dynactivegs.splat._reference`), for tests.
- ``"auto"``: ``"cuda"`` when a CUDA device is available and gsplat imports, else ``"cpu"``.

Outputs are differentiable with respect to every raw Gaussian parameter (and the
background colour); not with respect to the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import torch

from dynactivegs.errors import DagsError
from dynactivegs.splat._common import NEAR_PLANE, check_intrinsics, world_to_cam
from dynactivegs.splat.gaussians import Gaussians

Backend = Literal["auto", "cpu", "cuda", "reference"]


@dataclass(frozen=True, eq=False)
class RenderOut:
    """One rendered view. Images are (H, W[, 3]) in the Gaussians' dtype, on their device."""

    rgb: torch.Tensor          # (H, W, 3) sum_i w_i c_i + T * background
    depth: torch.Tensor        # (H, W) expected z-depth in m: sum_i w_i z_i / alpha (0 where alpha = 0)
    alpha: torch.Tensor        # (H, W) accumulated opacity 1 - T (silhouette), in [0, 1)
    radii: torch.Tensor        # (N, 2) int32 screen-box half-widths in px (x, y); 0: culled / not in view
    n_touched: torch.Tensor | None   # (N,) int32 pixels the Gaussian contributed to (w_i > 0); None on cuda
    weight_sum: torch.Tensor   # (N,) sum over pixels of its blending weight w_i (detached)
    backend: str               # the backend that rendered: "cpu", "cuda" or "reference"

    @property
    def visible(self) -> torch.Tensor:
        """(N,) bool: the Gaussian was projected into the view (not culled)."""
        return (self.radii > 0).all(dim=-1)


def gsplat_available() -> bool:
    """True when a CUDA device is usable and gsplat imports."""
    if not torch.cuda.is_available():
        return False
    try:
        import gsplat  # noqa: F401
    except Exception:
        return False
    return True


def resolve_backend(backend: Backend) -> str:
    """The concrete backend ``render`` will use for ``backend``; raises DagsError if unusable."""
    if backend == "auto":
        return "cuda" if gsplat_available() else "cpu"
    if backend == "cuda":
        if not torch.cuda.is_available():
            raise DagsError("render backend 'cuda' needs a CUDA device but none is available; use backend='cpu'")
        if not gsplat_available():
            raise DagsError("render backend 'cuda' needs gsplat; install it with `pip install dynactivegs[cuda]`")
        return "cuda"
    if backend in ("cpu", "reference"):
        return backend
    raise DagsError(f"unknown render backend {backend!r}; use 'auto', 'cpu', 'cuda' or 'reference'")


def render(
    gaussians: Gaussians,
    K: np.ndarray | torch.Tensor,
    T_world_cam: np.ndarray | torch.Tensor,
    width: int,
    height: int,
    background: torch.Tensor | tuple[float, float, float] | None = None,
    backend: Backend = "auto",
    *,
    near_plane: float = NEAR_PLANE,
) -> RenderOut:
    """Render ``gaussians`` seen by a pinhole camera.

    Args:
        gaussians: the map (N Gaussians, raw parameters).
        K: (3, 3) intrinsics; pixel (row v, col u) has its centre at (u + 0.5, v + 0.5).
        T_world_cam: (4, 4) rigid transform, camera points -> world points (OpenCV camera:
            x right, y down, z forward).
        width, height: image size in px.
        background: (3,) colour behind the Gaussians (default black); may require grad.
        backend: see the module docstring.
        near_plane: Gaussians whose camera z is below this (m) are culled.
    Returns:
        :class:`RenderOut`.
    """
    which = resolve_backend(backend)
    K64 = check_intrinsics(K, width, height)
    viewmat = world_to_cam(T_world_cam)
    dt, dev = gaussians.dtype, gaussians.device
    if background is None:
        bg = torch.zeros(3, dtype=dt, device=dev)
    else:
        bg = torch.as_tensor(background, dtype=dt, device=dev)
        if bg.shape != (3,):
            raise DagsError(f"background must be 3 values (RGB); got shape {tuple(bg.shape)}")
    assert near_plane > 0.0

    if which == "cuda":
        from dynactivegs.splat._gsplat import rasterize_gsplat

        rgb, depth, alpha, radii, n_touched, weight_sum = rasterize_gsplat(
            gaussians, bg, viewmat, K64, width, height, near_plane)
        return RenderOut(rgb, depth, alpha, radii, n_touched, weight_sum, which)

    if dev.type != "cpu":
        raise DagsError(f"render backend {which!r} needs the Gaussians on the CPU; they are on {dev}")
    if which == "cpu":
        from dynactivegs.splat._cpu import render_raw

        rgb, depth, alpha, radii, n_touched, weight_sum = render_raw(
            *gaussians.tensors(), bg, viewmat, K64, width, height, near_plane)
        return RenderOut(rgb, depth, alpha, radii, n_touched, weight_sum, which)

    from dynactivegs.splat._reference import rasterize

    rgb, depth_acc, alpha, radii, n_touched, weight_sum = rasterize(
        gaussians.means, gaussians.unit_quats, gaussians.scales, gaussians.opacities, gaussians.rgb,
        bg, viewmat, K64, width, height, near_plane)
    # expected depth, as gsplat's render_mode="RGB+ED": accumulated depth / accumulated opacity
    depth = depth_acc / alpha.clamp(min=1e-10)
    return RenderOut(rgb, depth, alpha, radii, n_touched, weight_sum.detach(), which)
