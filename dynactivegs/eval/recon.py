"""Reconstruction points from a Gaussian map, in two ways; the result says which was used.

- ``"centres"``: the centres of Gaussians whose peak opacity is above ``opacity_min``. Cheap
  (no rendering); blind to how far a Gaussian extends, so a few large Gaussians covering a
  wall give few points.
- ``"renders"``: the map is rendered at a set of views (by default the survey views: the
  fewest views of a free-space lattice x evenly spaced headings from which a perfect map
  shows nearly all the ground truth, :func:`dynactivegs.eval.geometry.survey`; a sparse
  fixed lattice would cap C.R. below 100 % for a perfect map) and each pixel whose accumulated opacity is
  above ``alpha_min`` is back-projected at its expected depth. This measures the surface the
  map shows, as a mesh extracted from rendered depth would. Expected depth blends the two
  sides of a depth edge into "flying" pixels between them; as in depth fusion, pixels that
  sit on a depth edge (:func:`depth_edge_mask`) are left out. Gaussians nearer to the camera
  than its minimum depth are not rendered, as the ground truth sees nothing that near: a
  survey view can stand where the robot never did, next to a wall, and a Gaussian of that
  wall a few centimetres from the lens would otherwise cover the whole image.

Both are voxel-downsampled (centroid per voxel, 1 cm by default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from dynactivegs.eval.geometry import voxel_downsample
from dynactivegs.splat.gaussians import Gaussians
from dynactivegs.splat.render import NEAR_PLANE, Backend, render


@dataclass(frozen=True)
class ReconPoints:
    """Points extracted from a Gaussian map."""

    points_m: np.ndarray          # float64 (N, 3), world frame, one per occupied voxel
    method: str                   # "centres" or "renders"
    description: str              # one line: how the points were extracted


def centre_points(gaussians: Gaussians, *, opacity_min: float = 0.5, voxel_m: float = 0.01) -> ReconPoints:
    """Centres of the Gaussians with peak opacity above ``opacity_min``, voxel-downsampled."""
    with torch.no_grad():
        keep = gaussians.opacities > opacity_min
        pts = gaussians.means[keep].detach().to("cpu", torch.float64).numpy()
    down = voxel_downsample(pts, voxel_m)
    return ReconPoints(down, "centres", f"centres of {len(pts)} of {len(gaussians)} Gaussians with opacity > "
                                        f"{opacity_min:g}, {voxel_m * 100:g} cm voxels")


def backproject_depth(depth_m: np.ndarray, mask: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
    """float64 (N, 3) world points of the pixels where ``mask`` (H, W) is True, at z-depth ``depth_m`` (H, W).

    Pixel (row v, col u) has its centre at (u + 0.5, v + 0.5), as everywhere in the project.
    """
    assert depth_m.shape == mask.shape and K.shape == (3, 3) and T_world_cam.shape == (4, 4)
    v, u = np.nonzero(mask)
    z = depth_m[v, u].astype(np.float64)
    p_cam = np.stack([(u + 0.5 - K[0, 2]) / K[0, 0] * z, (v + 0.5 - K[1, 2]) / K[1, 1] * z, z], axis=-1)
    return p_cam @ T_world_cam[:3, :3].T + T_world_cam[:3, 3]


def depth_edge_mask(depth_m: np.ndarray, valid: np.ndarray, jump_rel: float) -> np.ndarray:
    """bool (H, W): pixels on a depth edge, whose depth a blend of two surfaces may have made up.

    Along each image axis a pixel is smooth when both valid neighbours are within ``jump_rel`` x its
    depth, or when inverse depth is linear across the three pixels (as on any plane, however
    oblique) to within ``jump_rel / 4`` of its own. A pixel that is not smooth along both axes
    is on an edge. Pixels at the image border or next to an invalid pixel have no linearity
    test along that axis and must pass the jump test with the neighbour they have.
    """
    d = np.where(valid, depth_m.astype(np.float64), np.nan)
    inv = 1.0 / d
    edge = np.zeros(d.shape, bool)
    for axis in (0, 1):
        pad = [(0, 0), (0, 0)]
        pad[axis] = (1, 1)
        dp, ip = np.pad(d, pad, constant_values=np.nan), np.pad(inv, pad, constant_values=np.nan)
        sl = [slice(None), slice(None)]
        sl[axis] = slice(0, -2)
        prev_d, prev_i = dp[tuple(sl)], ip[tuple(sl)]
        sl[axis] = slice(2, None)
        next_d, next_i = dp[tuple(sl)], ip[tuple(sl)]
        with np.errstate(invalid="ignore"):
            jump = np.fmax(np.abs(prev_d - d), np.abs(next_d - d))
            near = ~(jump > jump_rel * d)                                          # NaN (no neighbour) is near
            linear = np.abs(prev_i + next_i - 2.0 * inv) <= 0.25 * jump_rel * inv  # NaN (a side missing) is not
        edge |= ~(near | linear)
    return edge & valid


def rendered_points(gaussians: Gaussians, poses: np.ndarray, K: np.ndarray, width: int, height: int, *,
                    alpha_min: float = 0.9, edge_jump_rel: float = 0.1, voxel_m: float = 0.01,
                    backend: Backend = "auto", near_plane: float = NEAR_PLANE, views_note: str = "") -> ReconPoints:
    """Back-projected depth of renders at ``poses`` (V, 4, 4) where the accumulated opacity exceeds ``alpha_min``,
    leaving out depth-edge pixels (:func:`depth_edge_mask` with ``edge_jump_rel``; 0 keeps every pixel).
    Gaussians nearer than ``near_plane`` (m) are not rendered: give the camera's minimum depth, the range
    below which the ground truth sees nothing either.
    ``views_note``: how the poses were chosen, for the description."""
    assert poses.ndim == 3 and poses.shape[1:] == (4, 4)
    parts = []
    if len(gaussians):
        with torch.no_grad():
            for T in poses:
                out = render(gaussians, K, T, width, height, backend=backend, near_plane=near_plane)
                depth = out.depth.detach().to("cpu", torch.float64).numpy()
                alpha = out.alpha.detach().to("cpu", torch.float64).numpy()
                keep = (alpha > alpha_min) & (depth > 0)
                if edge_jump_rel > 0:
                    keep &= ~depth_edge_mask(depth, keep, edge_jump_rel)
                parts.append(backproject_depth(depth, keep, K, T))
    pts = np.concatenate(parts) if parts else np.zeros((0, 3))
    down = voxel_downsample(pts, voxel_m)
    edges = f", depth edges (jump > {edge_jump_rel:g} x depth) left out" if edge_jump_rel > 0 else ""
    views = f"renders at {views_note}" if views_note else f"{len(poses)} renders"
    return ReconPoints(down, "renders", f"back-projected depth of {views} (near plane {near_plane * 100:g} cm), "
                                        f"where alpha > {alpha_min:g}{edges}, {voxel_m * 100:g} cm voxels")
