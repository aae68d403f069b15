"""Camera poses for evaluation: free-space lattices, survey views and held-out novel views.

All poses are the robot camera's (level, at the camera height, OpenCV axes; see
:func:`dynactivegs.sim.robot.camera_pose`) at positions where the robot's body fits
(``FreeSpace.navigable(robot radius)``). Ground-truth images come from the static scene
only: people are never rendered into them.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from dynactivegs.config import CameraConfig
from dynactivegs.errors import DagsError
from dynactivegs.rng import derive_rng
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.render import Renderer, intrinsics
from dynactivegs.sim.robot import camera_pose

VIEW_BATCH = 256          # candidate held-out poses drawn per round
MAX_VIEW_DRAWS = 200      # give up after drawing this many times the requested number of candidates


def free_space_lattice(freespace: FreeSpace, radius_m: float, spacing_m: float) -> np.ndarray:
    """float64 (M, 2): world xy of navigable cells on a square lattice of about ``spacing_m``.

    The lattice takes every k-th cell of the free-space grid in both directions
    (k = round(spacing / cell size), at least 1), keeping those where a disc of ``radius_m`` fits.
    Deterministic: no randomness.
    """
    nav = freespace.navigable(radius_m)
    k = max(1, int(round(spacing_m / freespace.res_m)))
    sel = np.zeros_like(nav)
    sel[k // 2::k, k // 2::k] = True
    return freespace.cell_to_world(np.argwhere(nav & sel))


def survey_views(freespace: FreeSpace, radius_m: float, camera: CameraConfig, spacing_m: float,
                 n_yaws: int) -> np.ndarray:
    """float64 (M * n_yaws, 4, 4) ``T_world_cam``: every lattice position x ``n_yaws`` evenly spaced headings.

    Used to extract reconstruction points from a map independently of where the robot went.
    """
    xy = free_space_lattice(freespace, radius_m, spacing_m)
    yaws = np.arange(n_yaws) * (2 * math.pi / n_yaws)
    poses = [camera_pose(float(x), float(y), float(a), camera.height_m) for x, y in xy for a in yaws]
    return np.stack(poses) if poses else np.zeros((0, 4, 4))


def heldout_views(freespace: FreeSpace, radius_m: float, camera: CameraConfig, n_views: int, seed: int,
                  scene_name: str, trajectory_xy_m: np.ndarray | None = None,
                  min_trajectory_dist_m: float = 0.2) -> np.ndarray:
    """float64 (n_views, 4, 4) ``T_world_cam`` of held-out novel views, at camera height, in free space.

    Candidates come from one seeded stream per (``seed``, ``scene_name``): a navigable cell chosen
    uniformly, a uniform offset inside it, a uniform yaw. A candidate is kept when the robot's
    body fits there and it is at least ``min_trajectory_dist_m`` (horizontally) from every
    position in ``trajectory_xy_m`` (T, 2). Because the stream does not depend on the trajectory,
    two runs on one scene share every held-out view neither of them went near; pass the union of
    their trajectories to compare them on identical views.

    Raises :class:`DagsError` when the trajectory leaves too little free space for ``n_views`` views.
    """
    nav_cells = np.argwhere(freespace.navigable(radius_m))
    if len(nav_cells) == 0:
        raise DagsError(f"scene {scene_name}: no free space for held-out views (robot radius {radius_m} m)")
    tree = None
    if trajectory_xy_m is not None and len(trajectory_xy_m):
        traj = np.asarray(trajectory_xy_m, dtype=np.float64)
        assert traj.ndim == 2 and traj.shape[1] == 2, f"trajectory_xy_m must be (T, 2); got {traj.shape}"
        tree = cKDTree(traj)
    rng = derive_rng(seed, "heldout-views", scene_name)
    kept: list[np.ndarray] = []          # (x, y, yaw) rows
    drawn = 0
    while sum(len(k) for k in kept) < n_views:
        if drawn >= MAX_VIEW_DRAWS * n_views:
            raise DagsError(f"scene {scene_name}: only {sum(len(k) for k in kept)} of {n_views} held-out views are "
                            f"{min_trajectory_dist_m} m from the trajectory; lower eval.min_trajectory_dist_m "
                            "or eval.n_views")
        cells = nav_cells[rng.integers(0, len(nav_cells), size=VIEW_BATCH)]
        xy = freespace.cell_to_world(cells) + (rng.random((VIEW_BATCH, 2)) - 0.5) * freespace.res_m
        yaw = rng.uniform(-math.pi, math.pi, size=VIEW_BATCH)
        drawn += VIEW_BATCH
        ok = freespace.is_navigable(xy, radius_m)
        if tree is not None:
            d, _ = tree.query(xy)
            ok &= d >= min_trajectory_dist_m
        kept.append(np.c_[xy[ok], yaw[ok]])
    rows = np.concatenate(kept)[:n_views]
    return np.stack([camera_pose(float(x), float(y), float(a), camera.height_m) for x, y, a in rows])


def camera_intrinsics(camera: CameraConfig) -> np.ndarray:
    """float64 (3, 3) K of the robot camera (the simulator's)."""
    return intrinsics(camera.width_px, camera.height_px, camera.fx, camera.fy)


def ground_truth_renders(renderer: Renderer, poses: np.ndarray, camera: CameraConfig) -> tuple[np.ndarray, np.ndarray]:
    """Static-only renders at ``poses`` (V, 4, 4): rgb uint8 (V, H, W, 3) and depth_m float32 (V, H, W).

    The renderer is given no people, so these are the simulator's ``render_static`` images.
    """
    assert poses.ndim == 3 and poses.shape[1:] == (4, 4)
    K = camera_intrinsics(camera)
    h, w = camera.height_px, camera.width_px
    rgb = np.zeros((len(poses), h, w, 3), np.uint8)
    depth = np.zeros((len(poses), h, w), np.float32)
    for i, T in enumerate(poses):
        out = renderer.render(T, K, w, h, min_depth_m=camera.min_depth_m, max_depth_m=camera.max_depth_m)
        rgb[i], depth[i] = out.rgb, out.depth_m
    return rgb, depth
