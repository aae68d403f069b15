"""Uncertainty-weighted Gaussian mapping with known poses (DESIGN.md §5, Mapping).

Per step t (``step``), given frame t, its pose and beta_t from perception:

1. **Render** the current map G_{t-1} at frame t's pose (no gradients). This render is
   returned in :class:`MappingOut` (perception trains on it at step t+1; fields aggregate its
   residual) and decides densification.
2. **Densify**: one isotropic Gaussian per ``densify_stride``-th pixel where the frame has a
   depth return and the map is not yet opaque there (alpha < ``densify_alpha``) or something
   is observed clearly in front of the map's surface (depth disagreement). Its standard
   deviation is ``init_scale`` times the footprint of ``densify_stride`` pixels at its depth:
   at 160 x 92 a full footprint is 5 cm at 2 m, and the map's walls come out as thick as that
   (measured on a 600-step run of apartment-00: half the footprint took Acc from 5.5 to
   4.1 cm). With weighting on, pixels whose beta exceeds ``seed_beta_ratio`` times the frame's
   reference beta (2 by default, see MappingConfig) never seed Gaussians. Additions stop at
   ``max_gaussians``.
3. **Keyframe**: every ``keyframe_every``-th frame joins the keyframe set, with its beta.
4. **Optimise** ``iters`` Adam steps of the paper's mapping loss on views drawn from the
   current frame (every other iteration), the last ``window`` keyframes and
   ``random_older`` random older keyframes:

       L = mean_px[ w * (l1 * L_color + l2 * L_depth) ] + l3 * L_iso
       L_color = 0.8 |I^ - I|_1 + 0.2 (1 - SSIM(I^, I))      per pixel (mean over RGB)
       L_depth = |D^ - D|                                    per pixel, where D > 0 and the render is opaque
       w = (b_ref / max(beta, b_ref))^2                      the paper's 1 / beta^2, normalised
                                                             (0 where beta > drop_beta_ratio * b_ref, if set)

   plus ``l_a * mean_px[ w * (1 - A^) ]`` over pixels with a depth return (A^ the render's
   accumulated opacity): a silhouette term as in SplaTAM. Indoors every pixel with a return
   sees a surface, and without this term the colour loss lets opacities drift down until
   surfaces are half transparent (measured: median opacity 0.35 after 40 steps, 30 % of
   pixels below alpha 0.8).

   b_ref, the frame's reference beta, is the ``ref_percentile``-th percentile of beta over the
   pixels with a depth return: the level of a confidently static pixel in that frame. beta's
   absolute level follows how well the map explains the scene (perception calibrates it to the
   residuals, which are larger while the map is young), so only beta relative to b_ref says
   "this pixel is on something moving". Dividing by b_ref^2 is a constant per frame (Adam is
   invariant to it), the clamp only affects the most confident pixels, and it keeps l3 meaning
   the same with the weighting on and off. With ``weighted=False`` (the ablation "no weighted
   mapping") w = 1 and beta is ignored entirely. The optional cut-off ``drop_beta_ratio`` is
   not in the paper and is off by default. With the soft weights alone a person 4 m away with
   beta at 2-4 x b_ref keeps a quarter to a sixteenth of the weight, and where people keep
   walking through the view the map grows opaque Gaussians of 10-25 cm on their paths
   (measured on a 600-step run of apartment-02: 50 such Gaussians gave half of the
   reconstruction points more than 20 cm off the surface; a cut-off at 1.5 took Acc there from
   7.2 to 5.1 cm). But a static surface seen for the first time also has a high beta until the
   map fits it, and a hard cut-off can keep it from ever being fitted: on a 70-step scripted
   tour it cost 1.4 dB of held-out PSNR.
5. **Carve** (every step): Gaussians that frame t shows to be in free space go: their centre
   projects onto a pixel with a depth return (and, with weighting on, a confident beta there)
   and lies in front of that return by more than ``carve_margin_m`` + ``carve_margin_rel`` *
   depth + twice their largest scale. Something that was there has moved away: this is what
   removes the ghosts of people who walked off (the depth term of the loss alone removes them
   only slowly at a few iterations per step).
6. **Prune** (every ``prune_every`` steps): Gaussians with opacity < ``prune_opacity`` or a
   largest scale > ``prune_scale_m``.
7. **Free-space vote** (every ``vote_every`` steps): each Gaussian against every keyframe.
   Carving (5) only hears the current frame; the vote also hears the keyframes taken before
   a Gaussian was seeded, which saw through the place where a person later stood. A keyframe
   votes *free* when the Gaussian lies in front of the nearest return of the 3 x 3 pixels
   around its centre's pixel by more than carving's margin, and *support* when the return at
   its pixel is within that margin of it. A Gaussian with at least ``vote_min_free`` free
   votes and more free than support votes goes.

``refine`` is the offline refinement after the episode: the same loss over all keyframes,
``refine_passes`` times over (:func:`refine_iters`), then a prune.
All tensors are float32 on the CPU by default (``device="cuda"`` uses gsplat when available).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
from scipy.ndimage import minimum_filter

from dynactivegs.mapping.adam import AdamState, adam_step
from dynactivegs.mapping.config import MappingConfig
from dynactivegs.records import Frame, MappingOut, StepRecord
from dynactivegs.splat.gaussians import Gaussians
from dynactivegs.splat.losses import isotropy, l1_map, ssim_map
from dynactivegs.splat.render import render


@dataclass(frozen=True, slots=True)
class Keyframe:
    """A frame kept for optimisation, with the uncertainty it had when it was taken."""

    step: int
    rgb: np.ndarray                # uint8 (H, W, 3)
    depth_m: np.ndarray            # float32 (H, W)
    beta: np.ndarray | None        # float32 (H, W); None when the weighting is off
    K: np.ndarray                  # float64 (3, 3)
    T_world_cam: np.ndarray        # float64 (4, 4)


@dataclass(frozen=True)
class MappingState:
    """The map, its optimiser moments and the keyframes."""

    gaussians: Gaussians
    adam: AdamState
    keyframes: tuple[Keyframe, ...]
    steps: int


def init_state(cfg: MappingConfig) -> MappingState:
    """An empty map."""
    g = Gaussians.empty(torch.float32, cfg.device)
    return MappingState(g, AdamState.zeros_like(g), (), 0)


def _backend(cfg: MappingConfig) -> str:
    return "cuda" if cfg.device == "cuda" else "cpu"


def _render(cfg: MappingConfig, g: Gaussians, K: np.ndarray, T: np.ndarray, w: int, h: int):
    return render(g, K, T, w, h, (0.0, 0.0, 0.0), backend=_backend(cfg))


@torch.no_grad()
def render_view(cfg: MappingConfig, g: Gaussians, K: np.ndarray, T_world_cam: np.ndarray, width: int,
                height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rgb uint8 (H, W, 3), depth_m float32 (H, W), alpha float32 (H, W)) of the map from a camera."""
    if len(g) == 0:
        return (np.zeros((height, width, 3), np.uint8), np.zeros((height, width), np.float32),
                np.zeros((height, width), np.float32))
    out = _render(cfg, g, K, T_world_cam, width, height)
    rgb = (out.rgb.clamp(0, 1) * 255.0 + 0.5).to(torch.uint8).cpu().numpy()
    # depth and alpha rounded to half precision (depth to 0.05 %, alpha to 5e-4): ample for every
    # use downstream, and the cleared low mantissa bits halve their compressed size in the log
    half = lambda t: t.half().float().cpu().numpy()  # noqa: E731
    return rgb, half(out.depth), half(out.alpha)


def seed_mask(cfg: MappingConfig, depth_m: np.ndarray, beta: np.ndarray | None, render_depth_m: np.ndarray,
              render_alpha: np.ndarray) -> np.ndarray:
    """bool (H, W): pixels that seed new Gaussians (step 2 of the module docstring)."""
    valid = depth_m > 0
    in_front = (render_depth_m > 0) & (depth_m < render_depth_m * (1.0 - cfg.densify_depth_rel))
    need = valid & ((render_alpha < cfg.densify_alpha) | in_front)
    if cfg.weighted and beta is not None:
        need &= beta <= cfg.seed_beta_ratio * reference_beta(cfg, beta, depth_m)   # never seed from people
    return need


def reference_beta(cfg: MappingConfig, beta: np.ndarray, depth_m: np.ndarray) -> float:
    """b_ref: the ``ref_percentile``-th percentile of beta over pixels with a depth return."""
    valid = depth_m > 0
    return float(np.percentile(beta[valid] if valid.any() else beta, cfg.ref_percentile))


def pixel_weights(cfg: MappingConfig, beta: np.ndarray | None, depth_m: np.ndarray) -> torch.Tensor:
    """(H, W) loss weights (b_ref / max(beta, b_ref))^2, or ones when the weighting is off."""
    if not cfg.weighted or beta is None:
        return torch.ones(depth_m.shape)
    b_ref = np.float32(reference_beta(cfg, beta, depth_m))
    w = (b_ref / np.maximum(beta, b_ref)) ** 2
    if cfg.drop_beta_ratio > 0:
        w = np.where(beta > cfg.drop_beta_ratio * b_ref, np.float32(0.0), w)
    return torch.from_numpy(w)


def view_loss(cfg: MappingConfig, g: Gaussians, kf: Keyframe) -> torch.Tensor:
    """The mapping loss of the module docstring on one view (differentiable in ``g``)."""
    h, w = kf.depth_m.shape
    out = _render(cfg, g, kf.K, kf.T_world_cam, w, h)
    dev = out.rgb.device
    target = torch.from_numpy(np.ascontiguousarray(kf.rgb, np.float32) / 255.0).to(dev)
    depth = torch.from_numpy(np.array(kf.depth_m, np.float32)).to(dev)
    valid = depth > 0
    weight = pixel_weights(cfg, kf.beta, kf.depth_m).to(dev)
    colour = ((1 - cfg.ssim_weight) * l1_map(out.rgb, target)
              + cfg.ssim_weight * (1 - ssim_map(out.rgb, target, window=7, sigma=1.5)))
    opaque = valid & (out.alpha.detach() > 0.5)
    depth_err = torch.where(opaque, (out.depth - depth).abs(), torch.zeros_like(depth))
    n_valid = valid.sum().clamp(min=1)
    data = ((weight * colour * valid).sum() * cfg.color_weight + (weight * depth_err).sum() * cfg.depth_weight
            + (weight * (1 - out.alpha) * valid).sum() * cfg.alpha_weight) / n_valid
    return data + cfg.iso_weight * isotropy(g.log_scales)


def optimise(cfg: MappingConfig, g: Gaussians, adam: AdamState, views: list[Keyframe]) -> tuple[Gaussians, AdamState, float]:
    """One Adam step per view in ``views`` (in order); returns the map, moments and the last loss."""
    loss = float("nan")
    for kf in views:
        if len(g) == 0:
            break
        params = tuple(p.detach().requires_grad_(True) for p in g.tensors())
        g_req = Gaussians(*params)
        total = view_loss(cfg, g_req, kf)
        grads = torch.autograd.grad(total, params, allow_unused=True)
        grads = tuple(torch.zeros_like(p) if gr is None else gr for p, gr in zip(params, grads))
        g, adam = adam_step(g_req, grads, adam, cfg.lrs)
        loss = float(total.detach())
    return g, adam, loss


def prune(cfg: MappingConfig, g: Gaussians, adam: AdamState) -> tuple[Gaussians, AdamState, int]:
    """Drops transparent and oversized Gaussians; returns the map, moments and how many went."""
    keep = (g.opacities >= cfg.prune_opacity) & (g.scales.max(dim=1).values <= cfg.prune_scale_m)
    n = int((~keep).sum())
    if n == 0:
        return g, adam, 0
    return g.masked(keep), adam.masked(keep), n


def carve(cfg: MappingConfig, g: Gaussians, adam: AdamState, frame: Frame,
          beta: np.ndarray | None) -> tuple[Gaussians, AdamState, int]:
    """Removes Gaussians that frame shows to be in free space (step 5 of the module docstring)."""
    if len(g) == 0:
        return g, adam, 0
    means = g.means.detach().cpu().double().numpy()
    idx, vi, ui, z = project_centres(means, frame.K, frame.T_world_cam, frame.width, frame.height)
    d = frame.depth_m[vi, ui].astype(np.float64)
    reach = g.scales.detach().cpu().double().numpy().max(axis=1)[idx]
    free = (d > 0) & (z < d - carve_margin(cfg, d, reach))
    if cfg.weighted and beta is not None:
        free &= beta[vi, ui] <= cfg.seed_beta_ratio * reference_beta(cfg, beta, frame.depth_m)
    if not free.any():
        return g, adam, 0
    keep = np.ones(len(g), bool)
    keep[idx[free]] = False
    keep_t = torch.from_numpy(keep).to(g.means.device)
    return g.masked(keep_t), adam.masked(keep_t), int((~keep).sum())


def project_centres(means: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, width: int,
                    height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The centres (N, 3) that fall in the image: their indices, pixel rows, pixel columns and z-depths."""
    T_cam_world = np.linalg.inv(T_world_cam)
    p = means @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.floor(K[0, 0] * p[:, 0] / z + K[0, 2])
        v = np.floor(K[1, 1] * p[:, 1] / z + K[1, 2])
    idx = np.flatnonzero((z > 0.05) & (u >= 0) & (u < width) & (v >= 0) & (v < height))
    return idx, v[idx].astype(np.int64), u[idx].astype(np.int64), z[idx]


def carve_margin(cfg: MappingConfig, depth_m: np.ndarray, reach_m: np.ndarray) -> np.ndarray:
    """How far in front of an observed depth a Gaussian of largest scale ``reach_m`` must lie to be seen through."""
    return cfg.carve_margin_m + cfg.carve_margin_rel * depth_m + 2.0 * reach_m


def free_space_vote(cfg: MappingConfig, g: Gaussians, adam: AdamState,
                    keyframes: tuple[Keyframe, ...]) -> tuple[Gaussians, AdamState, int]:
    """Removes Gaussians that the keyframes, taken together, show to be in free space (step 7 of the module docstring).

    Per keyframe a Gaussian whose centre falls in the image gets a *free* vote when it lies in front of the
    nearest depth return of the 3 x 3 pixels around it by more than :func:`carve_margin` (the neighbourhood
    keeps depth edges from voting against the near side), and a *support* vote when the return at its pixel
    lies within that margin of it. Those with ``vote_min_free`` or more free votes and more free than
    support votes go.
    """
    if len(g) == 0 or not keyframes:
        return g, adam, 0
    means = g.means.detach().cpu().double().numpy()
    reach = g.scales.detach().cpu().double().numpy().max(axis=1)
    free = np.zeros(len(g), np.int32)
    support = np.zeros(len(g), np.int32)
    for kf in keyframes:
        h, w = kf.depth_m.shape
        idx, vi, ui, z = project_centres(means, kf.K, kf.T_world_cam, w, h)
        depth = kf.depth_m.astype(np.float64)
        near = minimum_filter(np.where(depth > 0, depth, np.inf), size=3, mode="nearest")
        d, d_near = depth[vi, ui], near[vi, ui]
        margin = carve_margin(cfg, d, reach[idx])
        hit = d > 0
        free[idx] += hit & (z < d_near - margin)
        support[idx] += hit & (np.abs(z - d) <= margin)
    gone = (free >= cfg.vote_min_free) & (free > support)
    if not gone.any():
        return g, adam, 0
    keep = torch.from_numpy(~gone).to(g.means.device)
    return g.masked(keep), adam.masked(keep), int(gone.sum())


def surface_voxels(cfg: MappingConfig, g: Gaussians) -> np.ndarray:
    """int32 (M, 3): sorted unique voxels holding the centre of an opaque Gaussian."""
    if len(g) == 0:
        return np.zeros((0, 3), np.int32)
    means = g.means[g.opacities >= cfg.surface_opacity].detach().cpu().double().numpy()
    ijk = np.floor(means / cfg.surface_voxel_m).astype(np.int32)
    return np.unique(ijk, axis=0) if len(ijk) else np.zeros((0, 3), np.int32)


def densify(cfg: MappingConfig, g: Gaussians, adam: AdamState, view: Keyframe, render_depth_m: np.ndarray,
            render_alpha: np.ndarray, rng: np.random.Generator) -> tuple[Gaussians, AdamState, int]:
    """Adds Gaussians at ``view``'s :func:`seed_mask` pixels (step 2 of the module docstring), ``render_*`` being
    the map's render at that view; past ``max_gaussians`` a random subset (from ``rng``) fills the room left."""
    seeds = seed_mask(cfg, view.depth_m, view.beta, render_depth_m, render_alpha)
    new = Gaussians.from_rgbd(view.rgb, view.depth_m, view.K, view.T_world_cam, mask=seeds,
                              stride=cfg.densify_stride, opacity=cfg.init_opacity,
                              scale_factor=cfg.init_scale).to(device=cfg.device)
    room = max(cfg.max_gaussians - len(g), 0)
    if len(new) > room:
        keep = np.zeros(len(new), bool)
        keep[rng.choice(len(new), size=room, replace=False)] = True
        new = new.masked(torch.from_numpy(keep).to(cfg.device))
    if len(new):
        g, adam = Gaussians.cat([g, new]), adam.cat(new)
    return g, adam, len(new)


def _views(cfg: MappingConfig, current: Keyframe, keyframes: tuple[Keyframe, ...],
           rng: np.random.Generator) -> list[Keyframe]:
    """The views of this step's iterations: the current frame every other iteration, else keyframes."""
    window = list(keyframes[-cfg.window:])
    older = list(keyframes[:-cfg.window])
    if older and cfg.random_older:
        picks = rng.choice(len(older), size=min(cfg.random_older, len(older)), replace=False)
        window += [older[i] for i in sorted(picks)]
    views = []
    for i in range(cfg.iters):
        if i % 2 == 0 or not window:
            views.append(current)
        else:
            views.append(window[int(rng.integers(len(window)))])
    return views


def step(cfg: MappingConfig, rec: StepRecord, state: MappingState,
         rng: np.random.Generator) -> tuple[MappingState, MappingOut]:
    """Reads ``rec.frame`` and ``rec.perception.beta`` (ignored when ``cfg.weighted`` is off)."""
    frame: Frame = rec.frame
    assert rec.perception is not None or not cfg.weighted, "weighted mapping needs rec.perception"
    beta = rec.perception.beta if (cfg.weighted and rec.perception is not None) else None
    h, w = frame.height, frame.width
    g, adam = state.gaussians, state.adam

    r_rgb, r_depth, r_alpha = render_view(cfg, g, frame.K, frame.T_world_cam, w, h)     # 1. G_{t-1} at pose t

    current = Keyframe(frame.step, frame.rgb, frame.depth_m, beta, frame.K, frame.T_world_cam)
    g, adam, n_added = densify(cfg, g, adam, current, r_depth, r_alpha, rng)            # 2. densify

    is_key = state.steps % cfg.keyframe_every == 0                                      # 3. keyframes
    keyframes = state.keyframes
    g, adam, loss = optimise(cfg, g, adam, _views(cfg, current, keyframes, rng))       # 4. optimise
    if is_key:
        keyframes = keyframes + (current,)

    g, adam, n_pruned = carve(cfg, g, adam, frame, beta)                               # 5. carve
    if (state.steps + 1) % cfg.prune_every == 0:                                        # 6. prune
        g, adam, n = prune(cfg, g, adam)
        n_pruned += n
    if cfg.vote_every and (state.steps + 1) % cfg.vote_every == 0:                      # 7. free-space vote
        g, adam, n = free_space_vote(cfg, g, adam, keyframes)
        n_pruned += n

    out = MappingOut(render_rgb=r_rgb, render_depth_m=r_depth, render_alpha=r_alpha,
                     surface_ijk=surface_voxels(cfg, g), surface_voxel_m=cfg.surface_voxel_m,
                     n_gaussians=len(g), n_added=n_added, n_pruned=n_pruned, loss=loss, keyframe=is_key)
    return MappingState(g, adam, keyframes, state.steps + 1), out


def refine_iters(cfg: MappingConfig, state: MappingState) -> int:
    """Adam steps of the offline refinement: ``refine_passes`` times the number of keyframes."""
    return int(round(cfg.refine_passes * len(state.keyframes)))


def refine(cfg: MappingConfig, state: MappingState, iters: int, rng: np.random.Generator,
           progress: Callable[[int], None] | None = None) -> MappingState:
    """Offline refinement after the episode: ``iters`` Adam steps over all keyframes (random order,
    each keyframe once per pass), then a final prune. ``progress(k)`` is called after each step.
    With ``refine_densify`` the keyframes first fill the map's holes, one after the other in the
    order they were taken (:func:`densify` on the map's render at each)."""
    g, adam, kfs = state.gaussians, state.adam, state.keyframes
    if not kfs or iters <= 0 or len(g) == 0:
        return state
    if cfg.refine_densify:
        for kf in kfs:
            h, w = kf.depth_m.shape
            _, r_depth, r_alpha = render_view(cfg, g, kf.K, kf.T_world_cam, w, h)
            g, adam, _ = densify(cfg, g, adam, kf, r_depth, r_alpha, rng)
    order: list[int] = []
    while len(order) < iters:
        order += [int(i) for i in rng.permutation(len(kfs))]
    for k, i in enumerate(order[:iters]):
        g, adam, _ = optimise(cfg, g, adam, [kfs[i]])
        if progress is not None:
            progress(k + 1)
    g, adam, _ = prune(cfg, g, adam)
    return MappingState(g, adam, kfs, state.steps)
