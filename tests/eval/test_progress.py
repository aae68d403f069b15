"""Checkpoints of a step budget and the cheap coverage metric."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dynactivegs.eval.progress import CoverageProbe, ObservedSurface, checkpoint_steps, pixel_points
from dynactivegs.sim.robot import camera_pose
from dynactivegs.splat import Gaussians


def test_checkpoints_are_the_quarter_steps_of_the_budget():
    assert checkpoint_steps(1000) == (250, 500, 750, 1000)
    assert checkpoint_steps(10) == (3, 5, 8, 10)
    assert checkpoint_steps(3) == (1, 2, 3, 3)
    assert checkpoint_steps(1) == (1, 1, 1, 1)
    assert checkpoint_steps(200, (0.1, 1.0)) == (20, 200)
    with pytest.raises(ValueError):
        checkpoint_steps(0)


def test_coverage_is_the_share_of_ground_truth_near_the_reconstruction():
    gt = np.random.default_rng(0).random((50_000, 3)) * [4.0, 4.0, 0.0]
    probe = CoverageProbe.from_ground_truth(gt, 5_000, 5.0, seed=0)
    assert probe.points_m.shape == (5_000, 3)
    np.testing.assert_array_equal(probe.points_m, CoverageProbe.from_ground_truth(gt, 5_000, 5.0, seed=0).points_m)
    assert probe(gt) == 100.0
    assert 47.0 < probe(gt[gt[:, 0] < 2.0]) < 53.0
    assert probe(np.zeros((0, 3))) == 0.0
    assert probe(gt + [0.0, 0.0, 0.06]) == 0.0                  # 6 cm away: beyond the 5 cm threshold
    # From a Gaussian map: only opaque Gaussians count.
    means = torch.as_tensor(gt[gt[:, 0] < 2.0])
    n = len(means)
    opacity = torch.full((n,), 0.9, dtype=torch.float64)
    g = Gaussians.from_params(means, torch.full((n, 3), 0.01, dtype=torch.float64),
                              torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64).repeat(n, 1), opacity,
                              torch.full((n, 3), 0.5, dtype=torch.float64))
    assert probe.of_gaussians(g) == pytest.approx(probe(gt[gt[:, 0] < 2.0]))
    assert probe.of_gaussians(g, opacity_min=0.95) == 0.0


def _wall_points() -> np.ndarray:
    """A 1 cm grid on the wall x = 2 m, y in [-4, 4), z in [0, 2) (camera at the origin, height 1 m)."""
    y, z = np.meshgrid(np.arange(-4.0, 4.0, 0.01) + 0.005, np.arange(0.0, 2.0, 0.01) + 0.005, indexing="ij")
    return np.stack([np.full(y.size, 2.0), y.ravel(), z.ravel()], axis=1)


def test_observed_surface_is_what_the_frustum_saw_by_depth():
    # a 64 x 48 camera with 90 deg horizontal field of view at (0, 0, 1) m looking along +x at the wall x = 2 m
    K = np.array([[32.0, 0.0, 32.0], [0.0, 32.0, 24.0], [0.0, 0.0, 1.0]])
    T = camera_pose(0.0, 0.0, 0.0, 1.0)
    pts = _wall_points()
    wall = np.full((48, 64), 2.0, np.float32)              # the wall is at z-depth 2 m at every pixel
    obs = ObservedSurface(pts)
    obs.update(wall, K, T)
    # the frustum meets the wall in |y| < 2 m (half of 8 m) and |z - 1| < 1.5 m (all of its 2 m): 50 %
    assert obs.pct == pytest.approx(50.0, abs=0.3)
    assert np.all(np.abs(pts[obs.seen, 1]) <= 2.0 + 0.07)
    # a person 1 m in front of the camera over the image's left half hides the wall there
    hidden = ObservedSurface(pts)
    person = wall.copy()
    person[:, :32] = 1.0
    hidden.update(person, K, T)
    assert hidden.pct == pytest.approx(25.0, abs=0.3) and np.all(pts[hidden.seen, 1] < 0.07)   # x right = -y
    # no depth return: nothing seen; a depth off by more than the tolerance: nothing seen
    for depth in (np.zeros_like(wall), wall + 0.05):
        none = ObservedSurface(pts)
        none.update(depth, K, T)
        assert none.pct == 0.0
    # the wall behind the camera is not seen, though its points project into the image through the centre
    behind = ObservedSurface(pts * [-1.0, 1.0, 1.0])
    behind.update(wall, K, T)
    assert behind.pct == 0.0
    # seen points stay seen: turning to the person's side and back adds the left half after all
    hidden.update(wall, K, T)
    assert hidden.pct == pytest.approx(obs.pct) and np.array_equal(hidden.seen, obs.seen)


def _wall_depth(K: np.ndarray, T: np.ndarray, shape=(48, 64)) -> tuple[np.ndarray, np.ndarray]:
    """The z-depth image of the wall of :func:`_wall_points` from pose T (0 where a ray misses it), and the y of
    the wall point at each pixel (NaN where none)."""
    v, u = np.mgrid[:shape[0], :shape[1]] + 0.5
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(shape)], axis=-1)
    d = d_cam @ T[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (2.0 - T[0, 3]) / d[..., 0]
    hit = T[:3, 3] + t[..., None] * d
    ok = (t > 0) & (hit[..., 1] >= -4.0) & (hit[..., 1] < 4.0) & (hit[..., 2] >= 0.0) & (hit[..., 2] < 2.0)
    return np.where(ok, t, 0.0).astype(np.float32), np.where(ok, hit[..., 1], np.nan)


def test_the_views_share_of_observed_surface_weighs_points_by_the_pixels_they_fill():
    K = np.array([[32.0, 0.0, 32.0], [0.0, 32.0, 24.0], [0.0, 0.0, 1.0]])
    pts = _wall_points()
    normals = np.tile([-1.0, 0.0, 0.0], (len(pts), 1))
    obs = ObservedSurface(pts, normals=normals)
    person = _wall_depth(K, camera_pose(0.0, 0.0, 0.0, 1.0))[0]
    person[:, :32] = 1.0                                          # the camera saw the wall's y < 0 half only
    obs.update(person, K, camera_pose(0.0, 0.0, 0.0, 1.0))
    assert obs.pct == pytest.approx(25.0, abs=0.3)

    def pixel_share(poses) -> float:                               # the share of the views' wall pixels seen
        ys = np.concatenate([_wall_depth(K, T)[1].ravel() for T in poses])
        ys = ys[np.isfinite(ys)]
        return 100.0 * float(np.mean((ys >= -2.0) & (ys < 0.0)))

    near_seen, near_unseen = camera_pose(1.0, -1.0, 0.0, 1.0), camera_pose(1.0, 1.0, 0.0, 1.0)
    far_middle = camera_pose(-2.0, 0.5, 0.0, 1.0)
    for poses in ([camera_pose(0.0, 0.0, 0.0, 1.0)], [near_seen], [near_unseen], [near_unseen, far_middle],
                  [near_seen, far_middle, near_unseen]):
        poses = np.stack(poses)
        depths = np.stack([_wall_depth(K, T)[0] for T in poses])
        assert obs.view_share(poses, depths, K) == pytest.approx(pixel_share(poses), abs=2.0)
    # the far view sees 7.5 m of wall, 2 m of it seen, the near one 2 m, none seen: by pixels (the near wall
    # fills its image, the far one a third of its rows) 6 %, by points (the far view sees 5 times as many) 22 %
    both = np.stack([near_unseen, far_middle])
    depths = np.stack([_wall_depth(K, T)[0] for T in both])
    share = obs.view_share(both, depths, K)
    counted = np.concatenate([obs.visible(d, K, T) for T, d in zip(both, depths)])
    assert share == pytest.approx(6.3, abs=0.5) and 100.0 * obs.seen[counted].mean() == pytest.approx(22.2, abs=0.5)
    # an explicit seen mask, and views that see nothing
    assert obs.view_share(both, depths, K, seen=np.ones_like(obs.seen)) == pytest.approx(100.0)
    assert np.isnan(obs.view_share(both, np.zeros_like(depths), K))
    with pytest.raises(AssertionError):
        ObservedSurface(pts).view_share(both, depths, K)         # no normals


def test_the_pixels_of_views_that_show_surface_the_camera_saw():
    """pixel_points puts one point on the surface at each pixel with a return; an ObservedSurface of them, fed a
    run's frames, marks exactly the pixels whose wall point the run saw (here: the wall's y < 0 half)."""
    K = np.array([[32.0, 0.0, 32.0], [0.0, 32.0, 24.0], [0.0, 0.0, 1.0]])
    run_pose = camera_pose(0.0, 0.0, 0.0, 1.0)
    frame = _wall_depth(K, run_pose)[0]
    frame[:, :32] = 1.0                                           # a person hides the wall's y >= 0 half
    poses = np.stack([camera_pose(1.0, -1.0, 0.0, 1.0), camera_pose(-2.0, 0.5, 0.3, 1.0), camera_pose(1.0, 1.0, 0, 1)])
    walls = [_wall_depth(K, T) for T in poses]
    depths = np.stack([d for d, _ in walls])
    depths[1, :5, :] = 0.0                                        # some pixels without a return
    points, mask = pixel_points(poses, depths, K)
    assert mask.shape == depths.shape and np.array_equal(mask, depths > 0) and len(points) == mask.sum()
    assert np.allclose(points[:, 0], 2.0, atol=1e-6)              # on the wall ...
    ys = np.concatenate([y[d > 0] for (_, y), d in zip(walls, depths)])
    assert np.allclose(points[:, 1], ys, atol=1e-6)               # ... where each pixel's ray meets it
    obs = ObservedSurface(points)
    obs.update(frame, K, run_pose)
    seen = np.zeros_like(mask)
    seen[mask] = obs.seen
    for (_, y), d, s in zip(walls, depths, seen):
        inside = (y >= -2.0 + 0.07) & (y < -0.07) & (d > 0)        # seen half, away from the frustum's edges
        outside = ((y >= 0.07) | (y < -2.07)) & (d > 0)
        assert s[inside].all() and not s[outside].any() and not s[d == 0].any()
    assert not seen[2].any() and seen[0].mean() > 0.9             # the near views of each half
