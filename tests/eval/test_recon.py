"""Reconstruction points from rendered depth: the depth-edge filter."""

from __future__ import annotations

import numpy as np

from dynactivegs.eval.recon import depth_edge_mask


def oblique_plane_depth(h: int = 40, w: int = 60) -> np.ndarray:
    """z-depth of a floor seen at a grazing angle: inverse depth is linear in the row, up to 8 % per row."""
    v = np.arange(h, dtype=np.float64)[:, None]
    return np.broadcast_to(1.0 / (0.05 + 0.02 * v), (h, w)).astype(np.float32).copy()


def test_a_plane_has_no_depth_edges_however_oblique():
    d = oblique_plane_depth()
    edge = depth_edge_mask(d, np.ones(d.shape, bool), 0.05)
    assert not edge[1:-1].any()
    # the first and last rows lack a neighbour for the linearity test; the steep far rows there count as edges
    assert edge[0].all() and not edge[-1].any()


def test_a_blended_pixel_between_two_surfaces_is_an_edge_and_the_surfaces_are_not():
    d = np.full((20, 30), 2.0, np.float32)
    d[:, 16:] = 4.0                    # a wall 2 m behind the foreground
    d[:, 15] = 3.0                     # the column between them blends both
    edge = depth_edge_mask(d, np.ones(d.shape, bool), 0.05)
    assert edge[:, 15].all()
    assert not edge[:, :14].any() and not edge[:, 17:].any()


def test_invalid_pixels_are_never_edges_and_do_not_make_edges():
    d = np.full((10, 10), 2.0, np.float32)
    valid = np.ones(d.shape, bool)
    valid[:, 5] = False
    d[:, 5] = 0.0
    edge = depth_edge_mask(d, valid, 0.05)
    assert not edge.any()
