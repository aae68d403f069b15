"""Per-pixel uncertainty beta: a small MLP on image features, trained online against the map's renders.

Model (DESIGN.md §5, Perception). Features ``F (C, h, w)`` at stride ``s`` are standardised
with running statistics and mapped by an MLP ``C -> 64 -> 64 -> 1`` with a softplus output
``u``; ``beta = max(u, beta_min) + 1e-3``, bilinearly upsampled to the image. (In training the
floor passes gradients straight through; see :func:`beta_lowres`.)

Loss, following the appearance + depth consistency loss of NeRF On-the-go and WildGS-SLAM.
With the observed frame ``(I, D)``, the map's render at the same pose ``(I^, D^, A^)``
(colour, expected depth, accumulated opacity) and the mask
``M = (A^ > min_alpha) & (D > 0) & (D^ > 0) & ~stale`` (only where the map is already opaque,
and not where the map shows a surface clearly in front of the observed one:
``stale = D^ < D - stale_margin_m - stale_margin_rel * D``, a stale object such as a person who
has walked on, which mapping carves out at this step; its residual says nothing about what
the pixel shows now, and training on it would teach the predictor that the static surface
behind a departed person is uncertain), the loss minimised over the MLP's weights is

    L = w_a * mean_M[ r_ssim / beta^2 ]               (1) appearance residual
      + w_d * mean_M[ r_depth / beta^2 ]              (2) depth residual
      + 0.5 * mean_M[ log beta ]                      (3) keeps beta from growing without bound
      + w_reg * L_reg                                 (4) feature-similarity regulariser

- ``r_ssim = clip((1 - SSIM(I, I^)) / 2, 0, 1)``, SSIM computed per pixel in a 7x7 Gaussian window
  (sigma 1.5 px) and averaged over RGB; it does not depend on beta, so it is computed once per frame.
- ``r_depth = min(|D - D^| / D, depth_clip)``, relative to the observed depth (``depth_relative``;
  in metres when off): a person 1 m in front of a wall 4 m away and 0.5 m in front of one 2 m
  away are equally surprising, and the far, poorly observed parts of the map do not dominate.
- For a fixed residual ``r`` the data terms ``r / beta^2 + 0.5 log beta`` are minimised at
  ``beta = 2 sqrt(r)``: beta grows where the map cannot explain the frame (moving people).
- ``L_reg``: for ``n_anchors`` random feature cells (drawn from the run's rng), the variance of
  beta over all cells whose features have cosine similarity above ``sim_threshold`` to the
  anchor, averaged over anchors. Pixels that look alike get similar uncertainty, which spreads
  a high beta from the residual pixels of a person to the rest of that person.

Only the MLP is trained by this loss; the renders are treated as constants. The state (MLP
weights, Adam moments, feature statistics) is explicit, so a run can be replayed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from dynactivegs.perception.config import UncertaintyConfig  # noqa: F401  (re-exported)
from dynactivegs.splat.losses import ssim_map


@dataclass(frozen=True)
class UncertaintyState:
    """Everything the predictor keeps between frames."""

    params: tuple[torch.Tensor, ...]      # W1 (C, H), b1 (H,), W2 (H, H), b2 (H,), W3 (H, 1), b3 (1,)
    adam_m: tuple[torch.Tensor, ...]      # first moments, like params
    adam_v: tuple[torch.Tensor, ...]      # second moments, like params
    adam_t: int                           # Adam steps taken
    feat_mean: torch.Tensor               # (C,) running feature mean
    feat_var: torch.Tensor                # (C,) running feature variance
    frames_seen: int


def init_state(cfg: UncertaintyConfig, channels: int, seed: int) -> UncertaintyState:
    """He-initialised MLP weights drawn from ``seed``; the output bias starts beta near beta_min."""
    g = torch.Generator().manual_seed(seed)
    h = cfg.hidden

    def he(fan_in: int, fan_out: int) -> torch.Tensor:
        return torch.randn(fan_in, fan_out, generator=g) * (2.0 / fan_in) ** 0.5

    params = (he(channels, h), torch.zeros(h), he(h, h), torch.zeros(h), he(h, 1) * 0.1, torch.full((1,), -2.0))
    zeros = tuple(torch.zeros_like(p) for p in params)
    return UncertaintyState(params, zeros, zeros, 0, torch.zeros(channels), torch.ones(channels), 0)


def _mlp(params: tuple[torch.Tensor, ...], x: torch.Tensor) -> torch.Tensor:
    """x (N, C) -> u (N,) >= 0 (softplus output)."""
    w1, b1, w2, b2, w3, b3 = params
    z = F.relu(x @ w1 + b1)
    z = F.relu(z @ w2 + b2)
    return F.softplus(z @ w3 + b3)[:, 0]


def _standardise(feats: torch.Tensor, mean: torch.Tensor, var: torch.Tensor) -> torch.Tensor:
    """(C, h, w) -> (h*w, C) standardised feature rows."""
    c = feats.shape[0]
    x = feats.reshape(c, -1).T
    return (x - mean) / torch.sqrt(var + 1e-6)


def beta_lowres(cfg: UncertaintyConfig, params: tuple[torch.Tensor, ...], x: torch.Tensor,
                hw: tuple[int, int]) -> torch.Tensor:
    """beta at feature resolution (h, w) from standardised feature rows x (h*w, C)."""
    u = _mlp(params, x)
    # Forward value max(u, beta_min); the gradient passes straight through the floor. A hard
    # clamp has zero gradient below the floor, and the log-beta term (3) pushes every static
    # pixel there, after which no pixel could ever become uncertain again.
    floored = u + (cfg.beta_min - u).clamp(min=0.0).detach()
    return (floored + 1e-3).reshape(hw)


def upsample(beta_hw: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """Bilinear upsampling of (h, w) to the image size (H, W)."""
    return F.interpolate(beta_hw[None, None], size=size, mode="bilinear", align_corners=False)[0, 0]


def residuals(rgb: np.ndarray, depth_m: np.ndarray, rgb_hat: np.ndarray, depth_hat_m: np.ndarray,
              alpha_hat: np.ndarray, cfg: UncertaintyConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(r_ssim (H, W), r_depth (H, W), mask (H, W) bool) of a frame against the map's render.

    ``rgb`` uint8 (H, W, 3); ``rgb_hat`` float (H, W, 3) in [0, 1]; depths in metres (0 = none);
    ``alpha_hat`` (H, W) accumulated opacity of the render.
    """
    assert rgb.shape[:2] == depth_m.shape == depth_hat_m.shape == alpha_hat.shape == rgb_hat.shape[:2]
    i = torch.tensor(rgb).float() / 255.0
    i_hat = torch.tensor(rgb_hat, dtype=torch.float32).clamp(0, 1)
    ssim = ssim_map(i, i_hat, window=7, sigma=1.5)
    r_ssim = ((1.0 - ssim) / 2.0).clamp(0.0, 1.0)
    d = torch.tensor(depth_m, dtype=torch.float32)
    d_hat = torch.tensor(depth_hat_m, dtype=torch.float32)
    r_depth = (d - d_hat).abs()
    if cfg.depth_relative:
        r_depth = r_depth / d.clamp(min=1e-3)
    r_depth = r_depth.clamp(max=cfg.depth_clip)
    stale = d_hat < d - cfg.stale_margin_m - cfg.stale_margin_rel * d
    mask = (torch.tensor(alpha_hat) > cfg.min_alpha) & (d > 0) & (d_hat > 0) & ~stale
    return r_ssim, r_depth, mask


def loss_terms(cfg: UncertaintyConfig, params: tuple[torch.Tensor, ...], x: torch.Tensor, hw: tuple[int, int],
               r_ssim: torch.Tensor, r_depth: torch.Tensor, mask: torch.Tensor,
               anchors: torch.Tensor, similar: torch.Tensor) -> dict[str, torch.Tensor]:
    """The four loss terms of the module docstring (each a scalar tensor) and their sum ``total``."""
    beta_lo = beta_lowres(cfg, params, x, hw)
    beta = upsample(beta_lo, tuple(r_ssim.shape))[mask]
    inv2 = 1.0 / beta ** 2
    terms = {
        "appearance": cfg.appearance_weight * (r_ssim[mask] * inv2).mean(),  # (1)
        "depth": cfg.depth_weight * (r_depth[mask] * inv2).mean(),          # (2)
        "log_beta": 0.5 * torch.log(beta).mean(),                           # (3)
    }
    b = beta_lo.reshape(-1)
    w = similar.float()                                                     # (K, N) alike-cells mask
    mean_k = (w * b).sum(1) / w.sum(1)
    var_k = (w * (b[None] - mean_k[:, None]) ** 2).sum(1) / w.sum(1)
    terms["similarity"] = cfg.reg_weight * var_k.mean()                     # (4)
    terms["total"] = terms["appearance"] + terms["depth"] + terms["log_beta"] + terms["similarity"]
    return terms


def _adam(params, grads, m, v, t: int, lr: float, b1: float = 0.9, b2: float = 0.999, eps: float = 1e-8):
    m = tuple(b1 * mi + (1 - b1) * g for mi, g in zip(m, grads))
    v = tuple(b2 * vi + (1 - b2) * g * g for vi, g in zip(v, grads))
    c1, c2 = 1 - b1 ** t, 1 - b2 ** t
    params = tuple(p - lr * (mi / c1) / (torch.sqrt(vi / c2) + eps) for p, mi, vi in zip(params, m, v))
    return params, m, v


def with_feature_stats(cfg: UncertaintyConfig, state: UncertaintyState, feats: torch.Tensor) -> UncertaintyState:
    """The state with its running feature mean / variance updated by one feature map (C, h, w)."""
    c = feats.shape[0]
    mom = cfg.stats_momentum if state.frames_seen else 1.0
    flat = feats.reshape(c, -1)
    mean = (1 - mom) * state.feat_mean + mom * flat.mean(1)
    var = (1 - mom) * state.feat_var + mom * flat.var(1, unbiased=False)
    return UncertaintyState(state.params, state.adam_m, state.adam_v, state.adam_t, mean, var, state.frames_seen + 1)


@torch.no_grad()
def predict(cfg: UncertaintyConfig, state: UncertaintyState, feats: torch.Tensor, size: tuple[int, int]) -> np.ndarray:
    """float32 (H, W) beta of a frame from its features (C, h, w), with the state's weights and statistics."""
    c, h, w = feats.shape
    x = _standardise(feats, state.feat_mean, state.feat_var)
    return upsample(beta_lowres(cfg, state.params, x, (h, w)), size).numpy().astype(np.float32)


def train(cfg: UncertaintyConfig, state: UncertaintyState, feats: torch.Tensor, rgb: np.ndarray,
          depth_m: np.ndarray, rgb_hat: np.ndarray, depth_hat_m: np.ndarray, alpha_hat: np.ndarray,
          rng: np.random.Generator) -> tuple[UncertaintyState, float]:
    """``cfg.iters_per_frame`` Adam steps of the loss above on one frame and the map's render of it.

    ``feats`` (C, h, w); other arrays as in :func:`residuals`. Returns the new state and the
    total loss at the last iteration (nan, and the state unchanged, when fewer than 16 pixels
    are usable, e.g. while the map is still empty).
    """
    c, h, w = feats.shape
    x = _standardise(feats, state.feat_mean, state.feat_var)
    r_ssim, r_depth, mask = residuals(rgb, depth_m, rgb_hat, depth_hat_m, alpha_hat, cfg)
    if int(mask.sum()) < 16 or cfg.iters_per_frame == 0:
        return state, float("nan")
    params, m, v, t = state.params, state.adam_m, state.adam_v, state.adam_t
    xn = F.normalize(x, dim=1)
    anchors = torch.from_numpy(rng.choice(h * w, size=min(cfg.n_anchors, h * w), replace=False))
    similar = (xn[anchors] @ xn.T) > cfg.sim_threshold                  # (K, h*w), includes the anchor
    loss = float("nan")
    for _ in range(cfg.iters_per_frame):
        p = tuple(q.detach().requires_grad_(True) for q in params)
        terms = loss_terms(cfg, p, x, (h, w), r_ssim, r_depth, mask, anchors, similar)
        grads = torch.autograd.grad(terms["total"], p)
        t += 1
        params, m, v = _adam(tuple(q.detach() for q in p), grads, m, v, t, cfg.lr)
        loss = float(terms["total"].detach())
    return UncertaintyState(params, m, v, t, state.feat_mean, state.feat_var, state.frames_seen), loss


@dataclass(frozen=True)
class UncertaintyStep:
    state: UncertaintyState
    beta: np.ndarray               # float32 (H, W), the frame's uncertainty after this step's training
    beta_before: np.ndarray        # float32 (H, W), predicted before training on this frame
    loss: float                    # total loss at the last training iteration (nan if nothing to train on)


def update(cfg: UncertaintyConfig, state: UncertaintyState, feats: torch.Tensor, rgb: np.ndarray,
           depth_m: np.ndarray, rgb_hat: np.ndarray, depth_hat_m: np.ndarray, alpha_hat: np.ndarray,
           rng: np.random.Generator) -> UncertaintyStep:
    """Predict beta for a frame, train the MLP on it against the map's render, predict again.

    ``feats`` (C, h, w) from a feature extractor; other arrays as in :func:`residuals`.
    """
    state = with_feature_stats(cfg, state, feats)
    before = predict(cfg, state, feats, depth_m.shape)
    state, loss = train(cfg, state, feats, rgb, depth_m, rgb_hat, depth_hat_m, alpha_hat, rng)
    return UncertaintyStep(state, predict(cfg, state, feats, depth_m.shape), before, loss)
