"""Evaluation: metrics, held-out views, benchmark tables and plots (DESIGN.md §6).

- ``config.py``: :class:`EvalConfig`, every evaluation setting.
- ``geometry.py``: ground-truth points (uniform over the static surface visible from free
  space, cached on disk with the triangle each lies on), the survey views (cached), Acc (to
  those triangles) / Comp / C.R. with KD-trees, voxel downsampling.
- ``recon.py``: reconstruction points of a Gaussian map, from opaque centres or from
  back-projected renders (depth-edge pixels left out); the result names the method.
- ``views.py``: survey views (lattice candidates, the greedy cover of the ground truth and
  the C.R. a perfect map reaches from them), seeded held-out novel views away from the
  trajectory, static-only ground-truth renders.
- ``rendering.py``: PSNR, SSIM, depth L1 and (with local weights, ``lpips.py``) LPIPS, and
  where a view's PSNR is lost (holes, surfaces too near or too far, colours).
- ``progress.py``: 25/50/75/100 % checkpoints of a step budget, cheap coverage.
- ``metrics.py``: :class:`SceneEvaluator` (per-scene state) and the :class:`Metrics` result.
- ``classification.py``: AUROC of per-pixel scores.

This package imports torch only through ``recon``, ``rendering``, ``lpips`` and ``metrics``.
"""
