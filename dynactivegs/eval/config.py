"""Configuration of the evaluation: ground-truth points, reconstruction points, held-out views.

One frozen dataclass; a bad value raises :class:`~dynactivegs.errors.ConfigError` with a
one-line message naming the field.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from dynactivegs.errors import check_config

RECON_METHODS = ("renders", "centres")


@dataclass(frozen=True, slots=True)
class EvalConfig:
    """How a Gaussian map is measured against the static scene (DESIGN.md §6)."""

    # ---------------------------------------------------------------- ground-truth points
    n_gt_points: int = 200_000
    """Number of ground-truth points, uniform over the static surface area a camera at robot height can see."""
    gt_seed: int = 0
    """Seed of the ground-truth surface samples (the same for every run on a scene)."""
    viewpoint_spacing_m: float = 0.5
    """Spacing of the lattice of free-space camera positions from which visibility is tested."""
    visibility_tol_m: float = 0.005
    """A sample is visible from a viewpoint when the first hit towards it is no nearer than this before it."""
    cache_dir: str = ""
    """Directory of the ground-truth point cache; empty: $XDG_CACHE_HOME/dynactivegs or ~/.cache/dynactivegs."""

    # ---------------------------------------------------------------- reconstruction points
    recon_method: str = "renders"
    """How points are taken from a Gaussian map: renders (back-projected depth of renders at survey views,
    where the render is opaque) or centres (centres of opaque Gaussians)."""
    voxel_m: float = 0.01
    """Reconstruction points are reduced to one (the centroid) per voxel of this size."""
    opacity_min: float = 0.5
    """centres: a Gaussian counts when its peak opacity is above this."""
    alpha_min: float = 0.9
    """renders: a pixel counts when the render's accumulated opacity is above this."""
    edge_jump_rel: float = 0.1
    """renders: pixels on a depth edge (a neighbour farther than this x depth, and inverse depth not linear)
    are left out: their expected depth blends two surfaces; 0 keeps them."""
    survey_spacing_m: float = 0.5
    """renders: spacing of the free-space lattice of candidate survey positions (the ground truth's lattice)."""
    survey_yaws: int = 8
    """renders: number of evenly spaced candidate headings at each survey position (8 x 45 deg: every direction
    is seen by two views of a 90 deg camera)."""
    survey_cover: float = 0.995
    """renders: the map is rendered from the fewest candidate views (greedy set cover, computed once per scene
    and cached) from which a perfect map shows this fraction of the ground-truth points it shows from all of
    them; 0 renders every candidate. Measured on the static mesh: from the earlier survey (1 m lattice x 4
    headings) a perfect map showed only 79.2 % of apartment-01's ground truth, so C.R. could not pass that."""

    # ---------------------------------------------------------------- metrics
    cr_threshold_cm: float = 5.0
    """Completion ratio: percentage of ground-truth points with a reconstruction point within this distance."""
    coverage_points: int = 10_000
    """Cheap coverage for progress bars: ground-truth points in the fixed subsample it is measured on."""

    # ---------------------------------------------------------------- held-out views
    n_views: int = 60
    """Number of held-out novel views per scene."""
    view_seed: int = 0
    """Seed of the held-out view poses (per scene: the scene name is part of the stream's key)."""
    min_trajectory_dist_m: float = 0.2
    """A held-out view is at least this far (horizontally) from every position of the robot's trajectory."""
    lpips_weights_path: str = ""
    """Local LPIPS (AlexNet) weights: a torch state dict as saved from ``lpips.LPIPS(net="alex")``; empty: LPIPS is
    reported as n/a."""

    def __post_init__(self) -> None:
        check_config(1 <= self.n_gt_points <= 50_000_000, "eval.n_gt_points", self.n_gt_points, "in [1, 5e7]")
        check_config(0 <= self.gt_seed < 2**63, "eval.gt_seed", self.gt_seed, "in [0, 2^63)")
        check_config(0.05 <= self.viewpoint_spacing_m <= 5.0, "eval.viewpoint_spacing_m", self.viewpoint_spacing_m,
                     "in [0.05, 5] m")
        check_config(0.0 < self.visibility_tol_m <= 0.1, "eval.visibility_tol_m", self.visibility_tol_m,
                     "in (0, 0.1] m")
        check_config(self.recon_method in RECON_METHODS, "eval.recon_method", self.recon_method,
                     "one of " + ", ".join(RECON_METHODS))
        check_config(0.001 <= self.voxel_m <= 0.5, "eval.voxel_m", self.voxel_m, "in [0.001, 0.5] m")
        check_config(0.0 <= self.opacity_min < 1.0, "eval.opacity_min", self.opacity_min, "in [0, 1)")
        check_config(0.0 <= self.alpha_min < 1.0, "eval.alpha_min", self.alpha_min, "in [0, 1)")
        check_config(0.0 <= self.edge_jump_rel < 1.0, "eval.edge_jump_rel", self.edge_jump_rel, "in [0, 1)")
        check_config(0.1 <= self.survey_spacing_m <= 10.0, "eval.survey_spacing_m", self.survey_spacing_m,
                     "in [0.1, 10] m")
        check_config(1 <= self.survey_yaws <= 72, "eval.survey_yaws", self.survey_yaws, "in [1, 72]")
        check_config(0.0 <= self.survey_cover <= 1.0, "eval.survey_cover", self.survey_cover,
                     "in [0, 1] (0: every candidate view)")
        check_config(0.0 < self.cr_threshold_cm <= 100.0, "eval.cr_threshold_cm", self.cr_threshold_cm,
                     "in (0, 100] cm")
        check_config(1 <= self.coverage_points <= 10_000_000, "eval.coverage_points", self.coverage_points,
                     "in [1, 1e7]")
        check_config(1 <= self.n_views <= 100_000, "eval.n_views", self.n_views, "in [1, 1e5]")
        check_config(0 <= self.view_seed < 2**63, "eval.view_seed", self.view_seed, "in [0, 2^63)")
        check_config(0.0 <= self.min_trajectory_dist_m <= 5.0, "eval.min_trajectory_dist_m",
                     self.min_trajectory_dist_m, "in [0, 5] m")

    def resolved_cache_dir(self) -> Path:
        """The cache directory actually used (``cache_dir``, or the user's cache under ``dynactivegs``)."""
        if self.cache_dir:
            return Path(self.cache_dir).expanduser()
        base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        return Path(base) / "dynactivegs"
