"""Constants and camera helpers shared by every rasterizer backend.

The constants are gsplat's (``rasterization(..., rasterize_mode="classic")``, gsplat >= 1.5)
so that the CPU backends and gsplat on CUDA render the same image:

- EWA splatting (Zwicker et al. 2002, "EWA Splatting", eq. (31)-(34)): the camera-frame
  covariance is projected with the Jacobian of the pinhole map at the Gaussian's mean,
  ``cov2d = J W Sigma W^T J^T``, and a low-pass filter of ``EPS2D`` px^2 is added to its
  diagonal (the 0.3 of 3DGS, Kerbl et al. 2023, sec. 4).
- The Jacobian uses the mean's x/z, y/z clamped to 1.3x the field of view, as 3DGS does, so
  that Gaussians far outside the image do not get huge footprints.
- A Gaussian is culled when its camera z is below ``NEAR_PLANE`` (or above ``FAR_PLANE``),
  its peak opacity is below ``ALPHA_MIN``, its 2D covariance is not positive definite, or
  its screen box misses the image (non-finite values fail these tests and are culled too).
- Its screen box has half-widths ``ceil(extend * sqrt(cov2d_ii))`` px with
  ``extend = min(EXTEND_MAX, sqrt(2 ln(opacity / ALPHA_MIN)))``: the opacity-aware bound of
  Radl et al. 2024 (StopThePop, app. B.2), which contains every pixel where the Gaussian's
  alpha reaches ``ALPHA_MIN``. It is binned into the 16 x 16 px tiles the box overlaps.
- Compositing is front to back in order of camera z (ties: lower index first), per pixel:
  ``alpha = min(ALPHA_MAX, o * exp(-0.5 d^T cov2d^-1 d))`` with ``d`` from the pixel centre
  to the mean; terms with ``alpha < ALPHA_MIN`` are skipped; the pixel stops, without
  the current term, as soon as its transmittance would fall to ``T_MIN`` or below.
"""

from __future__ import annotations

import numpy as np
import torch

from dynactivegs.errors import DagsError

TILE = 16                 # tile edge, px
NEAR_PLANE = 0.01         # m; Gaussians with camera z below are culled
FAR_PLANE = 1e10          # m
EPS2D = 0.3               # px^2 low-pass added to the 2D covariance diagonal
ALPHA_MIN = 1.0 / 255.0   # terms below this alpha are skipped
ALPHA_MAX = 0.999         # alpha clamp (gsplat's; INRIA's 3DGS uses 0.99)
T_MIN = 1e-4              # a pixel stops once its transmittance would reach this
EXTEND_MAX = 3.33         # max screen-box half-width in standard deviations
FOV_CLAMP = 0.3           # Jacobian uses x/z clamped to (1 + FOV_CLAMP) x the half field of view
RADIUS_MAX = 2.0 ** 30    # px; screen-box half-widths are capped so that they fit in int32


def world_to_cam(T_world_cam: np.ndarray | torch.Tensor) -> np.ndarray:
    """(4, 4) float64 rigid inverse of ``T_world_cam``: world points -> camera points (gsplat's viewmat)."""
    T = np.asarray(T_world_cam.detach().cpu() if isinstance(T_world_cam, torch.Tensor) else T_world_cam,
                   dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise DagsError(f"T_world_cam must be a finite 4x4 matrix; got shape {T.shape}")
    R = T[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or abs(np.linalg.det(R) - 1.0) > 1e-5:
        raise DagsError("T_world_cam must be a rigid transform (its 3x3 block a rotation)")
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def check_intrinsics(K: np.ndarray | torch.Tensor, width: int, height: int) -> np.ndarray:
    """(3, 3) float64 pinhole intrinsics, checked: fx, fy > 0, no skew, image size >= 1."""
    K = np.asarray(K.detach().cpu() if isinstance(K, torch.Tensor) else K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise DagsError(f"K must be a finite 3x3 matrix; got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0 or K[0, 1] != 0 or np.any(K[2] != [0, 0, 1]):
        raise DagsError("K must be pinhole intrinsics [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    if width < 1 or height < 1:
        raise DagsError(f"image size must be positive; got {width} x {height}")
    return K
