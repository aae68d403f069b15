"""Soft visibility and view gains (eqs. 8-9): fast kernel vs. the plain-loop twin, occlusion, unknown space."""

from __future__ import annotations


import numpy as np
import pytest

from dynactivegs.errors import ConfigError
from dynactivegs.rng import derive_rng
from dynactivegs.selection._reference import view_gain_reference
from dynactivegs.selection.visibility import VisibilityConfig, bin_gains, column_occluders, occluder_grid, view_gains


def test_view_gains_equal_the_reference_on_seeded_random_grids():
    # Same formulas, different summation order: rtol 1e-9. Random node positions keep voxels
    # off exact bin edges, where one ulp of atan2 could move a voxel to the next bin.
    rng = derive_rng(0, "test-visibility-twin")
    cfg = VisibilityConfig(n_yaws=4, n_azimuth_bins=24, n_elevation_bins=6, range_m=1.6, camera_height_m=0.6)
    for trial in range(4):
        shape = tuple(int(s) for s in rng.integers(5, 11, 3))
        origin = rng.uniform(-1, 0, 3)
        voxel = 0.2
        occ = rng.random(shape) < (0.0 if trial == 0 else 0.08)     # trial 0: nothing mapped yet
        u_s = rng.uniform(0, 1, shape).astype(np.float32)
        u_m = rng.uniform(0, 2, shape).astype(np.float32)
        nodes = origin[:2] + rng.uniform(0.1, 1.0, (3, 2)) * np.array(shape[:2]) * voxel
        fast = view_gains(cfg, bin_gains(cfg, occ, u_s, u_m, origin, voxel, nodes)[0])
        fast_m = view_gains(cfg, bin_gains(cfg, occ, u_s, u_m, origin, voxel, nodes)[1])
        for n in range(len(nodes)):
            for k, yaw in enumerate(cfg.yaws_rad):
                g, r = view_gain_reference(cfg, occ, u_s, u_m, origin, voxel, nodes[n], yaw)
                assert fast[n, k] == pytest.approx(g, rel=1e-9, abs=1e-12)
                assert fast_m[n, k] == pytest.approx(r, rel=1e-9, abs=1e-12)


def _room(wall_x: float | None):
    """A 6 x 4 x 2.4 m grid (0.1 m voxels), U_s = 1 everywhere; optionally a wall across at x = wall_x."""
    voxel = 0.1
    shape = (60, 40, 24)
    occ = np.zeros(shape, bool)
    if wall_x is not None:
        occ[int(wall_x / voxel), :, :] = True
    return occ, np.ones(shape, np.float32), np.zeros(shape, np.float32), np.zeros(3), voxel


def test_a_wall_hides_what_is_behind_it_and_unknown_space_counts_as_visible():
    cfg = VisibilityConfig(range_m=4.0)
    node = np.array([[1.0, 2.0]])
    occ, us, um, origin, voxel = _room(None)
    open_gain = view_gains(cfg, bin_gains(cfg, occ, us, um, origin, voxel, node)[0])[0]
    occ_w, *_ = _room(2.0)
    walled = view_gains(cfg, bin_gains(cfg, occ_w, us, um, origin, voxel, node)[0])[0]
    east, west = 0, cfg.n_yaws // 2                                   # yaw 0 faces the wall, yaw pi away
    assert walled[east] < 0.35 * open_gain[east]                       # most of the view is behind the wall
    assert walled[west] == pytest.approx(open_gain[west], rel=1e-9)     # nothing between the node and the west
    assert open_gain[east] > 1.0                                       # unknown space is visible within range
    # U_m: a busy patch seen only from the east heading
    um2 = np.zeros_like(us)
    um2[25:30, 15:25, 0:18] = 2.0
    risk = view_gains(cfg, bin_gains(cfg, occ, us, um2, origin, voxel, node)[1])[0]
    assert risk[east] > 0.5 and risk[west] == 0.0


def test_occluder_grid_bins_surface_voxels_onto_the_query_grid():
    ijk = np.array([[0, 0, 0], [29, 0, 0], [30, 0, 0], [-5, 0, 0]], np.int32)   # 5 cm surface voxels
    occ = occluder_grid(ijk, 0.05, np.zeros(3), 0.15, (10, 2, 2))
    assert occ[0, 0, 0] and occ[9, 0, 0]
    assert occ.sum() == 2                                             # (30, 0, 0) is past x = 1.5 m; -5 is outside


def test_obstacle_columns_of_the_occupancy_grid_occlude_from_the_floor_up():
    origin, voxel, shape = np.array([0.0, 0.0, -0.3]), 0.1, (10, 10, 30)      # z from -0.3 to 2.7 m
    xy = np.array([[0.55, 0.55], [0.56, 0.54], [0.25, 0.75], [5.0, 5.0]])
    top = np.array([0.5, 0.7, 1.45, 1.45])                                 # one low column (two cells), one wall
    occ = column_occluders(xy, top, 1.4, origin, voxel, shape)
    layers = lambda i, j: np.nonzero(occ[i, j])[0]
    assert layers(5, 5).tolist() == list(range(3, 10))                      # floor to 0.7 m, the higher of the two
    assert layers(2, 7).tolist() == list(range(3, 30))                      # a wall: every layer above the floor
    assert occ.sum() == 7 + 27                                              # (5, 5) m is outside the grid
    # a wall the map's surface missed: a node next to it, facing it, sees nothing of the unknown behind it
    cfg = VisibilityConfig(range_m=4.0)
    room = _room(None)
    walls = column_occluders(np.array([[1.45, y] for y in np.arange(0.05, 4.0, 0.05)]), np.full(79, 1.5), 1.4,
                             room[3], room[4], room[0].shape)
    node = np.array([[1.2, 2.0]])
    open_gain = view_gains(cfg, bin_gains(cfg, room[0], *room[1:], node)[0])[0]
    walled = view_gains(cfg, bin_gains(cfg, walls, *room[1:], node)[0])[0]
    assert walled[0] < 0.05 * open_gain[0] and walled[cfg.n_yaws // 2] == pytest.approx(open_gain[cfg.n_yaws // 2])


def test_bad_config_raises():
    with pytest.raises(ConfigError):
        VisibilityConfig(n_yaws=8, n_azimuth_bins=60)
    with pytest.raises(ConfigError):
        VisibilityConfig(softness_m=0.0)
