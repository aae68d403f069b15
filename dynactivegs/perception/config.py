"""Configuration of the perception stage (torch-free, so that ``dynactivegs.config`` can import it)."""

from __future__ import annotations

from dataclasses import dataclass, field

from dynactivegs.errors import ConfigError

BACKENDS = ("filters", "random_conv", "dinov2")


@dataclass(frozen=True, slots=True)
class FeatureConfig:
    """Which feature extractor perception uses."""

    backend: str = "filters"
    """filters (built-in, default), random_conv (seeded random CNN) or dinov2 (local checkpoint)."""
    stride: int = 4
    """Output stride of the filter banks (the ViT's patch size sets it for dinov2)."""
    checkpoint_dir: str = ""
    """dinov2: a local directory holding a transformers checkpoint (config.json + model.safetensors)."""

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ConfigError(f"unknown feature backend {self.backend!r}: use one of {', '.join(BACKENDS)}")
        if not 1 <= self.stride <= 32:
            raise ConfigError(f"bad config value perception.features.stride={self.stride}: must be in [1, 32]")


@dataclass(frozen=True, slots=True)
class UncertaintyConfig:
    """The uncertainty MLP and its online training."""

    hidden: int = 64
    """Width of the two hidden layers."""
    lr: float = 3e-3
    """Adam learning rate."""
    iters_per_frame: int = 10
    """Adam steps on each new frame."""
    beta_min: float = 0.1
    """beta = max(u, beta_min) + 1e-3."""
    appearance_weight: float = 0.25
    """w_a: weight of the SSIM residual term."""
    depth_weight: float = 1.0
    """w_d: weight of the depth residual term."""
    depth_clip: float = 1.0
    """Depth residuals (relative, see depth_relative) are clipped at this value."""
    depth_relative: bool = True
    """Depth residual relative to the observed depth, |D - D^| / D, rather than in metres."""
    reg_weight: float = 1.0
    """w_reg: weight of the feature-similarity variance regulariser."""
    sim_threshold: float = 0.9
    """Cosine similarity above which two feature cells count as alike."""
    n_anchors: int = 32
    """Anchor cells per step for the regulariser."""
    min_alpha: float = 0.9
    """The loss only uses pixels where the map's accumulated opacity exceeds this."""
    stale_margin_m: float = 0.1
    """Pixels where the map's surface is this far (m) in front of the observed one ..."""
    stale_margin_rel: float = 0.05
    """... plus this fraction of the observed depth are left out of the loss (stale map content)."""
    stats_momentum: float = 0.05
    """EMA momentum of the running feature mean / variance."""

    def __post_init__(self) -> None:
        for name, ok, allowed in [("hidden", self.hidden >= 4, ">= 4"), ("lr", self.lr > 0, "> 0"),
                                  ("iters_per_frame", self.iters_per_frame >= 0, ">= 0"),
                                  ("beta_min", self.beta_min > 0, "> 0"),
                                  ("depth_weight", self.depth_weight >= 0, ">= 0"),
                                  ("depth_clip", self.depth_clip > 0, "> 0"),
                                  ("appearance_weight", self.appearance_weight >= 0, ">= 0"),
                                  ("reg_weight", self.reg_weight >= 0, ">= 0"),
                                  ("sim_threshold", -1 <= self.sim_threshold <= 1, "in [-1, 1]"),
                                  ("n_anchors", self.n_anchors >= 1, ">= 1"),
                                  ("min_alpha", 0 <= self.min_alpha < 1, "in [0, 1)"),
                                  ("stats_momentum", 0 < self.stats_momentum <= 1, "in (0, 1]")]:
            if not ok:
                raise ConfigError(f"bad config value perception.uncertainty.{name}={getattr(self, name)!r}: "
                                  f"must be {allowed}")


@dataclass(frozen=True, slots=True)
class PerceptionConfig:
    """Features and the uncertainty predictor."""

    features: FeatureConfig = field(default_factory=FeatureConfig)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)
