"""Pure-torch twin of the rasterizer: plainly written, autograd does the backward.

Used by the tests (the fast backend must agree with it on values and gradients) and as the
speed baseline of ``benchmarks/bench_splat.py``. It implements exactly the model of
:mod:`dynactivegs.splat._common`: same projection, culling, screen boxes, tile binning,
depth order and compositing thresholds. It loops over 16 x 16 tiles in Python and
composites each tile densely ((pixels, Gaussians in tile) tensors), so its memory grows
with the number of tile-Gaussian pairs; it is not meant for production use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from dynactivegs.splat._common import (
    ALPHA_MAX, ALPHA_MIN, EPS2D, EXTEND_MAX, FAR_PLANE, FOV_CLAMP, RADIUS_MAX, T_MIN, TILE,
)


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """(M, 4) unit quaternions w x y z -> (M, 3, 3) rotation matrices."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(-1, 3, 3)


@dataclass(frozen=True)
class Projected:
    """Screen-space Gaussians that survive culling (M of the N inputs)."""

    ids: torch.Tensor       # (M,) long, index into the N inputs
    means2d: torch.Tensor   # (M, 2) px, continuous image coordinates (pixel centres at +0.5)
    conics: torch.Tensor    # (M, 3) inverse 2D covariance (a, b, c) of [[a, b], [b, c]], 1/px^2
    depths: torch.Tensor    # (M,) camera z, m
    radii: torch.Tensor     # (N, 2) int32 screen-box half-widths in px; 0 where culled


def project(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, opacities: torch.Tensor,
            viewmat: np.ndarray, K: np.ndarray, width: int, height: int, near_plane: float) -> Projected:
    """EWA projection of N Gaussians (Zwicker et al. 2002, eq. (31)-(34)) with gsplat's culling.

    Args:
        means: (N, 3) world, m. quats: (N, 4) unit, w x y z. scales: (N, 3) std devs, m.
        opacities: (N,) in (0, 1). viewmat: (4, 4) world -> camera. K: (3, 3) intrinsics.
    """
    n = means.shape[0]
    dt = means.dtype
    R = torch.as_tensor(viewmat[:3, :3], dtype=dt)
    t = torch.as_tensor(viewmat[:3, 3], dtype=dt)
    fx, fy, cx, cy = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))

    # near/far culling first, so that nothing below divides by a small or negative z
    with torch.no_grad():
        z_all = means @ R[2] + t[2]
        front = ((z_all >= near_plane) & (z_all <= FAR_PLANE)).nonzero()[:, 0]
    mean_c = means[front] @ R.T + t                                    # (F, 3) camera frame
    rot = quat_to_rotmat(quats[front])
    M = rot * scales[front][:, None, :]                                # R_q S
    cov_c = R @ (M @ M.transpose(1, 2)) @ R.T                          # W Sigma W^T

    x, y, z = mean_c.unbind(-1)
    tan_x, tan_y = 0.5 * width / fx, 0.5 * height / fy
    tx = z * (x / z).clamp(-(cx / fx + FOV_CLAMP * tan_x), (width - cx) / fx + FOV_CLAMP * tan_x)
    ty = z * (y / z).clamp(-(cy / fy + FOV_CLAMP * tan_y), (height - cy) / fy + FOV_CLAMP * tan_y)
    zero = torch.zeros_like(z)
    J = torch.stack([fx / z, zero, -fx * tx / (z * z),
                     zero, fy / z, -fy * ty / (z * z)], dim=-1).reshape(-1, 2, 3)
    cov2d = J @ cov_c @ J.transpose(1, 2)
    a = cov2d[:, 0, 0] + EPS2D
    b = cov2d[:, 0, 1]
    c = cov2d[:, 1, 1] + EPS2D
    det = a * c - b * b
    means2d = torch.stack([fx * x / z + cx, fy * y / z + cy], dim=-1)

    with torch.no_grad():
        o = opacities[front]
        extend = torch.sqrt(2.0 * torch.log(torch.clamp_min(o / ALPHA_MIN, 1.0))).clamp(max=EXTEND_MAX)
        rx = torch.ceil((extend * torch.sqrt(a)).clamp(max=RADIUS_MAX))
        ry = torch.ceil((extend * torch.sqrt(c)).clamp(max=RADIUS_MAX))
        mx, my = means2d[:, 0], means2d[:, 1]
        keep = ((det > 0) & (o >= ALPHA_MIN) & ~((rx <= 0) & (ry <= 0))
                & (mx + rx > 0) & (mx - rx < width) & (my + ry > 0) & (my - ry < height))
        sel = keep.nonzero()[:, 0]
        radii = torch.zeros(n, 2, dtype=torch.int32)
        radii[front[sel], 0] = rx[sel].to(torch.int32)
        radii[front[sel], 1] = ry[sel].to(torch.int32)

    det_k = det[sel]
    conics = torch.stack([c[sel] / det_k, -b[sel] / det_k, a[sel] / det_k], dim=-1)
    return Projected(ids=front[sel], means2d=means2d[sel], conics=conics, depths=z[sel], radii=radii)


def tile_ranges(means2d: torch.Tensor, radii: torch.Tensor, width: int, height: int
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Tiles overlapped by each screen box: [x0, x1) x [y0, y1) in tile units (gsplat's isect_tiles).

    means2d: (M, 2) px; radii: (M, 2) px (float). Returns four (M,) long tensors.
    """
    tw, th = math.ceil(width / TILE), math.ceil(height / TILE)
    m = means2d.detach()
    x0 = torch.floor(m[:, 0] / TILE - radii[:, 0] / TILE).clamp(0, tw).long()
    x1 = torch.ceil(m[:, 0] / TILE + radii[:, 0] / TILE).clamp(0, tw).long()
    y0 = torch.floor(m[:, 1] / TILE - radii[:, 1] / TILE).clamp(0, th).long()
    y1 = torch.ceil(m[:, 1] / TILE + radii[:, 1] / TILE).clamp(0, th).long()
    return x0, x1, y0, y1


def rasterize(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, opacities: torch.Tensor,
              colors: torch.Tensor, background: torch.Tensor, viewmat: np.ndarray, K: np.ndarray,
              width: int, height: int, near_plane: float
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Render N activated Gaussians; every output is differentiable by autograd where it is a float.

    Args:
        means (N, 3) m, quats (N, 4) unit, scales (N, 3) m, opacities (N,), colors (N, 3),
        background (3,), viewmat (4, 4) world -> camera, K (3, 3).
    Returns:
        rgb (H, W, 3) = sum_i w_i c_i + T bg; depth_acc (H, W) = sum_i w_i z_i (m, not yet
        divided by alpha); alpha (H, W) = 1 - T; radii (N, 2) int32; n_touched (N,) int32
        pixels with w_i > 0; weight_sum (N,) sum over pixels of w_i (detached). Here
        w_i = alpha_i prod_{j<i} (1 - alpha_j) and T the final transmittance.
    """
    n = means.shape[0]
    dt = means.dtype
    proj = project(means, quats, scales, opacities, viewmat, K, width, height, near_plane)
    ids = proj.ids
    opac = opacities[ids]
    col = colors[ids]
    rad = proj.radii[ids].to(dt)
    x0, x1, y0, y1 = tile_ranges(proj.means2d, rad, width, height)
    tw, th = math.ceil(width / TILE), math.ceil(height / TILE)
    n_touched = torch.zeros(n, dtype=torch.int32)
    weight_sum = torch.zeros(n, dtype=dt)

    rows_rgb, rows_depth, rows_alpha = [], [], []
    for ty in range(th):
        tiles_rgb, tiles_depth, tiles_alpha = [], [], []
        v = torch.arange(ty * TILE, min(height, ty * TILE + TILE), dtype=dt)
        for tx in range(tw):
            u = torch.arange(tx * TILE, min(width, tx * TILE + TILE), dtype=dt)
            py, px = torch.meshgrid(v + 0.5, u + 0.5, indexing="ij")
            px, py = px.reshape(-1), py.reshape(-1)                    # (P,) pixel centres
            in_tile = ((x0 <= tx) & (tx < x1) & (y0 <= ty) & (ty < y1)).nonzero()[:, 0]
            order = torch.argsort(proj.depths.detach()[in_tile], stable=True)
            k = in_tile[order]                                         # front to back
            dx = proj.means2d[k, 0][None, :] - px[:, None]             # (P, K)
            dy = proj.means2d[k, 1][None, :] - py[:, None]
            A, B, C = proj.conics[k].unbind(-1)
            sigma = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
            alpha = torch.clamp(opac[k] * torch.exp(-sigma), max=ALPHA_MAX)
            alpha = torch.where((sigma >= 0) & (alpha >= ALPHA_MIN), alpha, torch.zeros_like(alpha))
            with torch.no_grad():
                still_going = torch.cumprod(1 - alpha, dim=1) > T_MIN  # early stop, exclusive
            alpha = alpha * still_going
            T_after = torch.cumprod(1 - alpha, dim=1)
            T_before = torch.cat([torch.ones_like(T_after[:, :1]), T_after[:, :-1]], dim=1)
            w = alpha * T_before                                       # (P, K) blending weights
            T_final = T_after[:, -1] if k.numel() else torch.ones_like(px)
            shape = (len(v), len(u))
            tiles_rgb.append((w @ col[k] + T_final[:, None] * background).reshape(*shape, 3))
            tiles_depth.append((w @ proj.depths[k]).reshape(shape))
            tiles_alpha.append((1 - T_final).reshape(shape))
            with torch.no_grad():
                n_touched.index_add_(0, ids[k], (w > 0).sum(0).to(torch.int32))
                weight_sum.index_add_(0, ids[k], w.sum(0))
        rows_rgb.append(torch.cat(tiles_rgb, dim=1))
        rows_depth.append(torch.cat(tiles_depth, dim=1))
        rows_alpha.append(torch.cat(tiles_alpha, dim=1))
    return (torch.cat(rows_rgb, 0), torch.cat(rows_depth, 0), torch.cat(rows_alpha, 0),
            proj.radii, n_touched, weight_sum)

