"""All metrics of a Gaussian map on one scene, and the per-scene state needed to compute them.

:class:`SceneEvaluator` holds what is fixed for a scene (ground-truth points and their
KD-tree, the renderer, free space, survey views, the LPIPS model if any) so that the
metrics at several checkpoints of a run, or for several runs, share it.
:meth:`SceneEvaluator.evaluate` gives a :class:`Metrics`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from dynactivegs.config import SimConfig
from dynactivegs.eval.config import EvalConfig
from dynactivegs.eval.geometry import GroundTruthPoints, Survey, geometry_metrics, ground_truth_points, survey
from dynactivegs.eval.lpips import load_lpips
from dynactivegs.eval.progress import CoverageProbe, ObservedSurface
from dynactivegs.eval.recon import ReconPoints, centre_points, rendered_points
from dynactivegs.eval.rendering import render_metrics
from dynactivegs.eval.views import camera_intrinsics, ground_truth_renders, heldout_views
from dynactivegs.sim.scenes import load_scene, scene_freespace, scene_renderer
from dynactivegs.splat.gaussians import Gaussians
from dynactivegs.splat.render import Backend


@dataclass(frozen=True)
class Metrics:
    """The metrics of one map at one step (DESIGN.md §6). Distances in cm, ratios in %."""

    step: int
    acc_cm: float                 # recon -> visible surface mean distance
    comp_cm: float                # GT -> recon mean nearest distance
    cr_pct: float                 # % of GT points within cr_threshold_cm of the recon
    cr_threshold_cm: float
    recon_method: str             # "renders" or "centres"
    recon_description: str        # how the reconstruction points were extracted
    n_recon_points: int
    n_gt_points: int
    psnr_db: float                # held-out views, mean over views
    ssim: float
    depth_l1_cm: float
    lpips: float | None           # None when LPIPS weights are not available locally
    lpips_note: str               # the weights used, or why LPIPS is n/a
    n_views: int
    psnr_views_db: tuple[float, ...] = ()  # PSNR of each held-out view
    hole_err_pct: float = math.nan         # where the PSNR is lost, mean over views (eval.rendering.psnr_split):
    front_err_pct: float = math.nan        # % of the squared colour error on holes, on surfaces rendered too near,
    behind_err_pct: float = math.nan       # on surfaces rendered too far,
    psnr_right_db: float = math.nan        # and the PSNR of the pixels whose surface is in the right place

    def summary(self) -> str:
        """One line for logs and progress bars."""
        lp = f"LPIPS {self.lpips:.3f}" if self.lpips is not None else f"LPIPS n/a ({self.lpips_note})"
        return (f"step {self.step}: Acc {self.acc_cm:.2f} cm, Comp {self.comp_cm:.2f} cm, "
                f"C.R. {self.cr_pct:.1f} % (<{self.cr_threshold_cm:g} cm) | PSNR {self.psnr_db:.2f} dB, "
                f"SSIM {self.ssim:.3f}, {lp}, depth L1 {self.depth_l1_cm:.2f} cm on {self.n_views} held-out views "
                f"| recon: {self.recon_method}, {self.n_recon_points} pts")


def coverage_probe_of(gt_points_m: np.ndarray, cfg: EvalConfig) -> CoverageProbe:
    """The probe of ``cfg.coverage_points`` of the ground-truth points (N, 3) at the C.R. threshold: coverage and
    the observed surface are measured on it."""
    return CoverageProbe.from_ground_truth(gt_points_m, cfg.coverage_points, cfg.cr_threshold_cm, cfg.gt_seed)


class SceneEvaluator:
    """Metrics of Gaussian maps of one scene. Builds (or loads) the ground truth on construction."""

    def __init__(self, sim: SimConfig, cfg: EvalConfig) -> None:
        self.sim = sim
        self.cfg = cfg
        self.scene = load_scene(sim)
        self.renderer = scene_renderer(self.scene)
        self.freespace = scene_freespace(self.scene, self.renderer, sim.grid_res_m, sim.robot.body_height_m)
        self.gt: GroundTruthPoints = ground_truth_points(sim, cfg)
        self._gt_tree = cKDTree(self.gt.points_m)
        self.K = camera_intrinsics(sim.camera)
        self._survey: Survey | None = None
        self._heldout: tuple[bytes | None, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self.lpips_model, self.lpips_note = load_lpips(cfg.lpips_weights_path)

    @property
    def survey(self) -> Survey:
        """The views the "renders" reconstruction points are extracted from (cached on disk per scene)."""
        if self._survey is None:
            self._survey = survey(self.sim, self.cfg, self.gt, renderer=self.renderer, freespace=self.freespace,
                                  gt_tree=self._gt_tree)
        return self._survey

    @property
    def survey_poses(self) -> np.ndarray:
        """(V, 4, 4) the survey's poses."""
        return self.survey.poses

    def coverage_probe(self) -> CoverageProbe:
        """A probe of ``cfg.coverage_points`` ground-truth points at the C.R. threshold."""
        return coverage_probe_of(self.gt.points_m, self.cfg)

    def observed_surface(self, probe: CoverageProbe | None = None) -> ObservedSurface:
        """An empty :class:`ObservedSurface` of the coverage probe's points (``probe``, when already drawn from
        :meth:`coverage_probe`), with their faces' normals."""
        points = (self.coverage_probe() if probe is None else probe).points_m
        _, i = self._gt_tree.query(points)                 # the probe is a subset of the ground-truth points
        tri = self.scene.triangles_m[self.gt.face_idx[i]]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return ObservedSurface(points, normals=n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))

    def observed_view_pct(self, observed: ObservedSurface, trajectory_xy_m: np.ndarray | None,
                          seen: np.ndarray | None = None) -> float:
        """The share (%) of the held-out views' pixels (of the views :meth:`evaluate` renders for this
        trajectory) showing surface that ``observed`` (from :meth:`observed_surface`) has seen
        (:meth:`ObservedSurface.view_share`; ``seen``: a mask of its points instead of what it saw so far)."""
        poses, _, depth = self.heldout(trajectory_xy_m)
        return observed.view_share(poses, depth, self.K, seen)

    def recon_points(self, gaussians: Gaussians, method: str | None = None, backend: Backend = "auto") -> ReconPoints:
        """Reconstruction points of the map by ``method`` (default ``cfg.recon_method``)."""
        method = self.cfg.recon_method if method is None else method
        if method == "centres":
            return centre_points(gaussians, opacity_min=self.cfg.opacity_min, voxel_m=self.cfg.voxel_m)
        assert method == "renders", f"unknown reconstruction method {method!r}"
        cam = self.sim.camera
        return rendered_points(gaussians, self.survey_poses, self.K, cam.width_px, cam.height_px,
                               alpha_min=self.cfg.alpha_min, edge_jump_rel=self.cfg.edge_jump_rel,
                               voxel_m=self.cfg.voxel_m, backend=backend, near_plane=cam.min_depth_m,
                               views_note=self.survey.note())

    def heldout(self, trajectory_xy_m: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Held-out poses (V, 4, 4) away from the trajectory (T, 2), and their static-only rgb and depth.
        Those of the last trajectory asked for are kept and returned again (shared: do not write to them): a run's
        checkpoints measure the map, the refined map and the observed surface on the same views."""
        key = None if trajectory_xy_m is None else np.ascontiguousarray(trajectory_xy_m, np.float64).tobytes()
        if self._heldout is None or self._heldout[0] != key:
            poses = heldout_views(self.freespace, self.sim.robot.radius_m, self.sim.camera, self.cfg.n_views,
                                  self.cfg.view_seed, self.scene.name, trajectory_xy_m,
                                  self.cfg.min_trajectory_dist_m)
            rgb, depth = ground_truth_renders(self.renderer, poses, self.sim.camera)
            self._heldout = (key, (poses, rgb, depth))
        return self._heldout[1]

    def evaluate(self, gaussians: Gaussians, *, step: int, trajectory_xy_m: np.ndarray | None,
                 method: str | None = None, backend: Backend = "auto") -> Metrics:
        """All metrics of the map: geometry against the ground-truth points, rendering on held-out views.

        ``trajectory_xy_m`` (T, 2): the robot positions the map was built from; held-out views
        keep ``cfg.min_trajectory_dist_m`` away from them.
        """
        rec = self.recon_points(gaussians, method, backend)
        geo = geometry_metrics(rec.points_m, self.gt.points_m, self.cfg.cr_threshold_cm, gt_tree=self._gt_tree,
                               gt_faces=self.gt.face_idx, triangles_m=self.scene.triangles_m)
        poses, rgb, depth = self.heldout(trajectory_xy_m)
        ren = render_metrics(gaussians, poses, rgb, depth, self.K, lpips_model=self.lpips_model,
                             lpips_note=self.lpips_note, backend=backend, near_plane=self.sim.camera.min_depth_m)
        return Metrics(step=step, acc_cm=geo.acc_cm, comp_cm=geo.comp_cm, cr_pct=geo.cr_pct,
                       cr_threshold_cm=geo.cr_threshold_cm, recon_method=rec.method,
                       recon_description=rec.description, n_recon_points=geo.n_recon, n_gt_points=geo.n_gt,
                       psnr_db=ren.psnr_db, ssim=ren.ssim, depth_l1_cm=ren.depth_l1_cm, lpips=ren.lpips,
                       lpips_note=ren.lpips_note, n_views=ren.n_views, psnr_views_db=ren.psnr_views_db,
                       hole_err_pct=ren.hole_err_pct, front_err_pct=ren.front_err_pct,
                       behind_err_pct=ren.behind_err_pct, psnr_right_db=ren.psnr_right_db)
