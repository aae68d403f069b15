"""The Gaussian map: raw parameters, their activations, creation from RGB-D, concat and prune.

Raw parameters are what the optimiser sees; activations turn them into the quantities the
rasterizer uses. The parametrisation is the one of 3DGS (Kerbl et al. 2023) and of its
``.ply`` files, so that a map exports to, and imports from, the INRIA layout without any
conversion of stored values (see :mod:`dynactivegs.splat.ply`):

================  ========  ===============================================  ==============
field             shape     activation (what the rasterizer uses)            .ply fields
================  ========  ===============================================  ==============
``means``         (N, 3)    none: world position in metres                   x y z
``log_scales``    (N, 3)    ``exp``: standard deviations along the local     scale_0..2
                            axes, metres
``quats``         (N, 4)    ``q / |q|``: unit quaternion, w x y z order,     rot_0..3
                            local -> world rotation
``opacity_logits`` (N,)     ``sigmoid``: peak opacity in (0, 1)              opacity
``sh0``           (N, 3)    ``max(C0 * sh0 + 0.5, 0)``: linear RGB, 0..1     f_dc_0..2
                            (degree-0 spherical harmonic, C0 = 0.2821)
================  ========  ===============================================  ==============

Colour is therefore stored *raw with a clamp* at 0 (no upper clamp), exactly as INRIA's
rasterizer and gsplat evaluate SH degree 0; it is view-independent (no higher SH bands).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

SH_C0 = 0.28209479177387814
"""Degree-0 real spherical harmonic, 1 / (2 sqrt(pi)): rgb = SH_C0 * sh0 + 0.5."""


def rgb_to_sh0(rgb: torch.Tensor) -> torch.Tensor:
    """Inverse of the colour activation on [0, 1]: sh0 = (rgb - 0.5) / C0."""
    return (rgb - 0.5) / SH_C0


def sh0_to_rgb(sh0: torch.Tensor) -> torch.Tensor:
    """Colour activation: rgb = max(C0 * sh0 + 0.5, 0) (INRIA / gsplat convention for SH degree 0)."""
    return torch.clamp_min(SH_C0 * sh0 + 0.5, 0.0)


@dataclass(frozen=True, eq=False)
class Gaussians:
    """A set of N 3D Gaussians as raw (pre-activation) parameters, all on one device and dtype.

    The container is frozen (fields cannot be reassigned) but the tensors are ordinary
    tensors: an optimiser may hold them as leaf tensors with ``requires_grad`` and update
    them in place. Operations that change N (:meth:`cat`, :meth:`masked`) return a new set.
    """

    means: torch.Tensor           # (N, 3) world position, metres
    log_scales: torch.Tensor      # (N, 3) log standard deviation per local axis, log metres
    quats: torch.Tensor           # (N, 4) rotation local -> world, w x y z, not necessarily unit
    opacity_logits: torch.Tensor  # (N,)   logit of the peak opacity
    sh0: torch.Tensor             # (N, 3) degree-0 SH colour coefficient (INRIA f_dc)

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        assert self.means.shape == (n, 3), f"means must be (N, 3); got {tuple(self.means.shape)}"
        assert self.log_scales.shape == (n, 3), f"log_scales must be (N, 3); got {tuple(self.log_scales.shape)}"
        assert self.quats.shape == (n, 4), f"quats must be (N, 4); got {tuple(self.quats.shape)}"
        assert self.opacity_logits.shape == (n,), f"opacity_logits must be (N,); got {tuple(self.opacity_logits.shape)}"
        assert self.sh0.shape == (n, 3), f"sh0 must be (N, 3); got {tuple(self.sh0.shape)}"
        dtypes = {t.dtype for t in self.tensors()}
        devices = {t.device for t in self.tensors()}
        assert len(dtypes) == 1 and len(devices) == 1, "all Gaussian parameters must share dtype and device"
        assert self.means.dtype.is_floating_point, "Gaussian parameters must be floating point"

    # ------------------------------------------------------------------ basics
    def tensors(self) -> tuple[torch.Tensor, ...]:
        """The raw parameters in field order (means, log_scales, quats, opacity_logits, sh0)."""
        return tuple(getattr(self, f.name) for f in fields(self))

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def dtype(self) -> torch.dtype:
        return self.means.dtype

    @property
    def device(self) -> torch.device:
        return self.means.device

    # ------------------------------------------------------------- activations
    @property
    def scales(self) -> torch.Tensor:
        """(N, 3) standard deviations along the local axes, metres: exp(log_scales)."""
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        """(N,) peak opacities in (0, 1): sigmoid(opacity_logits)."""
        return torch.sigmoid(self.opacity_logits)

    @property
    def unit_quats(self) -> torch.Tensor:
        """(N, 4) unit quaternions (w x y z): quats / |quats|."""
        return self.quats / self.quats.norm(dim=-1, keepdim=True)

    @property
    def rgb(self) -> torch.Tensor:
        """(N, 3) linear RGB colours, >= 0 (1 is full intensity): max(C0 * sh0 + 0.5, 0)."""
        return sh0_to_rgb(self.sh0)

    # --------------------------------------------------------------- creation
    @staticmethod
    def from_params(
        means: torch.Tensor,
        scales: torch.Tensor,
        quats: torch.Tensor,
        opacities: torch.Tensor,
        rgb: torch.Tensor,
    ) -> Gaussians:
        """Build raw parameters from activated values (scales in metres, opacities in (0, 1), rgb in [0, 1])."""
        return Gaussians(
            means=means,
            log_scales=torch.log(scales),
            quats=quats,
            opacity_logits=torch.logit(opacities),
            sh0=rgb_to_sh0(rgb),
        )

    @staticmethod
    def empty(dtype: torch.dtype = torch.float32, device: torch.device | str = "cpu") -> Gaussians:
        """A set with N = 0."""
        z = lambda *s: torch.zeros(s, dtype=dtype, device=device)  # noqa: E731
        return Gaussians(z(0, 3), z(0, 3), z(0, 4), z(0), z(0, 3))

    @staticmethod
    def from_rgbd(
        rgb: np.ndarray,
        depth_m: np.ndarray,
        K: np.ndarray,
        T_world_cam: np.ndarray,
        *,
        mask: np.ndarray | None = None,
        stride: int = 1,
        opacity: float = 0.5,
        scale_factor: float = 1.0,
        dtype: torch.dtype = torch.float32,
    ) -> Gaussians:
        """One isotropic Gaussian per valid pixel, back-projected from an RGB-D frame.

        A pixel (row v, col u) with depth z > 0 (and ``mask`` True where given) becomes a
        Gaussian at its back-projected centre ``T_world_cam @ (z * K^-1 [u + 0.5, v + 0.5, 1])``
        with the pixel's colour, identity rotation, peak opacity ``opacity`` and standard
        deviation ``scale_factor * stride * z / fx`` metres: the footprint of one sampled
        pixel at that depth, so neighbouring Gaussians just overlap.

        Args:
            rgb: (H, W, 3) uint8 (0..255) or float in [0, 1].
            depth_m: (H, W) z-depth in metres; 0 (or non-finite) means no return.
            K: (3, 3) intrinsics, pixel centres at +0.5.
            T_world_cam: (4, 4) camera points -> world points.
            mask: optional (H, W) bool; only True pixels are used.
            stride: use every ``stride``-th pixel in both directions.
            opacity: initial peak opacity in (0, 1).
            scale_factor: multiplies the pixel-footprint standard deviation.
        Returns:
            Gaussians with N = number of selected pixels, on the CPU in ``dtype``.
        """
        h, w = depth_m.shape
        assert rgb.shape == (h, w, 3), f"rgb must be (H, W, 3) matching depth; got {rgb.shape}"
        assert K.shape == (3, 3) and T_world_cam.shape == (4, 4)
        assert stride >= 1 and 0.0 < opacity < 1.0 and scale_factor > 0.0
        sel = np.isfinite(depth_m) & (depth_m > 0)
        if mask is not None:
            assert mask.shape == (h, w) and mask.dtype == np.bool_
            sel &= mask
        sub = np.zeros((h, w), dtype=bool)
        sub[::stride, ::stride] = True
        v, u = np.nonzero(sel & sub)
        z = depth_m[v, u].astype(np.float64)
        fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        p_cam = np.stack([(u + 0.5 - cx) / fx * z, (v + 0.5 - cy) / fy * z, z], axis=-1)
        p_world = p_cam @ T_world_cam[:3, :3].T + T_world_cam[:3, 3]
        colour = rgb[v, u].astype(np.float64)
        if rgb.dtype == np.uint8:
            colour = colour / 255.0
        n = len(z)
        sigma = scale_factor * stride * z / fx
        t = lambda a: torch.as_tensor(a, dtype=dtype)  # noqa: E731
        quats = np.zeros((n, 4))
        quats[:, 0] = 1.0
        return Gaussians(
            means=t(p_world),
            log_scales=t(np.repeat(np.log(sigma)[:, None], 3, axis=1)),
            quats=t(quats),
            opacity_logits=t(np.full(n, math.log(opacity / (1.0 - opacity)))),
            sh0=t((colour - 0.5) / SH_C0),
        )

    # ---------------------------------------------------------- set operations
    @staticmethod
    def cat(parts: list[Gaussians] | tuple[Gaussians, ...]) -> Gaussians:
        """Concatenate sets (in order); all parts must share dtype and device."""
        assert len(parts) > 0, "Gaussians.cat needs at least one set"
        return Gaussians(*(torch.cat(ts, dim=0) for ts in zip(*(p.tensors() for p in parts))))

    def masked(self, keep: torch.Tensor) -> Gaussians:
        """The subset where ``keep`` (N,) bool is True, e.g. to prune transparent Gaussians."""
        assert keep.shape == (len(self),) and keep.dtype == torch.bool, "keep must be (N,) bool"
        return Gaussians(*(t[keep] for t in self.tensors()))

    def detach(self) -> Gaussians:
        """Copies of the parameters without autograd history."""
        return Gaussians(*(t.detach().clone() for t in self.tensors()))

    def requires_grad_(self, flag: bool = True) -> Gaussians:
        """Mark every raw parameter as a leaf requiring grad (in place); returns self."""
        for t in self.tensors():
            t.requires_grad_(flag)
        return self

    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> Gaussians:
        """The same set in another dtype and/or on another device."""
        return Gaussians(*(t.to(dtype=dtype, device=device) for t in self.tensors()))

    # ------------------------------------------------------------------- files
    def save_ply(self, path: str | Path) -> None:
        """Write the INRIA 3DGS ``.ply`` layout (see :func:`dynactivegs.splat.ply.write_ply`)."""
        from dynactivegs.splat.ply import write_ply

        write_ply(path, self)

    @staticmethod
    def load_ply(path: str | Path) -> Gaussians:
        """Read an INRIA 3DGS ``.ply`` (see :func:`dynactivegs.splat.ply.read_ply`)."""
        from dynactivegs.splat.ply import read_ply

        return read_ply(path)
