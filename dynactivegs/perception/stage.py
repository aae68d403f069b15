"""The perception stage: per-pixel uncertainty beta of each frame (DESIGN.md §5, Perception).

``step`` reads ``rec.frame`` and ``rec.prev_mapping`` and writes :class:`PerceptionOut`.
Order within a step (predict-then-train, one frame behind):

1. features of frame t; the running feature statistics take them in;
2. the MLP trains on frame t-1 against the map's render of frame t-1 (``rec.prev_mapping``,
   rendered from the map before it learnt from frame t-1, so a person who walked into view
   shows up as a residual rather than being half-absorbed into the map already);
3. beta of frame t is predicted with the trained weights.

So beta_t never depends on frame t's own residual, and the step needs nothing from the
mapping stage of the same step, which runs after it and consumes beta_t.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import torch

from dynactivegs.perception.config import FeatureConfig, PerceptionConfig, UncertaintyConfig  # noqa: F401
from dynactivegs.perception.features import FeatureExtractor, make_extractor
from dynactivegs.perception.uncertainty import (UncertaintyState, init_state as init_mlp,
                                                predict, train, with_feature_stats)
from dynactivegs.records import PerceptionOut, StepRecord


@dataclass(frozen=True)
class PerceptionState:
    """The MLP (weights, Adam moments, feature statistics) and the previous frame to train on."""

    mlp: UncertaintyState
    extractor_seed: int                  # seeds the random_conv backend's fixed weights
    prev_feats: torch.Tensor | None      # (C, h, w) features of frame t-1
    prev_rgb: np.ndarray | None          # uint8 (H, W, 3) frame t-1
    prev_depth_m: np.ndarray | None      # float32 (H, W) frame t-1


@lru_cache(maxsize=4)
def extractor_for(cfg: FeatureConfig, seed: int) -> FeatureExtractor:
    """The (deterministic, stateless) feature extractor of a config, built once per process."""
    return make_extractor(cfg, seed)


def init_state(cfg: PerceptionConfig, seed: int) -> PerceptionState:
    """Step 0's state: a fresh MLP drawn from ``seed``; fails early on a bad feature backend."""
    extractor = extractor_for(cfg.features, seed)
    return PerceptionState(init_mlp(cfg.uncertainty, extractor.channels, seed), seed, None, None, None)


def step(cfg: PerceptionConfig, rec: StepRecord, state: PerceptionState,
         rng: np.random.Generator) -> tuple[PerceptionState, PerceptionOut]:
    """Reads ``rec.frame`` and ``rec.prev_mapping``; returns beta of ``rec.frame``."""
    frame = rec.frame
    feats = extractor_for(cfg.features, state.extractor_seed)(frame.rgb)
    mlp = with_feature_stats(cfg.uncertainty, state.mlp, feats)
    loss, trained = float("nan"), False
    prev = rec.prev_mapping
    if prev is not None and state.prev_feats is not None:
        assert prev.render_depth_m.shape == state.prev_depth_m.shape, "prev_mapping does not match the previous frame"
        mlp, loss = train(cfg.uncertainty, mlp, state.prev_feats, state.prev_rgb, state.prev_depth_m,
                          prev.render_rgb.astype(np.float32) / 255.0, prev.render_depth_m, prev.render_alpha, rng)
        trained = not np.isnan(loss)
    # rounded to half precision (11 significant bits, 0.05 %): what is logged is exactly what the
    # later stages read, and the cleared low mantissa bits halve the compressed log
    beta = _half(predict(cfg.uncertainty, mlp, feats, frame.depth_m.shape))
    new_state = PerceptionState(mlp, state.extractor_seed, feats, frame.rgb, frame.depth_m)
    return new_state, PerceptionOut(beta=beta, loss=loss, trained=trained)


def _half(beta: np.ndarray) -> np.ndarray:
    return beta.astype(np.float16).astype(np.float32)


def predict_beta(cfg: PerceptionConfig, state: PerceptionState, rgb: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """beta (float32 ``shape``) of an image under the state's MLP, as :func:`step` would give it now (no training)."""
    feats = extractor_for(cfg.features, state.extractor_seed)(rgb)
    return _half(predict(cfg.uncertainty, state.mlp, feats, shape))
