"""Held-out and survey views: where they are, how they avoid the trajectory, and their static-only ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.config import CameraConfig, CrowdConfig, SimConfig
from dynactivegs.errors import DagsError
from dynactivegs.eval.config import EvalConfig
from dynactivegs.eval.views import (camera_intrinsics, covering_survey, free_space_lattice, greedy_cover,
                                    ground_truth_renders, heldout_views, survey_views, view_footprints)
from dynactivegs.sim.robot import camera_pose
from dynactivegs.sim.world import Simulator

CAM = CameraConfig(width_px=64, height_px=37)
SIM = SimConfig(scene="tiny-00", camera=CAM, crowd=CrowdConfig(count=2))
N_VIEWS = EvalConfig().n_views


@pytest.fixture(scope="module")
def sim() -> Simulator:
    return Simulator(SIM, 0)


def yaw_of(T: np.ndarray) -> float:
    return math.atan2(T[1, 2], T[0, 2])


def trajectory(sim: Simulator) -> np.ndarray:
    """A robot-like path: the navigable lattice points of the left half of the room."""
    xy = free_space_lattice(sim.freespace, SIM.robot.radius_m, 0.25)
    return xy[xy[:, 0] < np.median(xy[:, 0])]


def test_heldout_views_are_level_at_camera_height_in_free_space_and_away_from_the_trajectory(sim):
    traj = trajectory(sim)
    poses = heldout_views(sim.freespace, SIM.robot.radius_m, CAM, N_VIEWS, 0, "tiny-00", traj, 0.2)
    assert N_VIEWS >= 50 and poses.shape == (N_VIEWS, 4, 4)
    np.testing.assert_allclose(poses[:, 2, 3], CAM.height_m)
    np.testing.assert_allclose(poses[:, :3, 1], np.tile([0.0, 0.0, -1.0], (N_VIEWS, 1)), atol=1e-12)  # level
    assert sim.freespace.is_navigable(poses[:, :2, 3], SIM.robot.radius_m).all()
    d = np.min(np.linalg.norm(poses[:, None, :2, 3] - traj[None], axis=2), axis=1)
    assert (d >= 0.2).all()
    yaws = np.array([yaw_of(T) for T in poses])
    assert np.ptp(yaws) > 5.0 and len(np.unique(np.round(yaws, 6))) == N_VIEWS     # varied headings
    for T, yaw in zip(poses, yaws):      # the robot camera's convention
        np.testing.assert_allclose(T, camera_pose(T[0, 3], T[1, 3], yaw, CAM.height_m), atol=1e-12)


def test_heldout_views_are_deterministic_per_seed_and_stable_across_trajectories(sim):
    r = SIM.robot.radius_m
    a = heldout_views(sim.freespace, r, CAM, N_VIEWS, 0, "tiny-00")
    b = heldout_views(sim.freespace, r, CAM, N_VIEWS, 0, "tiny-00")
    c = heldout_views(sim.freespace, r, CAM, N_VIEWS, 1, "tiny-00")
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a[:, :2, 3], c[:, :2, 3])
    # Views that no trajectory goes near are the same for every trajectory.
    traj = trajectory(sim)
    with_traj = heldout_views(sim.freespace, r, CAM, N_VIEWS, 0, "tiny-00", traj, 0.2)
    far = np.min(np.linalg.norm(a[:, None, :2, 3] - traj[None], axis=2), axis=1) >= 0.2
    n_far = int(far.sum())
    np.testing.assert_array_equal(with_traj[:n_far], a[far])


def test_heldout_views_fail_with_a_clear_error_when_the_trajectory_covers_everything(sim):
    nav = np.argwhere(sim.freespace.navigable(SIM.robot.radius_m))
    everywhere = sim.freespace.cell_to_world(nav)
    with pytest.raises(DagsError, match="min_trajectory_dist_m"):
        heldout_views(sim.freespace, SIM.robot.radius_m, CAM, 5, 0, "tiny-00", everywhere, 0.3)


def test_survey_views_cover_every_lattice_point_with_every_heading(sim):
    xy = free_space_lattice(sim.freespace, SIM.robot.radius_m, 1.0)
    poses = survey_views(sim.freespace, SIM.robot.radius_m, CAM, 1.0, 4)
    assert len(xy) > 3 and poses.shape == (4 * len(xy), 4, 4)
    np.testing.assert_allclose(poses[::4, :2, 3], xy)
    np.testing.assert_allclose([yaw_of(T) for T in poses[:4]], [0.0, math.pi / 2, math.pi, -math.pi / 2], atol=1e-12)


def test_greedy_cover_takes_the_largest_gain_first_and_stops_at_the_fraction():
    feet = [np.array([0, 1, 2, 3]), np.array([0, 1]), np.array([6]), np.array([2, 3, 4, 5]), np.array([], np.int64)]
    chosen, n_cov, total = greedy_cover(feet, 8, 1.0)
    assert chosen.tolist() == [0, 3, 2] and n_cov == total == 7       # point 7 is in no footprint
    chosen, n_cov, _ = greedy_cover(feet, 8, 0.5)                     # 4 of 7 points: one view does
    assert chosen.tolist() == [0] and n_cov == 4
    # Ties go to the lower index, also after a stale gain was re-counted.
    chosen, _, _ = greedy_cover([np.array([0, 1, 2]), np.array([2, 3]), np.array([4, 5])], 6, 1.0)
    assert chosen.tolist() == [0, 2, 1]


def test_covering_survey_shows_what_every_candidate_shows_with_fewer_views(sim):
    gt = sim.surface_samples(4000, np.random.default_rng(3))
    all_poses, n_cand, all_ceiling = covering_survey(sim.renderer, sim.freespace, SIM.robot.radius_m, CAM, 0.5, 8,
                                                     gt, 0.0, 0.05, 0.1, 0.01)
    poses, n_cand2, ceiling = covering_survey(sim.renderer, sim.freespace, SIM.robot.radius_m, CAM, 0.5, 8, gt, 0.99,
                                              0.05, 0.1, 0.01)
    assert n_cand == n_cand2 == len(all_poses) == len(survey_views(sim.freespace, SIM.robot.radius_m, CAM, 0.5, 8))
    assert len(poses) < len(all_poses) / 2
    assert 0.99 * all_ceiling <= ceiling <= all_ceiling and all_ceiling > 0.3   # whole-mesh samples: ceiling, outsides
    # the chosen poses are candidates, and together they show what the ceiling says
    cand = {tuple(np.round(T[:3, 3], 9)) + (round(yaw_of(T), 9),) for T in all_poses}
    assert all(tuple(np.round(T[:3, 3], 9)) + (round(yaw_of(T), 9),) in cand for T in poses)
    shown = np.unique(np.concatenate(view_footprints(sim.renderer, poses, CAM, gt, 0.05, 0.1, 0.01)))
    assert abs(len(shown) - ceiling * len(gt)) <= 0.002 * len(gt)   # per-view vs joint voxel downsampling


def test_ground_truth_renders_are_static_only_even_when_people_are_in_view(sim):
    # A view that looks straight at a person from 1.5-3 m away.
    person = sim.crowd.positions_xy_m[0]
    xy = free_space_lattice(sim.freespace, SIM.robot.radius_m, 0.1)
    dist = np.linalg.norm(xy - person, axis=1)
    xy = xy[(dist > 1.5) & (dist < 3.0)]
    assert len(xy), "the test scene has room to look at a person"
    poses = np.stack([camera_pose(x, y, math.atan2(person[1] - y, person[0] - x), CAM.height_m) for x, y in xy[:5]])
    rgb, depth = ground_truth_renders(sim.renderer, poses, CAM)
    seen_person = False
    for T, rgb_i, depth_i in zip(poses, rgb, depth):
        static = sim.render_static(T)
        np.testing.assert_array_equal(rgb_i, static.rgb)
        np.testing.assert_array_equal(depth_i, static.depth_m)
        live = sim.renderer.render(T, camera_intrinsics(CAM), CAM.width_px, CAM.height_px, people=sim.people_mesh(),
                                   min_depth_m=CAM.min_depth_m, max_depth_m=CAM.max_depth_m)
        if live.people_mask.any():
            seen_person = True
            assert not np.array_equal(live.rgb, rgb_i)     # the person would have shown
    assert seen_person
    assert np.array_equal(camera_intrinsics(CAM), sim.K)
