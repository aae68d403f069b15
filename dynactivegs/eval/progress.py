"""Progress over a run: the 25/50/75/100 % checkpoints of a step budget and a cheap coverage metric.

The full metrics (:class:`dynactivegs.eval.metrics.SceneEvaluator`) render the map at many
views; they run at the checkpoints. Coverage is cheap enough for every few steps (a
progress bar, a viewer plot): the percentage of a fixed subsample of the ground-truth
points that have an opaque Gaussian centre within the C.R. threshold. It tracks C.R. from
below-or-near (Gaussian centres are sparser than rendered surfaces) and is not a
replacement for it.

Observed surface (:class:`ObservedSurface`) is a trait of the path, not of the map: the percentage of
the same probe points that the camera has seen so far, by its own depth (a point is seen in a frame when
it projects into the image, in front of the camera, onto a pixel whose depth return lies within
``OBSERVED_TOL_M`` of the point's depth; a person or an object in front hides it). A map can only be as
complete as what its path saw; PSNR on held-out views goes with it (benchmarks/results/
apartment-1000-observed). :meth:`ObservedSurface.view_share` weighs the points as a set of views sees them
(each by the pixels its patch of surface fills there): on the held-out views it is the share of their
pixels that show surface the camera saw, which goes with their PSNR more closely still (a small room left
unseen fills many held-out views and little of the flat's surface).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from dynactivegs.rng import derive_rng

CHECKPOINT_FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def checkpoint_steps(budget: int, fractions: tuple[float, ...] = CHECKPOINT_FRACTIONS) -> tuple[int, ...]:
    """The step counts at which each fraction of ``budget`` steps is spent: ``ceil(f * budget)``, at least 1.

    With ``budget = 1000``: (250, 500, 750, 1000). One entry per fraction, in order, so
    ``dict(zip(fractions, checkpoint_steps(budget, fractions)))`` maps fractions to steps;
    for tiny budgets neighbouring fractions may share a step.
    """
    if budget < 1:
        raise ValueError(f"step budget must be >= 1; got {budget}")
    assert all(0.0 < f <= 1.0 for f in fractions), "fractions must lie in (0, 1]"
    return tuple(max(1, math.ceil(f * budget - 1e-9)) for f in fractions)


@dataclass(frozen=True)
class CoverageProbe:
    """A fixed subsample of ground-truth points and a distance threshold, for cheap coverage checks."""

    points_m: np.ndarray          # float64 (M, 3), subsample of the ground-truth points
    threshold_cm: float

    @staticmethod
    def from_ground_truth(gt_points_m: np.ndarray, n: int, threshold_cm: float, seed: int = 0) -> "CoverageProbe":
        """``n`` ground-truth points (N, 3) chosen without replacement (all when N <= n), seeded."""
        assert gt_points_m.ndim == 2 and gt_points_m.shape[1] == 3
        if len(gt_points_m) <= n:
            return CoverageProbe(np.asarray(gt_points_m, dtype=np.float64).copy(), threshold_cm)
        idx = np.sort(derive_rng(seed, "coverage-probe").choice(len(gt_points_m), size=n, replace=False))
        return CoverageProbe(np.asarray(gt_points_m[idx], dtype=np.float64), threshold_cm)

    def __call__(self, recon_points_m: np.ndarray) -> float:
        """Percentage of probe points with a point of ``recon_points_m`` (N, 3) within the threshold."""
        assert recon_points_m.ndim == 2 and recon_points_m.shape[1] == 3
        if len(recon_points_m) == 0:
            return 0.0
        d, _ = cKDTree(recon_points_m).query(self.points_m, distance_upper_bound=self.threshold_cm / 100.0)
        return float(np.isfinite(d).mean() * 100.0)

    def of_gaussians(self, gaussians, opacity_min: float = 0.5) -> float:
        """Coverage (%) by the centres of the Gaussians (a splat.Gaussians) above ``opacity_min``."""
        import torch

        with torch.no_grad():
            keep = gaussians.opacities > opacity_min
            pts = gaussians.means[keep].detach().to("cpu", torch.float64).numpy()
        return self(pts)


OBSERVED_TOL_M = 0.03
"""A probe point is seen in a frame when the depth return at its pixel is within this of its own z-depth."""


class ObservedSurface:
    """Which of a fixed set of surface points (M, 3) the camera has seen so far (module docstring).

    ``normals`` (M, 3), unit normals of the surface at the points, are needed for :meth:`view_share` only."""

    def __init__(self, points_m: np.ndarray, tol_m: float = OBSERVED_TOL_M, normals: np.ndarray | None = None) -> None:
        assert points_m.ndim == 2 and points_m.shape[1] == 3 and tol_m > 0
        self.points_m = np.asarray(points_m, dtype=np.float64)
        self.tol_m = float(tol_m)
        self.normals = None if normals is None else np.asarray(normals, dtype=np.float64)
        assert self.normals is None or self.normals.shape == self.points_m.shape
        self.seen = np.zeros(len(self.points_m), dtype=np.bool_)

    def visible(self, depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
        """Indices of the points a view sees: z-depth image (H, W) in m (0: no return), intrinsics (3, 3) with
        pixel centres at +0.5, camera-to-world (4, 4) in OpenCV axes."""
        h, w = depth_m.shape
        pc = (self.points_m - T_world_cam[:3, 3]) @ T_world_cam[:3, :3]      # world -> camera
        z = pc[:, 2]
        front = z > 1e-6
        zs = np.where(front, z, 1.0)
        u = np.floor(K[0, 0] * pc[:, 0] / zs + K[0, 2])
        v = np.floor(K[1, 1] * pc[:, 1] / zs + K[1, 2])
        idx = np.flatnonzero(front & (u >= 0) & (u < w) & (v >= 0) & (v < h))
        d = depth_m[v[idx].astype(np.int64), u[idx].astype(np.int64)]
        return idx[(d > 0) & (np.abs(d - z[idx]) <= self.tol_m)]

    def update(self, depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> None:
        """Mark the points seen in one frame (arguments as :meth:`visible`)."""
        self.seen[self.visible(depth_m, K, T_world_cam)] = True

    @property
    def pct(self) -> float:
        """Percentage of the points seen so far (0 for no points)."""
        return float(self.seen.mean() * 100.0) if len(self.seen) else 0.0

    def view_weights(self, poses: np.ndarray, depths_m: np.ndarray, K: np.ndarray) -> np.ndarray:
        """float64 (M,): how many pixels of the views (poses (V, 4, 4), their true depth (V, H, W)) each point stands
        for, summed over the views. Points sample the surface uniformly, so a point stands for a patch of it, which
        fills |cos| / r^2 of solid angle; a pixel's solid angle falls as cos^3 of its angle off the optical axis, so
        the patch fills pixels in proportion to |cos| r / z^3 (z the z-depth). 0 for points no view sees."""
        assert self.normals is not None, "view weights need the points' normals"
        w = np.zeros(len(self.points_m))
        for T, depth in zip(poses, depths_m):
            idx = self.visible(depth, K, T)
            ray = self.points_m[idx] - T[:3, 3]
            z = ray @ T[:3, 2]
            w[idx] += np.abs(np.einsum("ij,ij->i", ray, self.normals[idx])) / z ** 3
        return w

    def view_share(self, poses: np.ndarray, depths_m: np.ndarray, K: np.ndarray, seen: np.ndarray | None = None
                   ) -> float:
        """Percentage of the views' pixels (to the sampling: :meth:`view_weights`) that show surface seen
        (``seen``, bool (M,); default: seen so far). NaN when the views see none of the points."""
        seen = self.seen if seen is None else seen
        assert seen.shape == self.seen.shape
        return weighted_share(self.view_weights(poses, depths_m, K), seen)


def pixel_points(poses: np.ndarray, depths_m: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface points a set of views shows, one per pixel: poses (V, 4, 4) camera-to-world in OpenCV axes,
    their z-depth images (V, H, W) in m (0: no return), intrinsics (3, 3) with pixel centres at +0.5. Returns
    float64 (M, 3) world points of the pixels with a return, and bool (V, H, W), True at those pixels, in the
    order of the points (``mask[mask] = seen`` puts a per-point result back on the pixels). An
    :class:`ObservedSurface` of these points, updated with a run's frames, says which pixels of the views show
    surface the run's camera saw: what :meth:`ObservedSurface.view_share` estimates from the probe points."""
    from dynactivegs.eval.recon import backproject_depth      # torch-importing module: only when asked

    depths = np.asarray(depths_m, np.float64)
    assert depths.ndim == 3 and len(poses) == len(depths), "depths must be (V, H, W), one per pose"
    mask = depths > 0
    points = [backproject_depth(d, m, K, T) for T, d, m in zip(poses, depths, mask)]
    return (np.concatenate(points) if points else np.zeros((0, 3))), mask


def weighted_share(weights: np.ndarray, seen: np.ndarray) -> float:
    """Percentage of the total of ``weights`` (M,) on the points ``seen`` (bool (M,)); NaN when the total is 0."""
    den = float(weights.sum())
    return 100.0 * float(weights[seen].sum()) / den if den > 0 else float("nan")
