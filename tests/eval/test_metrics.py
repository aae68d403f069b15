"""End to end on a real scene: maps built directly from the simulator's static RGB-D frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.config import CameraConfig, CrowdConfig, SimConfig
from dynactivegs.eval.config import EvalConfig
from dynactivegs.eval.geometry import geometry_metrics, voxel_downsample
from dynactivegs.eval.metrics import Metrics, SceneEvaluator
from dynactivegs.eval.recon import backproject_depth, depth_edge_mask, rendered_points
from dynactivegs.eval.rendering import render_metrics
from dynactivegs.rng import derive_rng
from dynactivegs.sim.world import Simulator
from dynactivegs.splat import Gaussians

SIM = SimConfig(scene="tiny-00", camera=CameraConfig(width_px=80, height_px=46), crowd=CrowdConfig(count=2))


@pytest.fixture(scope="module")
def evaluator(tmp_path_factory) -> SceneEvaluator:
    cfg = EvalConfig(cache_dir=str(tmp_path_factory.mktemp("gt")), n_gt_points=50_000, viewpoint_spacing_m=1.0,
                     survey_spacing_m=1.0, n_views=50)
    return SceneEvaluator(SIM, cfg)


def rgbd_map(sim: Simulator, poses: np.ndarray) -> Gaussians:
    """Gaussians back-projected from static (people-free) RGB-D frames at ``poses``; nothing is optimised."""
    parts = []
    for T in poses:
        frame = sim.render_static(T)
        parts.append(Gaussians.from_rgbd(frame.rgb, frame.depth_m, sim.K, T, opacity=0.95, scale_factor=0.25))
    return Gaussians.cat(parts)


def test_metrics_of_rgbd_maps_are_sensible_and_improve_with_more_views(evaluator):
    sim = Simulator(SIM, 0)
    poses = evaluator.survey_poses
    order = derive_rng(0, "test-views").permutation(len(poses))
    results: dict[int, Metrics] = {}
    for k in (3, len(poses)):
        used = poses[order[:k]]
        results[k] = evaluator.evaluate(rgbd_map(sim, used), step=k, trajectory_xy_m=used[:, :2, 3], backend="cpu")
    few, many = results[3], results[len(poses)]
    for m in (few, many):
        assert m.acc_cm < 5.0                                   # what the map has is on the surface
        assert m.recon_method == "renders" and m.n_gt_points == 50_000 and m.n_views == 50
        assert m.lpips is None and "eval.lpips_weights_path" in m.lpips_note
        assert "\n" not in m.summary() and "C.R." in m.summary() and "LPIPS n/a" in m.summary()
    assert many.cr_pct > few.cr_pct + 20.0                      # more views, more of the scene
    assert many.comp_cm < few.comp_cm / 3
    assert many.psnr_db > few.psnr_db + 3.0 and many.ssim > few.ssim
    assert many.depth_l1_cm < few.depth_l1_cm / 2
    assert many.cr_pct > 50.0 and many.psnr_db > 18.0
    # The cheap coverage follows the same trend.
    probe = evaluator.coverage_probe()
    assert probe.of_gaussians(rgbd_map(sim, poses[order[:3]])) < probe.of_gaussians(rgbd_map(sim, poses)) - 20.0


def test_the_survey_ceiling_is_the_cr_of_the_true_surface_seen_from_the_survey(evaluator):
    sim = Simulator(SIM, 0)
    sv = evaluator.survey
    assert 0 < len(sv.poses) < sv.n_candidates and sv.ceiling > 0.85   # 80 px: pixels ~5 cm apart at 3 m
    cfg = evaluator.cfg
    parts = []
    for T in sv.poses:
        d = sim.render_static(T).depth_m.astype(np.float64)
        keep = (d > 0) & ~depth_edge_mask(d, d > 0, cfg.edge_jump_rel)
        parts.append(backproject_depth(d, keep, evaluator.K, T))
    geo = geometry_metrics(voxel_downsample(np.concatenate(parts), cfg.voxel_m), evaluator.gt.points_m,
                           cfg.cr_threshold_cm)
    assert geo.cr_pct == pytest.approx(100 * sv.ceiling, abs=1e-9)
    # A second evaluator loads the same survey from the cache.
    again = SceneEvaluator(SIM, cfg).survey
    assert again.from_cache and np.array_equal(again.poses, sv.poses) and again.ceiling == sv.ceiling
    assert f"{len(sv.poses)} of {sv.n_candidates} lattice views" in evaluator.recon_points(rgbd_map(sim, sv.poses[:2])).description


def test_centre_points_of_an_rgbd_map_lie_on_the_ground_truth_surface(evaluator):
    sim = Simulator(SIM, 0)
    g = rgbd_map(sim, evaluator.survey_poses)
    rec = evaluator.recon_points(g, "centres")
    assert rec.method == "centres" and "centres" in rec.description
    m = evaluator.evaluate(g, step=0, trajectory_xy_m=None, method="centres", backend="cpu")
    # Centres are exact surface points, and Acc is measured to the surface (not to the ~2 cm spaced samples).
    assert m.acc_cm < 0.5 and m.recon_method == "centres"
    assert not math.isnan(m.comp_cm)


def test_gaussians_nearer_than_the_cameras_minimum_depth_do_not_count(evaluator):
    """The true images see nothing nearer than the camera's minimum depth; the map's renders leave it out too,
    or one Gaussian a few cm in front of a survey or held-out camera would cover most of its image."""
    import torch

    sim = Simulator(SIM, 0)
    T = evaluator.survey_poses[0]
    g = rgbd_map(sim, T[None])
    near_m = 0.5 * SIM.camera.min_depth_m
    blob = Gaussians.from_params(torch.tensor(T[:3, :3] @ [0.0, 0.0, near_m] + T[:3, 3], dtype=torch.float32)[None],
                                 torch.full((1, 3), 0.06), torch.tensor([[1.0, 0.0, 0.0, 0.0]]),
                                 torch.tensor([0.99]), torch.tensor([[0.2, 0.8, 0.2]]))
    with_blob = Gaussians.cat([g, blob])
    K, w, h = evaluator.K, SIM.camera.width_px, SIM.camera.height_px
    clean = rendered_points(g, T[None], K, w, h, near_plane=SIM.camera.min_depth_m, backend="cpu")
    clipped = rendered_points(with_blob, T[None], K, w, h, near_plane=SIM.camera.min_depth_m, backend="cpu")
    unclipped = rendered_points(with_blob, T[None], K, w, h, near_plane=0.01, backend="cpu")
    assert np.array_equal(clean.points_m, clipped.points_m)
    # unclipped, the blob hides most of the scene behind a few voxels next to the camera
    assert np.linalg.norm(unclipped.points_m - T[:3, 3], axis=1).min() < SIM.camera.min_depth_m
    assert len(unclipped.points_m) < 0.75 * len(clean.points_m)
    assert f"near plane {100 * SIM.camera.min_depth_m:g} cm" in evaluator.recon_points(g, backend="cpu").description
    frame = sim.render_static(T)
    rgb, depth = frame.rgb[None], frame.depth_m[None]
    kept, blocked = (render_metrics(with_blob, T[None], rgb, depth, K, near_plane=p, backend="cpu")
                     for p in (SIM.camera.min_depth_m, 0.01))
    assert kept.psnr_db > blocked.psnr_db + 10.0 and kept.depth_l1_cm < blocked.depth_l1_cm / 10


def test_held_out_views_of_the_last_trajectory_are_kept_and_those_of_another_are_drawn_anew(evaluator):
    traj = np.array([[1.0, 1.0], [1.5, 1.0]])
    first = evaluator.heldout(traj)
    again = evaluator.heldout(traj.copy())                 # equal values: the same arrays, nothing rendered
    assert all(a is b for a, b in zip(first, again))
    other = evaluator.heldout(traj + 0.5)
    assert other[0] is not first[0] and len(other[0]) == len(first[0])
    fresh = SceneEvaluator(evaluator.sim, evaluator.cfg).heldout(traj + 0.5)
    for a, b in zip(other, fresh):
        np.testing.assert_array_equal(a, b)               # what is kept is what a fresh evaluator renders
    assert evaluator.heldout(None)[0] is evaluator.heldout(None)[0]
