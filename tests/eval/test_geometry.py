"""Geometry metrics on constructed cases, and the ground-truth points of a real scene."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import trimesh

from dynactivegs.config import CrowdConfig, SimConfig
from dynactivegs.eval import geometry
from dynactivegs.eval.config import EvalConfig
from dynactivegs.eval.geometry import geometry_metrics, ground_truth_points, voxel_downsample
from dynactivegs.errors import ConfigError
from dynactivegs.sim.scenes import load_scene
from dynactivegs.sim.world import Simulator


def plane_grid(step_m: float = 0.01, size_m: float = 1.0) -> np.ndarray:
    """float64 (N, 3): a square grid of points on z = 0."""
    u = np.arange(0.0, size_m, step_m)
    x, y = np.meshgrid(u, u)
    return np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]


def test_perfect_reconstruction_gives_zero_error_and_full_completion():
    gt = np.random.default_rng(0).random((5000, 3))
    m = geometry_metrics(gt.copy(), gt)
    assert m.acc_cm == 0.0 and m.comp_cm == 0.0 and m.cr_pct == 100.0
    assert (m.n_recon, m.n_gt) == (5000, 5000)


def test_known_offset_of_3cm_gives_3cm():
    gt = plane_grid()
    m = geometry_metrics(gt + [0.0, 0.0, 0.03], gt)
    assert m.acc_cm == pytest.approx(3.0, abs=1e-9) and m.comp_cm == pytest.approx(3.0, abs=1e-9)
    assert m.cr_pct == 100.0                                   # within 5 cm
    assert geometry_metrics(gt + [0.0, 0.0, 0.03], gt, cr_threshold_cm=2.0).cr_pct == 0.0


def test_missing_half_gives_completion_ratio_about_half():
    gt = np.random.default_rng(1).random((20000, 3)) * [4.0, 4.0, 0.0]
    recon = gt[gt[:, 0] < 2.0]
    m = geometry_metrics(recon, gt)
    assert m.acc_cm == 0.0                                     # what is there is exact
    assert 48.0 < m.cr_pct < 52.0                              # half, plus a 5 cm band along the cut (~1 %)
    assert m.comp_cm > 20.0                                    # the missing half is on average ~1 m away


SQUARE = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
                   [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]])    # the unit square on z = 0, two triangles


def sparse_square_samples(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random points on SQUARE and the triangle each lies on."""
    xy = np.random.default_rng(seed).random((n, 2))
    return np.c_[xy, np.zeros(n)], (xy[:, 1] > xy[:, 0]).astype(np.int64)


def test_surface_accuracy_is_free_of_the_sampling_floor():
    gt, faces = sparse_square_samples(400, 3)                 # ~5 cm spacing: 2-3 cm to the nearest sample
    recon = np.c_[np.random.default_rng(4).random((3000, 2)), np.zeros(3000)]
    by_point = geometry_metrics(recon, gt)
    by_surface = geometry_metrics(recon, gt, gt_faces=faces, triangles_m=SQUARE)
    assert by_point.acc_cm > 1.5
    assert by_surface.acc_cm == pytest.approx(0.0, abs=1e-9)   # every point lies on the surface
    assert by_surface.comp_cm == by_point.comp_cm and by_surface.cr_pct == by_point.cr_pct


def test_surface_accuracy_of_a_known_offset():
    gt, faces = sparse_square_samples(400, 5)
    recon = np.c_[np.random.default_rng(6).random((3000, 2)) * 0.8 + 0.1, np.full(3000, 0.03)]
    m = geometry_metrics(recon, gt, gt_faces=faces, triangles_m=SQUARE)
    assert m.acc_cm == pytest.approx(3.0, abs=1e-9)
    far = geometry_metrics(recon + [0.0, 0.0, 0.5], gt, gt_faces=faces, triangles_m=SQUARE)
    assert far.acc_cm == pytest.approx(53.0, abs=1e-9)


def test_empty_reconstruction():
    m = geometry_metrics(np.zeros((0, 3)), plane_grid(0.1))
    assert math.isnan(m.acc_cm) and math.isnan(m.comp_cm) and m.cr_pct == 0.0


def test_voxel_downsample_keeps_one_centroid_per_voxel_independent_of_order():
    rng = np.random.default_rng(2)
    pts = np.repeat(rng.random((100, 3)) * 10.0, 5, axis=0) + rng.random((500, 3)) * 1e-3   # 5 points per cluster
    down = voxel_downsample(pts, 0.01)
    assert len(down) <= 100 * 8 and len(down) >= 100
    shuffled = voxel_downsample(pts[rng.permutation(len(pts))], 0.01)
    np.testing.assert_allclose(down, shuffled, atol=1e-12)
    one_voxel = np.array([[0.001, 0.001, 0.001], [0.009, 0.009, 0.009]])
    np.testing.assert_allclose(voxel_downsample(one_voxel, 0.01), [[0.005, 0.005, 0.005]])


# ------------------------------------------------------------------------- ground truth on a scene
SIM = SimConfig(scene="tiny-00")
SMALL = dict(n_gt_points=20_000, viewpoint_spacing_m=1.0)


def test_ground_truth_points_are_the_visible_static_surface(tmp_path):
    cfg = EvalConfig(cache_dir=str(tmp_path), **SMALL)
    gt = ground_truth_points(SIM, cfg)
    pts = gt.points_m
    assert pts.shape == (20_000, 3) and not gt.from_cache
    scene = load_scene(SIM)
    room = scene.rooms[0]
    # Exterior faces (outer sides of walls at the room's rectangle, slab underside, ceiling top) are never visible.
    on_exterior = ((np.abs(pts[:, 0] - room.x0) < 1e-4) | (np.abs(pts[:, 0] - room.x1) < 1e-4)
                   | (np.abs(pts[:, 1] - room.y0) < 1e-4) | (np.abs(pts[:, 1] - room.y1) < 1e-4)
                   | (pts[:, 2] < -1e-6) | (pts[:, 2] > scene.wall_height_m + 1e-6))
    assert not on_exterior.any()
    all_samples = scene.sample_surface(20_000, np.random.default_rng(0))[0]
    assert (all_samples[:, 2] < -1e-6).mean() > 0.05            # ...though the mesh has plenty of them
    assert 0.2 < gt.visible_fraction < 0.8
    # Floor, walls and ceiling are all seen.
    assert (pts[:, 2] < 0.01).mean() > 0.05 and (pts[:, 2] > scene.wall_height_m - 0.01).mean() > 0.02
    # Each point lies on the triangle it is recorded with (float32 storage: ~1e-6 m).
    on_face = trimesh.triangles.closest_point(scene.triangles_m[gt.face_idx], pts)
    assert np.abs(on_face - pts).max() < 1e-5
    assert np.array_equal(ground_truth_points(SIM, cfg).face_idx, gt.face_idx)       # through the cache too


def test_people_never_appear_in_ground_truth_points(tmp_path):
    crowded = dataclasses.replace(SIM, crowd=CrowdConfig(count=3))
    cfg = EvalConfig(cache_dir=str(tmp_path), **SMALL)
    pts = ground_truth_points(crowded, cfg).points_m
    empty = ground_truth_points(dataclasses.replace(SIM, crowd=CrowdConfig(count=0)),
                                dataclasses.replace(cfg, cache_dir=str(tmp_path / "other"))).points_m
    np.testing.assert_array_equal(pts, empty)                   # the crowd does not enter the ground truth
    sim = Simulator(crowded, 0)
    for _ in range(3):
        sim.step(1)
    assert len(sim.crowd) == 3
    for (px, py), height in zip(sim.crowd.positions_xy_m, sim.crowd.heights_m):
        torso = (np.hypot(pts[:, 0] - px, pts[:, 1] - py) < 0.15) & (pts[:, 2] > 0.3) & (pts[:, 2] < height - 0.2)
        assert not torso.any()


def test_ground_truth_cache_is_reused_and_keyed_by_parameters(tmp_path, monkeypatch):
    cfg = EvalConfig(cache_dir=str(tmp_path), **SMALL)
    first = ground_truth_points(SIM, cfg)
    assert first.path.is_file() and first.path.parent.parent == tmp_path

    def fail(*args, **kwargs):
        raise AssertionError("recomputed although cached")

    with monkeypatch.context() as mp:
        mp.setattr(geometry, "sample_visible_surface", fail)
        second = ground_truth_points(SIM, cfg)
    assert second.from_cache and second.key == first.key
    np.testing.assert_array_equal(second.points_m, first.points_m)

    scene = load_scene(SIM)
    keys = {geometry.gt_cache_key(scene, SIM, cfg),
            geometry.gt_cache_key(scene, SIM, dataclasses.replace(cfg, n_gt_points=20_001)),
            geometry.gt_cache_key(scene, SIM, dataclasses.replace(cfg, viewpoint_spacing_m=0.5)),
            geometry.gt_cache_key(scene, SIM, dataclasses.replace(cfg, gt_seed=1)),
            geometry.gt_cache_key(scene, dataclasses.replace(SIM, camera=dataclasses.replace(SIM.camera, height_m=1.0)),
                                  cfg),
            geometry.gt_cache_key(load_scene(SimConfig(scene="tiny-01")), SIM, cfg)}
    assert len(keys) == 6
    # Settings the ground truth does not depend on keep the key (and the cache).
    assert geometry.gt_cache_key(scene, SIM, dataclasses.replace(cfg, n_views=7, cr_threshold_cm=2.0)) == first.key


def test_ground_truth_points_are_deterministic(tmp_path):
    cfg = EvalConfig(cache_dir=str(tmp_path / "a"), n_gt_points=3000, viewpoint_spacing_m=1.0)
    a = ground_truth_points(SIM, cfg).points_m
    b = ground_truth_points(SIM, dataclasses.replace(cfg, cache_dir=str(tmp_path / "b"))).points_m
    c = ground_truth_points(SIM, dataclasses.replace(cfg, cache_dir=str(tmp_path / "c"), gt_seed=1)).points_m
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_bad_config_values_are_one_line_errors():
    with pytest.raises(ConfigError, match="eval.recon_method"):
        EvalConfig(recon_method="mesh")
    with pytest.raises(ConfigError, match="eval.n_gt_points"):
        EvalConfig(n_gt_points=0)
