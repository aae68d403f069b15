"""Seeded random Gaussian scenes for the splat tests, including the degenerate cases."""

from __future__ import annotations

import math

import numpy as np
import torch

from dynactivegs.splat.gaussians import Gaussians, rgb_to_sh0


def camera(width: int, height: int, hfov_deg: float = 90.0) -> tuple[np.ndarray, np.ndarray]:
    """(K, T_world_cam): a pinhole camera looking along +y of a Z-up world from (0, -1, 0.5)."""
    f = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
    K = np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    # camera x = world x, camera y (down) = world -z, camera z (forward) = world y
    T = np.eye(4)
    T[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    T[:3, 3] = [0.0, -1.0, 0.5]
    return K, T


def cam_to_world(p_cam: torch.Tensor, T: np.ndarray) -> torch.Tensor:
    Tt = torch.as_tensor(T, dtype=p_cam.dtype)
    return p_cam @ Tt[:3, :3].T + Tt[:3, 3]


def random_scene(n: int, width: int, height: int, gen: torch.Generator, dtype=torch.float64,
                 *, adversarial: bool = True) -> tuple[Gaussians, np.ndarray, np.ndarray]:
    """N Gaussians mostly in view of ``camera(width, height)``.

    With ``adversarial``, about a tenth each are: behind or at the camera, at or past the
    image border, very thin (one axis 1e-4 of the others), nearly transparent (opacity just
    above and below 1/255), huge (covering many tiles), and a tight cluster of opaque
    Gaussians at one spot (many overlaps, early termination).
    """
    K, T = camera(width, height)
    f = float(K[0, 0])
    u = torch.rand(n, generator=gen, dtype=dtype) * width
    v = torch.rand(n, generator=gen, dtype=dtype) * height
    z = 0.5 + 4.0 * torch.rand(n, generator=gen, dtype=dtype)
    scale_px = 0.3 + 1.7 * torch.rand(n, 3, generator=gen, dtype=dtype)   # std dev on screen, px
    opacity = 0.05 + 0.9 * torch.rand(n, generator=gen, dtype=dtype)
    if adversarial:
        k = max(1, n // 10)
        idx = torch.randperm(n, generator=gen)
        groups = [idx[i * k:(i + 1) * k] for i in range(7)]
        z[groups[0]] = -2.0 + 2.02 * torch.rand(k, generator=gen, dtype=dtype)    # behind / at the camera
        border = groups[1]
        u[border] = torch.where(torch.rand(k, generator=gen) < 0.5, -3.0, width + 3.0) \
            + 6.0 * torch.rand(k, generator=gen, dtype=dtype) - 3.0
        thin = groups[2]
        axis = torch.randint(0, 3, (k,), generator=gen)
        scale_px[thin, axis] = scale_px[thin, axis] * 1e-4
        faint = groups[3]
        opacity[faint] = (1.0 / 255.0) * (0.5 + torch.rand(k, generator=gen, dtype=dtype))
        huge = groups[4]
        scale_px[huge] = scale_px[huge] * 8.0
        opacity[huge] = opacity[huge] * 0.3
        cluster = groups[5]
        u[cluster] = width * 0.3 + torch.randn(k, generator=gen, dtype=dtype)
        v[cluster] = height * 0.6 + torch.randn(k, generator=gen, dtype=dtype)
        z[cluster] = 2.0 + 0.05 * torch.rand(k, generator=gen, dtype=dtype)
        opacity[cluster] = 0.9 + 0.09 * torch.rand(k, generator=gen, dtype=dtype)
        near = groups[6]
        z[near] = 0.05 + 0.1 * torch.rand(k, generator=gen, dtype=dtype)          # close to the camera
    scale = scale_px * torch.abs(z).clamp_min(0.01)[:, None] / f
    x_cam = (u - K[0, 2]) / f * z
    y_cam = (v - K[1, 2]) / f * z
    means = cam_to_world(torch.stack([x_cam, y_cam, z], dim=-1), T)
    quats = torch.randn(n, 4, generator=gen, dtype=dtype)
    rgb = torch.rand(n, 3, generator=gen, dtype=dtype)
    g = Gaussians(means=means, log_scales=torch.log(scale), quats=quats,
                  opacity_logits=torch.logit(opacity), sh0=rgb_to_sh0(rgb))
    return g, K, T
