"""Novel-view quality of a Gaussian map: PSNR, SSIM, LPIPS and depth L1 against static-only renders.

Per view, then averaged over views (the 3DGS convention):

- PSNR (dB) of RGB in [0, 1] over the whole image (:func:`dynactivegs.splat.losses.psnr`);
- SSIM, 11 x 11 Gaussian window, sigma 1.5 (:func:`dynactivegs.splat.losses.ssim`);
- depth L1 (cm): mean |rendered - true| z-depth over pixels with a true depth return; a
  pixel the map leaves empty counts with its rendered depth 0;
- LPIPS (AlexNet) only with a model loaded from local weights (:mod:`dynactivegs.eval.lpips`);
  otherwise ``None`` and the reason;
- where the PSNR is lost (:func:`psnr_split`): the share of the squared colour error on pixels
  the map leaves empty, on pixels whose rendered surface is too near or too far, and the PSNR
  over the rest, where the surface is in the right place and only its colours can be wrong;
- whether it is lost where the path never looked (:func:`seen_split`): the share of the squared error on
  pixels showing surface the run's camera never saw, and the PSNR over the others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from dynactivegs.eval.lpips import LPIPS_MIN_PX, LpipsAlex
from dynactivegs.splat.gaussians import Gaussians
from dynactivegs.splat.losses import psnr, ssim
from dynactivegs.splat.render import NEAR_PLANE, Backend, render


def _image(rgb: np.ndarray | torch.Tensor) -> torch.Tensor:
    """float64 (H, W, 3) tensor in [0, 1] from uint8 0..255 or float 0..1."""
    t = torch.as_tensor(np.asarray(rgb) if not isinstance(rgb, torch.Tensor) else rgb.detach().cpu())
    t = t.to(torch.float64) / 255.0 if t.dtype == torch.uint8 else t.to(torch.float64)
    assert t.dim() == 3 and t.shape[-1] == 3, f"images must be (H, W, 3); got {tuple(t.shape)}"
    return t


def _pixel_sq_err(pred_rgb: np.ndarray | torch.Tensor, true_rgb: np.ndarray | torch.Tensor) -> np.ndarray:
    """float64 (H, W): each pixel's squared colour error, the mean over RGB, of the prediction clamped to [0, 1]."""
    return ((_image(pred_rgb).clamp(0, 1) - _image(true_rgb)) ** 2).mean(-1).numpy()


def psnr_db(pred_rgb: np.ndarray | torch.Tensor, true_rgb: np.ndarray | torch.Tensor) -> float:
    """PSNR in dB of two (H, W, 3) images (uint8 or float in [0, 1]); inf for identical images."""
    return psnr(_image(pred_rgb).clamp(0, 1), _image(true_rgb))


def ssim_value(pred_rgb: np.ndarray | torch.Tensor, true_rgb: np.ndarray | torch.Tensor) -> float:
    """Mean SSIM of two (H, W, 3) images (uint8 or float in [0, 1]); 1 for identical images."""
    return float(ssim(_image(pred_rgb).clamp(0, 1), _image(true_rgb)))


def depth_l1_cm(pred_depth_m: np.ndarray | torch.Tensor, true_depth_m: np.ndarray | torch.Tensor) -> float:
    """Mean |pred - true| in cm over pixels with a true depth return (true > 0); NaN when there is none."""
    pred = np.asarray(pred_depth_m.detach().cpu() if isinstance(pred_depth_m, torch.Tensor) else pred_depth_m,
                      dtype=np.float64)
    true = np.asarray(true_depth_m, dtype=np.float64)
    assert pred.shape == true.shape and pred.ndim == 2, f"depths must be (H, W); got {pred.shape}, {true.shape}"
    valid = np.isfinite(true) & (true > 0)
    if not valid.any():
        return float("nan")
    p = np.where(np.isfinite(pred), pred, 0.0)
    return float(np.abs(p[valid] - true[valid]).mean() * 100.0)


def _nanmean(values: list[float]) -> float:
    finite = [x for x in values if not np.isnan(x)]
    return float(np.mean(finite)) if finite else float("nan")


HOLE_ALPHA = 0.9
"""A pixel whose rendered accumulated opacity is below this is a hole in the map."""
DEPTH_TOL_M = 0.10
DEPTH_TOL_REL = 0.05
"""A rendered depth off the true one by more than max(DEPTH_TOL_M, DEPTH_TOL_REL * true depth) is misplaced."""


@dataclass(frozen=True)
class PsnrSplit:
    """Where one view's squared colour error lies. Each pixel is in one class: a **hole** (rendered
    opacity < HOLE_ALPHA), **front** (a true depth return, and the render's surface nearer by more than
    the tolerance: a floater or a surface where there is none), **behind** (farther by as much: the view
    sees past a missing surface) or **right** (the rest). ``*_px``: share of the pixels, ``*_err``: share
    of the summed squared error, both in [0, 1]."""

    hole_px: float
    hole_err: float
    front_px: float
    front_err: float
    behind_px: float
    behind_err: float
    right_psnr_db: float          # PSNR over the right pixels alone (nan when there are none)


def psnr_split(pred_rgb: np.ndarray, pred_depth_m: np.ndarray, pred_alpha: np.ndarray, true_rgb: np.ndarray,
               true_depth_m: np.ndarray) -> PsnrSplit:
    """The :class:`PsnrSplit` of one view: rgb (H, W, 3) as for :func:`psnr_db`, depths (H, W) in m (true 0:
    no return), alpha (H, W) in [0, 1]."""
    err = _pixel_sq_err(pred_rgb, true_rgb)
    pred_depth_m, true_depth_m = np.asarray(pred_depth_m), np.asarray(true_depth_m)
    assert err.shape == pred_depth_m.shape == true_depth_m.shape == np.shape(pred_alpha), "image sizes differ"
    hole = np.asarray(pred_alpha) < HOLE_ALPHA
    tol = np.maximum(DEPTH_TOL_M, DEPTH_TOL_REL * true_depth_m)
    placed = ~hole & (true_depth_m > 0)
    front = placed & (pred_depth_m < true_depth_m - tol)
    behind = placed & (pred_depth_m > true_depth_m + tol)
    right = ~(hole | front | behind)
    total = float(err.sum())
    share = (lambda m: float(err[m].sum()) / total) if total > 0 else (lambda m: 0.0)
    if not right.any():
        right_psnr = math.nan
    else:
        right_mse = float(err[right].mean())
        right_psnr = math.inf if right_mse == 0 else -10.0 * math.log10(right_mse)
    return PsnrSplit(float(hole.mean()), share(hole), float(front.mean()), share(front), float(behind.mean()),
                     share(behind), right_psnr)


@dataclass(frozen=True)
class SeenSplit:
    """One view's squared colour error split by whether the run's camera saw the surface at each pixel
    (:func:`dynactivegs.eval.progress.pixel_points`): what a map could not know, and what it got wrong. Sums
    and counts, so that views pool (:meth:`pooled`): a view that shows little seen surface weighs little."""

    seen_px: int                  # pixels showing surface the camera saw
    seen_sse: float               # their summed squared error (per pixel the mean over RGB, in [0, 1])
    unseen_px: int                # the other pixels (surface never seen, or no surface)
    unseen_sse: float

    @staticmethod
    def pooled(splits: list[SeenSplit]) -> tuple[float, float, float, float]:
        """Over all pixels of ``splits``: the unseen pixels' share of the pixels and of the squared error (in
        [0, 1]), the PSNR (dB) over the seen pixels and over all pixels (nan without pixels, inf when exact).
        Pooled PSNR is that of the mean squared error over all the views' pixels, which lies below the mean of
        per-view PSNRs when views differ (compare the two pooled values with each other)."""
        seen_px, unseen_px = sum(x.seen_px for x in splits), sum(x.unseen_px for x in splits)
        seen_sse, unseen_sse = sum(x.seen_sse for x in splits), sum(x.unseen_sse for x in splits)
        px, sse = seen_px + unseen_px, seen_sse + unseen_sse
        db = lambda e, n: math.nan if n == 0 else math.inf if e == 0 else -10.0 * math.log10(e / n)  # noqa: E731
        return ((unseen_px / px if px else math.nan), (unseen_sse / sse if sse > 0 else 0.0), db(seen_sse, seen_px),
                db(sse, px))


def seen_split(pred_rgb: np.ndarray, true_rgb: np.ndarray, seen: np.ndarray) -> SeenSplit:
    """The :class:`SeenSplit` of one view: rgb (H, W, 3) as for :func:`psnr_db`, ``seen`` bool (H, W)."""
    err = _pixel_sq_err(pred_rgb, true_rgb)
    seen = np.asarray(seen, bool)
    assert seen.shape == err.shape, f"seen must be (H, W) like the images; got {seen.shape}"
    return SeenSplit(int(seen.sum()), float(err[seen].sum()), int((~seen).sum()), float(err[~seen].sum()))


@dataclass(frozen=True)
class RenderMetrics:
    """Novel-view metrics averaged over views."""

    psnr_db: float
    ssim: float
    depth_l1_cm: float
    lpips: float | None           # None: not computed (see lpips_note)
    lpips_note: str               # where the LPIPS weights came from, or why LPIPS is n/a
    n_views: int
    psnr_views_db: tuple[float, ...] = ()  # per view, in the order of the poses
    hole_err_pct: float = math.nan         # mean over views of PsnrSplit.hole_err, in %
    front_err_pct: float = math.nan        # ... of front_err
    behind_err_pct: float = math.nan       # ... of behind_err
    psnr_right_db: float = math.nan        # mean over views of PsnrSplit.right_psnr_db (finite ones)


def render_metrics(gaussians: Gaussians, poses: np.ndarray, true_rgb: np.ndarray, true_depth_m: np.ndarray,
                   K: np.ndarray, *, lpips_model: LpipsAlex | None = None, lpips_note: str = "",
                   backend: Backend = "auto", near_plane: float = NEAR_PLANE) -> RenderMetrics:
    """Render the map at ``poses`` (V, 4, 4) and compare with the true rgb (V, H, W, 3) and depth (V, H, W).

    Renders use a black background, like the simulator's images where no surface is hit, and
    leave out Gaussians nearer than ``near_plane`` (m): give the camera's minimum depth, at which
    the true images were clipped too.
    """
    assert poses.ndim == 3 and poses.shape[1:] == (4, 4)
    v, h, w = true_depth_m.shape
    assert len(poses) == v and true_rgb.shape == (v, h, w, 3)
    if lpips_model is not None and min(h, w) < LPIPS_MIN_PX:
        lpips_model, lpips_note = None, f"images too small for LPIPS ({w}x{h} px; AlexNet needs >= {LPIPS_MIN_PX} px)"
    ps, ss, ds, lp, split = [], [], [], [], []
    with torch.no_grad():
        for i, T in enumerate(poses):
            out = render(gaussians, K, T, w, h, backend=backend, near_plane=near_plane)
            pred = out.rgb.detach().to("cpu", torch.float64).clamp(0, 1)
            true = _image(true_rgb[i])
            ps.append(psnr(pred, true))
            ss.append(float(ssim(pred, true)))
            pred_depth = out.depth.detach().cpu().numpy()
            ds.append(depth_l1_cm(pred_depth, true_depth_m[i]))
            split.append(psnr_split(pred, pred_depth, out.alpha.detach().cpu().numpy(), true, true_depth_m[i]))
            if lpips_model is not None:
                a = pred.to(torch.float32).permute(2, 0, 1)[None]
                b = true.to(torch.float32).permute(2, 0, 1)[None]
                lp.append(float(lpips_model(a, b)[0]))
    return RenderMetrics(psnr_db=_nanmean(ps), ssim=_nanmean(ss),
                         depth_l1_cm=_nanmean(ds),
                         lpips=float(np.mean(lp)) if lp else None,
                         lpips_note=lpips_note or ("LPIPS model given" if lpips_model else "no LPIPS model given"),
                         n_views=len(poses), psnr_views_db=tuple(float(p) for p in ps),
                         hole_err_pct=100.0 * _nanmean([x.hole_err for x in split]),
                         front_err_pct=100.0 * _nanmean([x.front_err for x in split]),
                         behind_err_pct=100.0 * _nanmean([x.behind_err for x in split]),
                         psnr_right_db=_nanmean([x.right_psnr_db for x in split if not math.isinf(x.right_psnr_db)]))
