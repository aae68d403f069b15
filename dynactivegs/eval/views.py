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


def _true_surface(renderer: Renderer, T: np.ndarray, camera: CameraConfig, edge_jump_rel: float) -> np.ndarray:
    """float64 (N, 3): a perfect map's "renders" points of one view: the static mesh's back-projected depth,
    depth-edge pixels left out (as :func:`dynactivegs.eval.recon.rendered_points` does)."""
    from dynactivegs.eval.recon import backproject_depth, depth_edge_mask      # recon imports geometry, which imports this

    K = camera_intrinsics(camera)
    depth = renderer.render(T, K, camera.width_px, camera.height_px, min_depth_m=camera.min_depth_m,
                            max_depth_m=camera.max_depth_m).depth_m.astype(np.float64)
    keep = depth > 0
    if edge_jump_rel > 0:
        keep &= ~depth_edge_mask(depth, keep, edge_jump_rel)
    return backproject_depth(depth, keep, K, T)


def view_footprints(renderer: Renderer, poses: np.ndarray, camera: CameraConfig, points_m: np.ndarray,
                    radius_m: float, edge_jump_rel: float, voxel_m: float,
                    points_tree: cKDTree | None = None) -> list[np.ndarray]:
    """For each pose (V, 4, 4): int64 indices of the ``points_m`` (N, 3) that a perfect map shows from it:
    those within ``radius_m`` of its :func:`_true_surface` points, voxel-downsampled at ``voxel_m``."""
    from dynactivegs.eval.geometry import voxel_downsample

    tree = cKDTree(points_m) if points_tree is None else points_tree
    out = []
    for T in poses:
        pts = voxel_downsample(_true_surface(renderer, T, camera, edge_jump_rel), voxel_m)
        hits = tree.query_ball_point(pts, radius_m, return_sorted=False) if len(pts) else []
        out.append(np.unique(np.fromiter((i for h in hits for i in h), np.int64)))
    return out


def perfect_cr(renderer: Renderer, poses: np.ndarray, camera: CameraConfig, points_m: np.ndarray, radius_m: float,
               edge_jump_rel: float, voxel_m: float) -> float:
    """The fraction of ``points_m`` within ``radius_m`` of a perfect map's "renders" points at ``poses``
    (voxel-downsampled together, as a map's are): the C.R. a perfect map reaches with these views."""
    from dynactivegs.eval.geometry import voxel_downsample

    if len(poses) == 0 or len(points_m) == 0:
        return 0.0
    pts = voxel_downsample(np.concatenate([_true_surface(renderer, T, camera, edge_jump_rel) for T in poses]), voxel_m)
    if len(pts) == 0:
        return 0.0
    d, _ = cKDTree(pts).query(points_m, distance_upper_bound=radius_m)
    return float((d <= radius_m).mean())


def greedy_cover(footprints: list[np.ndarray], n_points: int, fraction: float) -> tuple[np.ndarray, int, int]:
    """Greedy set cover: the indices of the footprints chosen, in order, until the chosen ones cover
    ``fraction`` of the union of all; with (points covered, points in the union).

    Each round takes the footprint adding the most uncovered points (ties: the lowest index), found
    lazily: a footprint's gain only shrinks, so a stale gain at the top of the heap is re-counted and
    pushed back until the top one is current. Deterministic.
    """
    import heapq

    union = np.zeros(n_points, bool)
    for f in footprints:
        union[f] = True
    total = int(union.sum())
    need = math.ceil(fraction * total - 1e-9)
    covered = np.zeros(n_points, bool)
    heap = [(-len(f), i) for i, f in enumerate(footprints) if len(f)]
    heapq.heapify(heap)
    chosen: list[int] = []
    n_cov = 0
    while n_cov < need and heap:
        neg, i = heapq.heappop(heap)
        gain = int((~covered[footprints[i]]).sum())
        if gain < -neg:                      # stale: re-count and queue again
            if gain > 0:
                heapq.heappush(heap, (-gain, i))
            continue
        covered[footprints[i]] = True
        n_cov += gain
        chosen.append(i)
    return np.asarray(chosen, np.int64), n_cov, total


def covering_survey(renderer: Renderer, freespace: FreeSpace, radius_m: float, camera: CameraConfig,
                    spacing_m: float, n_yaws: int, points_m: np.ndarray, cover: float, threshold_m: float,
                    edge_jump_rel: float, voxel_m: float,
                    points_tree: cKDTree | None = None) -> tuple[np.ndarray, int, float]:
    """The survey the "renders" reconstruction is rendered from: (poses (S, 4, 4), candidates, ceiling).

    Candidates are :func:`survey_views` (``spacing_m`` x ``n_yaws``). With ``cover`` in (0, 1], the
    survey is the fewest of them, chosen greedily (:func:`greedy_cover`), that a perfect map would
    show ``cover`` of the ground-truth points ``points_m`` from, out of those it shows from all
    candidates (a point counts within ``threshold_m``, the C.R. threshold); with ``cover`` 0 it
    is every candidate. ``ceiling``: :func:`perfect_cr` of the survey, the highest C.R. a map can reach
    with it (per-view footprints are voxel-downsampled apart, so the cover is met to within a few points).
    """
    cand = survey_views(freespace, radius_m, camera, spacing_m, n_yaws)
    if len(cand) == 0:
        return cand, 0, 0.0
    if cover > 0:
        feet = view_footprints(renderer, cand, camera, points_m, threshold_m, edge_jump_rel, voxel_m, points_tree)
        chosen, _, _ = greedy_cover(feet, len(points_m), cover)
        poses = cand[np.sort(chosen)]
    else:
        poses = cand
    return poses, len(cand), perfect_cr(renderer, poses, camera, points_m, threshold_m, edge_jump_rel, voxel_m)


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
