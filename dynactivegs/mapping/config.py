"""Configuration of the mapping stage (torch-free, so that ``dynactivegs.config`` can import it).

See :mod:`dynactivegs.mapping.stage` for what each value does.
"""

from __future__ import annotations

from dataclasses import dataclass

from dynactivegs.errors import check_config

@dataclass(frozen=True, slots=True)
class MappingConfig:
    """The Gaussian map and its online optimisation."""

    weighted: bool = True
    """Weight the loss by 1 / beta^2 and never seed Gaussians from uncertain pixels (off: the 'no weighted mapping' ablation)."""
    iters: int = 6
    """Adam iterations per step."""
    color_weight: float = 1.0
    """l1: weight of L_color."""
    depth_weight: float = 2.5
    """l2: weight of L_depth (metres)."""
    iso_weight: float = 10.0
    """l3: weight of the isotropy regulariser L_iso (metres)."""
    alpha_weight: float = 0.5
    """l_a: weight of the silhouette term (1 - alpha) on pixels with a depth return."""
    ssim_weight: float = 0.2
    """Share of (1 - SSIM) in L_color."""
    ref_percentile: float = 20.0
    """The frame's reference beta b_ref is this percentile of its beta; weights are (b_ref / max(beta, b_ref))^2."""
    seed_beta_ratio: float = 2.0
    """With weighting on, pixels with beta above this times b_ref never seed new Gaussians, and never carve.
    At 1.5 most static texture went unseeded: replaying full's logged apartment runs from mapping at 2
    (benchmarks/results/openloop-seed-beta-ratio) raised Acc, C.R. and PSNR in every run tried
    (apartment-03 seed 0: 2.74 cm / 92.1 % / 24.06 dB -> 2.42 / 93.0 / 24.26). Higher ratios gain more
    in the open loop but let people seed: on the scripted tour with the static vote off, 3 left 0.48 x
    the unweighted map's ghosts, 2 left 0.17 x. In closed loop (benchmarks/results/apartment-1000-seedgate,
    12 pairs) 2 and 1.5 could not be told apart: full 2.96 / 90.0 / 23.15 against 3.14 / 89.9 / 23.24; 3 against 2
    (benchmarks/results/apartment-1000-seedratio, 8 pairs): 3.37 / 90.5 / 23.75 against 2.77 / 91.6 / 23.19, the
    PSNR from one pair's path and Acc worse in 6 of 8."""
    drop_beta_ratio: float = 0.0
    """With weighting on, pixels with beta above this times b_ref get weight 0 instead of (b_ref / beta)^2;
    0 (the default): never, the paper's weights as they are. See the mapping stage's docstring."""
    densify_stride: int = 2
    """New Gaussians are seeded from every densify_stride-th pixel (both directions)."""
    densify_alpha: float = 0.7
    """Pixels where the render's accumulated opacity is below this get new Gaussians."""
    densify_depth_rel: float = 0.1
    """... and pixels observed in front of the map's surface by more than this fraction of their depth."""
    init_opacity: float = 0.6
    """Peak opacity of a new Gaussian."""
    init_scale: float = 0.5
    """A new Gaussian's standard deviation is this times the footprint of densify_stride pixels at its depth."""
    max_gaussians: int = 100_000
    """Cap on the map's size; densification stops there. A memory guard, not a resolution: at 60 000, baseline
    maps of 1000-step apartment runs hit it by step 500 in 5 of 8 runs and the rooms explored later got no
    Gaussians (apartment-01/03 seed 0: Acc 3.31/3.43 cm at 60 000, 2.55/2.44 at 100 000, with 81-86k Gaussians
    and no slower steps); full's maps ended below 63k either way (benchmarks/results/apartment-1000-cap)."""
    keyframe_every: int = 3
    """Every k-th frame becomes a keyframe."""
    window: int = 6
    """Optimisation views come from the last this-many keyframes ..."""
    random_older: int = 4
    """... and this many random older keyframes (drawn anew each step)."""
    prune_every: int = 5
    """Prune every this-many steps."""
    prune_opacity: float = 0.05
    """Gaussians below this opacity are pruned."""
    prune_scale_m: float = 0.5
    """Gaussians whose largest standard deviation exceeds this (m) are pruned."""
    carve_margin_m: float = 0.1
    """Free-space carving: a Gaussian must lie this far (m) in front of the observed depth ..."""
    carve_margin_rel: float = 0.05
    """... plus this fraction of the depth, plus twice its largest scale, to be removed."""
    vote_every: int = 10
    """Every this-many steps, every Gaussian is tested against all keyframes (the free-space vote); 0: never."""
    vote_min_free: int = 2
    """The vote removes a Gaussian that at least this many keyframes see through, and more of them than show
    a return at its depth."""
    surface_voxel_m: float = 0.15
    """Edge of the voxels of MappingOut.surface_ijk."""
    surface_opacity: float = 0.5
    """Gaussians at least this opaque count as surface in MappingOut.surface_ijk."""
    lr_means: float = 1e-3
    """Adam learning rate of the centres (m)."""
    lr_log_scales: float = 5e-3
    """Adam learning rate of the log scales."""
    lr_quats: float = 2e-3
    """Adam learning rate of the (unnormalised) quaternions."""
    lr_opacity: float = 5e-2
    """Adam learning rate of the opacity logits."""
    lr_sh0: float = 1e-2
    """Adam learning rate of the colour coefficients. Against 2e-2 (measured with the CPU rasterizer): on a
    200-step scripted tour of apartment-00 held-out PSNR 22.19 -> 22.67 dB, beta's AUROC 0.949 -> 0.956,
    ghosts 711 -> 387 (on apartment-02 seed 1, 300 steps: 23.12 -> 23.29 dB); 3 refinement passes from four
    logged 1000-step maps gave +0.18 to +0.25 dB. Colours that chase the current frame fit the other views
    worse; 5e-3 gave little more (+0.09 dB on the first tour, -0.02 dB on one map). In the closed loop
    (benchmarks/results/apartment-1000-colour-lr, 12 pairs) full's held-out PSNR was 0.46 dB above the same pairs
    at 2e-2, with other paths."""
    refine_passes: float = 3.0
    """Offline refinement after the step budget (DESIGN.md §5): this many passes over all keyframes, one Adam
    step per keyframe per pass (:func:`dynactivegs.mapping.stage.refine_iters`); 0: none. More passes buy little:
    benchmarks/refine_passes.py on full, apartment-00, seed 0, 1000 steps (334 keyframes; Acc cm / C.R. % / PSNR
    dB): 3 passes 2.88 / 90.12 / 23.83 (79 s), 6 passes 2.92 / 90.14 / 23.87 (170 s), 10 passes 3.02 / 90.16 /
    23.93 (300 s)."""
    refine_beta: str = "logged"
    """The beta that weights a keyframe in the offline refinement (with ``weighted``): ``logged``, the one
    perception gave it when it was taken, or ``final``, the one the uncertainty MLP predicts for it after the
    last step. A static surface seen for the first time has a high logged beta (the map did not fit it yet);
    the final MLP, trained on residuals against the finished map, keeps a high beta for people only.
    Measured on one run's final state (full, apartment-02, seed 1, 1000 steps; Acc cm / C.R. % / PSNR dB of
    the refined map): logged 2.81 / 90.46 / 21.89, final 2.90 / 89.91 / 21.89. Not a gain: logged stays."""
    refine_densify: bool = False
    """Before the refinement's Adam passes, each keyframe in turn adds Gaussians where the map leaves a hole
    in its view or lies behind what it saw (the online densification, step 2, with the keyframe's beta as
    refine_beta says): surfaces glimpsed only while their beta was high never seeded online. Measured on the
    run of refine_beta's note: 65.7k -> 72.4k Gaussians, 2.90 / 90.30 / 21.89 (with refine_beta=final: 74.4k,
    3.02 / 90.09 / 22.01), against 2.81 / 90.46 / 21.89 without: the holes' share of the PSNR error fell from
    15.2 to 14.4 % but Acc got worse. Off."""
    device: str = "cpu"
    """cpu (the numba rasterizer) or cuda (gsplat; needs the [cuda] extra)."""

    def __post_init__(self) -> None:
        c = check_config
        c(self.iters >= 0, "mapping.iters", self.iters, ">= 0")
        for name in ("color_weight", "depth_weight", "iso_weight", "alpha_weight"):
            c(getattr(self, name) >= 0, f"mapping.{name}", getattr(self, name), ">= 0")
        c(0 <= self.ssim_weight <= 1, "mapping.ssim_weight", self.ssim_weight, "in [0, 1]")
        c(0 <= self.ref_percentile <= 100, "mapping.ref_percentile", self.ref_percentile, "in [0, 100]")
        c(self.seed_beta_ratio >= 1, "mapping.seed_beta_ratio", self.seed_beta_ratio, ">= 1")
        c(self.drop_beta_ratio == 0 or self.drop_beta_ratio >= 1, "mapping.drop_beta_ratio", self.drop_beta_ratio,
          "0 (off) or >= 1")
        c(1 <= self.densify_stride <= 16, "mapping.densify_stride", self.densify_stride, "in [1, 16]")
        c(0 < self.densify_alpha <= 1, "mapping.densify_alpha", self.densify_alpha, "in (0, 1]")
        c(self.densify_depth_rel > 0, "mapping.densify_depth_rel", self.densify_depth_rel, "> 0")
        c(0 < self.init_opacity < 1, "mapping.init_opacity", self.init_opacity, "in (0, 1)")
        c(0.05 <= self.init_scale <= 4, "mapping.init_scale", self.init_scale, "in [0.05, 4]")
        c(self.max_gaussians >= 1, "mapping.max_gaussians", self.max_gaussians, ">= 1")
        c(self.keyframe_every >= 1, "mapping.keyframe_every", self.keyframe_every, ">= 1")
        c(self.window >= 1, "mapping.window", self.window, ">= 1")
        c(self.random_older >= 0, "mapping.random_older", self.random_older, ">= 0")
        c(self.prune_every >= 1, "mapping.prune_every", self.prune_every, ">= 1")
        c(0 <= self.prune_opacity < 1, "mapping.prune_opacity", self.prune_opacity, "in [0, 1)")
        c(self.prune_scale_m > 0, "mapping.prune_scale_m", self.prune_scale_m, "> 0")
        c(self.carve_margin_m >= 0, "mapping.carve_margin_m", self.carve_margin_m, ">= 0")
        c(self.carve_margin_rel >= 0, "mapping.carve_margin_rel", self.carve_margin_rel, ">= 0")
        c(self.vote_every >= 0, "mapping.vote_every", self.vote_every, ">= 0 (0 turns the vote off)")
        c(self.vote_min_free >= 1, "mapping.vote_min_free", self.vote_min_free, ">= 1")
        c(0.02 <= self.surface_voxel_m <= 2, "mapping.surface_voxel_m", self.surface_voxel_m, "in [0.02, 2] m")
        c(0 < self.surface_opacity < 1, "mapping.surface_opacity", self.surface_opacity, "in (0, 1)")
        for name in ("lr_means", "lr_log_scales", "lr_quats", "lr_opacity", "lr_sh0"):
            c(getattr(self, name) > 0, f"mapping.{name}", getattr(self, name), "> 0")
        c(0 <= self.refine_passes <= 100, "mapping.refine_passes", self.refine_passes, "in [0, 100] (0: no refinement)")
        c(self.refine_beta in ("logged", "final"), "mapping.refine_beta", self.refine_beta, "logged or final")
        c(self.device in ("cpu", "cuda"), "mapping.device", self.device, "cpu or cuda")

    @property
    def lrs(self) -> tuple[float, ...]:
        """Learning rates in the order of :meth:`Gaussians.tensors`."""
        return (self.lr_means, self.lr_log_scales, self.lr_quats, self.lr_opacity, self.lr_sh0)
