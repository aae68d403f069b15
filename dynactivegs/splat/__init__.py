"""Gaussian splatting core: the Gaussian map, a differentiable rasterizer, image losses.

- :class:`Gaussians` (``gaussians.py``): raw parameters, activations, creation from RGB-D,
  concat / prune, INRIA ``.ply`` export and import (``ply.py``).
- :func:`render` (``render.py``): colour, expected depth and silhouette from a pinhole
  camera; backends ``cpu`` (numba, tiled, hand-written backward), ``cuda`` (gsplat) and
  ``reference`` (plain torch, for tests).
- ``losses.py``: L1, SSIM, masked depth L1, isotropy regulariser.
"""

from dynactivegs.splat.gaussians import SH_C0, Gaussians
from dynactivegs.splat.render import RenderOut, render

__all__ = ["SH_C0", "Gaussians", "RenderOut", "render"]
