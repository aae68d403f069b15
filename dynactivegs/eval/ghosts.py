"""Ghosts: opaque Gaussians left behind on people's paths (DESIGN.md §5; issue 4's test metric).

A ghost is an opaque Gaussian whose centre lies within ``track_radius_m`` (on the floor plane,
below the person's height) of some position a person occupied during the run, but farther
than ``surface_dist_m`` from any static surface. The static surface is represented by dense
uniform samples of the static mesh (the simulator's, never people), so "farther than d from
the surface" is measured to the nearest sample; with ~2.5 cm sample spacing it is exact to
about a centimetre at d = 10 cm.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def count_ghosts(means_m: np.ndarray, opacities: np.ndarray, surface_pts_m: np.ndarray, track_xy_m: np.ndarray,
                 track_height_m: np.ndarray, *, min_opacity: float = 0.5, track_radius_m: float = 0.3,
                 surface_dist_m: float = 0.1) -> int:
    """Number of ghosts among Gaussians ``means_m`` (N, 3) with ``opacities`` (N,).

    ``surface_pts_m`` (S, 3) dense static-surface samples; ``track_xy_m`` (T, 2) every person
    position of the run and ``track_height_m`` (T,) the person's height there.
    """
    assert means_m.ndim == 2 and means_m.shape[1] == 3 and opacities.shape == (len(means_m),)
    assert track_xy_m.ndim == 2 and track_xy_m.shape[1] == 2 and track_height_m.shape == (len(track_xy_m),)
    sel = opacities >= min_opacity
    pts = means_m[sel]
    if len(pts) == 0 or len(track_xy_m) == 0:
        return 0
    d_track, i_track = cKDTree(track_xy_m).query(pts[:, :2])
    near_track = (d_track <= track_radius_m) & (pts[:, 2] <= track_height_m[i_track] + 0.1) & (pts[:, 2] >= 0.0)
    if not near_track.any():
        return 0
    d_surf, _ = cKDTree(surface_pts_m).query(pts[near_track])
    return int((d_surf > surface_dist_m).sum())
