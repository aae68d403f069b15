"""Perception + mapping along a scripted robot tour, with the quality measures of issue 4.

The robot follows :class:`~dynactivegs.sim.scripted.ScriptedDriver` (ground-truth free space,
not the method's planner), so the map's quality can be measured apart from exploration:
beta against the simulator's people masks (AUROC), ghosts on people's paths, and PSNR of
static renders at held-out poses (the trajectory's poses turned by a fixed yaw offset, which
the robot never looked from).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from dynactivegs.config import SimConfig
from dynactivegs.eval.classification import auroc
from dynactivegs.eval.ghosts import count_ghosts
from dynactivegs.eval.rendering import psnr_db
from dynactivegs.mapping import stage as mapping
from dynactivegs.perception import stage as perception
from dynactivegs.records import StepRecord
from dynactivegs.rng import derive_rng
from dynactivegs.records import RobotPose2D
from dynactivegs.sim.scripted import ScriptedDriver
from dynactivegs.sim.world import Simulator


@dataclass(frozen=True)
class TourResult:
    auroc: float                  # beta vs people mask over valid pixels after the warm-up
    ghosts: int
    psnr_db: float                # mean over held-out poses, static-only ground truth
    n_gaussians: int
    perception_s: float           # mean seconds per step
    mapping_s: float
    betas: list = field(repr=False, default_factory=list)


def run_tour(sim_cfg: SimConfig, perc_cfg: perception.PerceptionConfig, map_cfg: mapping.MappingConfig, steps: int,
             seed: int = 0, warmup: int = 30, heldout_every: int = 10, heldout_yaw_deg: float = 25.0) -> TourResult:
    """Runs the two stages for ``steps`` steps on a scripted tour and measures them."""
    sim = Simulator(sim_cfg, seed)
    drv = ScriptedDriver(sim.freespace, sim_cfg.robot.radius_m, derive_rng(seed, "driver"))
    p_state = perception.init_state(perc_cfg, seed)
    m_state = mapping.init_state(map_cfg)
    prev_map = None
    scores, labels = [], []
    track_xy, track_h, poses = [], [], []
    t_p = t_m = 0.0
    frame, truth = sim.observation()
    for k in range(steps):
        rec = StepRecord(frame=frame, prev_mapping=prev_map)
        t0 = time.perf_counter()
        p_state, p_out = perception.step(perc_cfg, rec, p_state, derive_rng(seed, k, 0))
        t1 = time.perf_counter()
        rec = StepRecord(frame=frame, prev_mapping=prev_map, perception=p_out)
        m_state, m_out = mapping.step(map_cfg, rec, m_state, derive_rng(seed, k, 1))
        t_p += t1 - t0
        t_m += time.perf_counter() - t1
        prev_map = m_out
        if k >= warmup:
            valid = frame.depth_m > 0
            scores.append(p_out.beta[valid])
            labels.append(truth.people_mask[valid])
        track_xy.append(truth.people_xy_m)
        track_h.append(truth.people_height_m)
        poses.append(truth.robot)
        frame, truth = sim.step(drv.act(truth.robot.x_m, truth.robot.y_m, truth.robot.yaw_rad, truth.collided))

    g = m_state.gaussians
    surf = sim.surface_samples(400_000, derive_rng(seed, "ghost-surface"))
    ghosts = count_ghosts(g.means.detach().cpu().double().numpy(), g.opacities.detach().cpu().double().numpy(),
                          surf, np.concatenate(track_xy), np.concatenate(track_h))
    psnrs = []
    for i, pose in enumerate(poses[::heldout_every]):
        turned = RobotPose2D(pose.x_m, pose.y_m, pose.yaw_rad + math.radians(heldout_yaw_deg * (1 if i % 2 else -1)))
        T = sim.camera_pose(turned)
        gt = sim.render_static(T)
        rgb, _, _ = mapping.render_view(map_cfg, g, sim.K, T, sim_cfg.camera.width_px, sim_cfg.camera.height_px)
        psnrs.append(psnr_db(rgb, gt.rgb))
    y = np.concatenate(labels) if labels else np.zeros(0, bool)
    a = auroc(np.concatenate(scores), y) if labels else float("nan")
    return TourResult(a, ghosts, float(np.mean(psnrs)), len(g), t_p / steps, t_m / steps)
