"""Occupancy grid: fast traversal vs. reference, what a frame marks, people, growth, config."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy import ndimage

from dynactivegs.errors import ConfigError
from dynactivegs.rng import derive_rng
from dynactivegs.selection._reference import update_occupancy_reference
from dynactivegs.selection.occupancy import (CellState, OccupancyConfig, OccupancyGrid, joining_pieces, let_go,
                                             update_occupancy)
from dynactivegs.selection.voronoi import traversable_mask

from tests.selection.scenes import intrinsics, render_depth, view

CFG = OccupancyConfig(cell_m=0.1, transient_frames=0)     # no let-go rule; their tests turn one on


def _random_frame(rng: np.random.Generator, w: int, h: int):
    depth = rng.uniform(0.15, 9.0, size=(h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.15] = 0.0                     # no returns
    yaw = rng.uniform(-math.pi, math.pi)
    T = view(rng.uniform(-3, 3), rng.uniform(-3, 3), yaw, rng.uniform(0.3, 1.8))
    tilt = rng.normal(0.0, 0.2)                                # pitch the camera about its x axis
    R = np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]])
    T[:3, :3] = T[:3, :3] @ R
    K = intrinsics(w, h, rng.uniform(60, 110), rng.uniform(40, 80))
    beta = rng.uniform(0.0, 1.0, size=(h, w)).astype(np.float32)
    return depth, K, T, beta


def test_fast_update_equals_reference_on_seeded_random_frames():
    # Exact equality: both mark the same cell sets; ties (a ray through a cell corner) have
    # probability zero with random float poses.
    rng = derive_rng(0, "test-occupancy-twin")
    for trial in range(6):
        grid_fast = grid_ref = OccupancyGrid.empty(CFG.cell_m)
        for _ in range(3):
            depth, K, T, beta = _random_frame(rng, 14, 9)
            grid_fast = update_occupancy(grid_fast, CFG, depth, K, T, beta)
            grid_ref = update_occupancy_reference(grid_ref, CFG, depth, K, T, beta)
            assert grid_fast.origin_ij == grid_ref.origin_ij
            np.testing.assert_array_equal(grid_fast.logodds, grid_ref.logodds)
        assert (grid_fast.logodds != 0).sum() > 50


def test_degenerate_frames_no_returns_and_points_in_the_camera_cell():
    rng = derive_rng(1, "test-occupancy-degenerate")
    _, K, T, beta = _random_frame(rng, 8, 6)
    empty = np.zeros((6, 8), np.float32)
    g = update_occupancy(OccupancyGrid.empty(CFG.cell_m), CFG, empty, K, T, beta)
    assert (g.logodds != 0).sum() == 1                         # only the camera's own cell is seen (free)
    near = np.full((6, 8), 0.01, np.float32)                   # every return lands in or next to the camera's cell
    g2 = update_occupancy(OccupancyGrid.empty(CFG.cell_m), CFG, near, K, T, beta)
    g2r = update_occupancy_reference(OccupancyGrid.empty(CFG.cell_m), CFG, near, K, T, beta)
    np.testing.assert_array_equal(g2.logodds, g2r.logodds)


def _room_frame(boxes=(), x=1.0, y=1.5, yaw=0.0, w=64, h=36):
    K = intrinsics(w, h)
    T = view(x, y, yaw)
    depth, which = render_depth(T, K, w, h, (4.0, 3.0), list(boxes))
    return depth, K, T, which


def test_a_room_view_marks_floor_free_walls_occupied_and_behind_the_camera_unknown():
    depth, K, T, _ = _room_frame()
    beta = np.zeros_like(depth)
    g = OccupancyGrid.empty(CFG.cell_m)
    for _ in range(2):
        g = update_occupancy(g, CFG, depth, K, T, beta)
    st = g.states(CFG)
    at = lambda x, y: st[tuple(g.world_to_cell(np.array([x, y])))]
    assert at(2.5, 1.5) == CellState.FREE                      # floor ahead
    # the far wall's surface is at x = 4.0, a cell boundary: its points land on either side
    assert CellState.OCCUPIED in (at(3.95, 1.5), at(4.05, 1.5))
    assert at(0.3, 1.5) == CellState.UNKNOWN                   # behind the camera
    assert at(4.3, 1.5) == CellState.UNKNOWN                   # beyond the wall
    # the wall is seen as a line of occupied cells across the view
    j = g.world_to_cell(np.array([3.95, 0.0]))[1]
    wall = (st[:, j] == CellState.OCCUPIED) | (st[:, j + 1] == CellState.OCCUPIED)
    assert wall.sum() >= 15


def test_an_uncertain_person_clears_space_but_is_not_an_obstacle():
    person = (2.43, 1.33, 2.83, 1.73, 1.8)   # faces off the 0.1 m cell boundaries
    depth, K, T, which = _room_frame(boxes=[person])
    cell_person = (2.45, 1.5)
    calm = OccupancyGrid.empty(CFG.cell_m)
    moving = OccupancyGrid.empty(CFG.cell_m)
    beta_calm = np.zeros_like(depth)
    beta_moving = np.where(which == 0, 2.0, 0.05).astype(np.float32)
    for _ in range(3):
        calm = update_occupancy(calm, CFG, depth, K, T, beta_calm)
        moving = update_occupancy(moving, CFG, depth, K, T, beta_moving)
    ij = tuple(calm.world_to_cell(np.array(cell_person)))
    assert calm.states(CFG)[ij] == CellState.OCCUPIED
    assert moving.states(CFG)[tuple(moving.world_to_cell(np.array(cell_person)))] != CellState.OCCUPIED
    assert not (moving.occupied(CFG) & ~calm.occupied(CFG)).any()     # uncertain returns never add obstacles
    # a person seen earlier as an obstacle is cleared once the space is seen free
    g = calm
    empty_depth, _, _, _ = _room_frame()
    for _ in range(8):
        g = update_occupancy(g, CFG, empty_depth, K, T, beta_calm)
    assert g.states(CFG)[tuple(g.world_to_cell(np.array(cell_person)))] == CellState.FREE
    # the uncertain person's returns are counted per frame in their cells (OccupancyGrid.people), the calm one's not
    ij_m = tuple(moving.world_to_cell(np.array(cell_person)))
    assert moving.people[ij_m] == 3 and moving.people.max() == 3 and not calm.people.any()
    assert not (moving.people > 0)[moving.states(CFG) == CellState.OCCUPIED].any()     # the walls hold none


def test_a_person_who_stood_long_is_cleared_in_a_few_frames_of_seeing_through():
    """logodds_max caps what a calm person standing for 20 frames leaves: 6 frames of the empty room clear it.
    At a cap of 3.5 the cell was still occupied then (a doorway stayed shut for the rest of a run)."""
    person = (2.43, 1.33, 2.83, 1.73, 1.8)
    depth, K, T, _ = _room_frame(boxes=[person])
    empty_depth, _, _, _ = _room_frame()
    beta = np.zeros_like(depth)
    for cap, after_6 in ((CFG.logodds_max, CellState.FREE), (3.5, CellState.OCCUPIED)):
        cfg = dataclasses.replace(CFG, logodds_max=cap)
        g = OccupancyGrid.empty(cfg.cell_m)
        for _ in range(20):
            g = update_occupancy(g, cfg, depth, K, T, beta)
        ij = tuple(g.world_to_cell(np.array([2.45, 1.5])))
        assert g.states(cfg)[ij] == CellState.OCCUPIED and g.logodds[ij] == pytest.approx(cap)
        for _ in range(6):
            g = update_occupancy(g, cfg, empty_depth, K, T, beta)
        assert g.states(cfg)[ij] == after_6


def _stood_then_left_behind(cfg: OccupancyConfig, obstacle, away_frames: int, seen_meanwhile: bool = False,
                            empty_frames: int = 6):
    """Grid after: ``empty_frames`` frames of the empty room (its floor seen free), 10 with ``obstacle`` standing in
    it (calm: beta 0), then ``away_frames`` facing the other way (or, ``seen_meanwhile``, still facing it)."""
    empty, K, T, _ = _room_frame()
    present, _, _, _ = _room_frame(boxes=[obstacle])
    away, _, T_away, _ = _room_frame(yaw=math.pi)
    beta = np.zeros_like(empty)
    g = OccupancyGrid.empty(cfg.cell_m)
    for depth, T_now, n in ((empty, T, empty_frames), (present, T, 10), (present if seen_meanwhile else away,
                                                               T if seen_meanwhile else T_away, away_frames)):
        for _ in range(n):
            g = update_occupancy(g, cfg, depth, K, T_now, beta)
    return g


def test_a_person_who_stood_where_the_floor_was_seen_free_is_let_go_after_transient_frames():
    """A calm person left occupied cells on floor seen free before; with the robot looking away nothing clears
    them. transient_frames lets them go (free again) that many frames after their last return; 0 keeps them."""
    person = (2.43, 1.33, 2.83, 1.73, 1.8)
    on = dataclasses.replace(CFG, transient_frames=20, transient_cut_m=0.0)     # the plain rule
    for cfg, frames, want in ((CFG, 40, CellState.OCCUPIED), (on, 15, CellState.OCCUPIED), (on, 25, CellState.FREE)):
        g = _stood_then_left_behind(cfg, person, frames)
        ij = tuple(g.world_to_cell(np.array([2.45, 1.5])))
        assert g.freed[ij] and g.quiet[ij] == frames
        assert g.states(cfg)[ij] == want, (cfg.transient_frames, frames)
    assert g.top_m[ij] == 0.0                                       # let go: no obstacle seen there any more
    # let go, one return makes it occupied again: the person is still there
    present, K, T, _ = _room_frame(boxes=[person])
    g = update_occupancy(g, on, present, K, T, np.zeros_like(present))
    assert g.states(on)[ij] == CellState.OCCUPIED


def test_what_is_not_a_standing_person_on_seen_floor_is_never_let_go():
    on = dataclasses.replace(CFG, transient_frames=20, transient_cut_m=0.0)     # the plain rule
    # still in view: each frame returns from it, so it never goes quiet
    g = _stood_then_left_behind(on, (2.43, 1.33, 2.83, 1.73, 1.8), 40, seen_meanwhile=True)
    assert g.states(on)[tuple(g.world_to_cell(np.array([2.45, 1.5])))] == CellState.OCCUPIED
    # a seat on seen floor: lower than transient_top_m
    g = _stood_then_left_behind(on, (2.43, 1.33, 2.83, 1.73, 0.6), 40)
    assert g.states(on)[tuple(g.world_to_cell(np.array([2.45, 1.5])))] == CellState.OCCUPIED
    # the far wall was never seen free, however long the robot looks away
    g = _stood_then_left_behind(on, (2.43, 1.33, 2.83, 1.73, 1.8), 60)
    j = g.world_to_cell(np.array([3.95, 0.0]))[1]
    wall = g.occupied(on)[:, j] | g.occupied(on)[:, j + 1]
    before = _stood_then_left_behind(CFG, (2.43, 1.33, 2.83, 1.73, 1.8), 60)
    assert (wall == (before.occupied(CFG)[:, j] | before.occupied(CFG)[:, j + 1])).all() and wall.sum() >= 15
    # a tall thing standing there from the start: its floor was never seen free before it
    g = _stood_then_left_behind(on, (2.43, 1.33, 2.83, 1.73, 1.8), 40, empty_frames=0)
    ij = tuple(g.world_to_cell(np.array([2.45, 1.5])))
    assert g.states(on)[ij] == CellState.OCCUPIED and not g.freed[ij] and g.quiet[ij] == 40


def test_joining_pieces_keeps_a_person_in_a_doorway_and_not_one_in_the_open():
    """5 cm cells, a wall with a 0.6 m door; the disc is the planner's 0.22 m. Only the person in the door
    parts floor the disc can travel; a person in the open, one in a corner and one in a door too narrow for the
    disc anyway part nothing."""
    free = np.ones((60, 120), np.bool_)
    free[:, 38:42] = False
    free[25:37, 38:42] = True                      # a 0.6 m door
    free[:, 78:82] = False
    free[25:31, 78:82] = True                      # a 0.3 m door: the disc does not pass it free or not
    people = np.zeros_like(free)
    people[28:34, 38:42] = True                    # in the wide door
    people[10:16, 10:16] = True                    # in the open
    people[0:4, 60:64] = True                      # against the grid's edge
    people[26:30, 78:82] = True                    # in the narrow door
    free &= ~people
    out = joining_pieces(people, free, 0.05, 0.22)
    assert out[30, 40] and out[28:34, 38:42].all() and out.sum() == 24
    # with the wide door's other side not yet known free, there is nothing to join
    alone = free.copy()
    alone[:, 42:] = False
    assert not joining_pieces(people & (np.arange(120) < 42), alone, 0.05, 0.22).any()
    assert not joining_pieces(np.zeros_like(free), free, 0.05, 0.22).any()
    # the wide door joins 3.44 m2 of the disc's positions (left, round the person in the open) to 3.535 m2
    assert joining_pieces(people, free, 0.05, 0.22, min_piece_m2=3.43).sum() == 24
    assert not joining_pieces(people, free, 0.05, 0.22, min_piece_m2=3.45).any()



def _joining_pieces_whole_grid(cells, free, cell_m, radius_m, min_piece_m2):
    """joining_pieces' definition read literally: every piece's floor recomputed over the whole grid."""
    eight = np.ones((3, 3), np.bool_)
    now = traversable_mask(free, cell_m, radius_m)
    now_lab, n_now = ndimage.label(now, structure=eight)
    area = np.bincount(now_lab.ravel(), minlength=n_now + 1) * cell_m ** 2
    now_lab = np.where(area[now_lab] >= min_piece_m2, now_lab, 0)
    pieces, n = ndimage.label(cells, structure=eight)
    keep = np.zeros(n + 1, np.bool_)
    for k in range(1, n + 1):
        gained = traversable_mask(free | (pieces == k), cell_m, radius_m) & ~now
        blobs, m = ndimage.label(gained, structure=eight)
        keep[k] = any(np.count_nonzero(np.unique(now_lab[ndimage.binary_dilation(blobs == b, structure=eight)])) >= 2
                      for b in range(1, m + 1))
    return keep[pieces]


@pytest.mark.parametrize("seed", range(6))
def test_joining_pieces_looks_only_near_each_piece_and_agrees_with_the_whole_grid(seed):
    """Random walls with doors and random small pieces, some against the grid's edge, and one door shut by a
    piece: the windowed search keeps exactly the pieces the whole-grid definition keeps."""
    rng = derive_rng(seed, "joining-pieces")
    free = np.ones((70, 90), np.bool_)
    free[:, 40:43] = False                               # a 0.6 m door with a piece shutting it
    free[20:32, 40:43] = True
    for _ in range(4):                                   # walls across the grid with a door of 6-14 cells
        if rng.random() < 0.5:
            c = int(rng.integers(5, 85))
            free[:, c:c + 3] = False
            d = int(rng.integers(0, 60))
            free[d:d + int(rng.integers(6, 15)), c:c + 3] = True
        else:
            r = int(rng.integers(5, 65))
            free[r:r + 3, :] = False
            d = int(rng.integers(0, 80))
            free[r:r + 3, d:d + int(rng.integers(6, 15))] = True
    cells = np.zeros_like(free)
    cells[25:27, 40:43] = True
    for _ in range(25):
        i, j = int(rng.integers(0, 68)), int(rng.integers(0, 88))
        cells[i:i + int(rng.integers(1, 4)), j:j + int(rng.integers(1, 4))] = True
    free &= ~cells
    for radius_m, min_m2 in ((0.22, 0.0), (0.22, 0.5), (0.12, 0.0)):
        want = _joining_pieces_whole_grid(cells, free, 0.05, radius_m, min_m2)
        assert (joining_pieces(cells, free, 0.05, radius_m, min_m2) == want).all(), (radius_m, min_m2)
        assert want.any() or radius_m < 0.2 or min_m2 > 0.0     # the door's piece joins for the planner's disc

def test_transient_cut_m_keeps_a_person_who_stood_in_the_open():
    """With transient_cut_m a let-go needs a join: the person in the open room is kept, at 0 let go."""
    person = (2.43, 1.33, 2.83, 1.73, 1.8)
    plain = dataclasses.replace(CFG, transient_frames=20, transient_cut_m=0.0)
    cut = dataclasses.replace(plain, transient_cut_m=0.22)
    for cfg, want in ((plain, CellState.FREE), (cut, CellState.OCCUPIED)):
        g = _stood_then_left_behind(cfg, person, 25)
        assert g.states(cfg)[tuple(g.world_to_cell(np.array([2.45, 1.5])))] == want, cfg.transient_cut_m


def _two_doors_grid(cfg: OccupancyConfig, pieces: list[tuple[tuple[slice, slice], float, bool]]) -> OccupancyGrid:
    """5 cm cells, 3 m x 6 m: walls at x 1.9-2.1 m and 3.9-4.1 m, each with a 0.6 m door (y 1.25-1.85 m), floor
    seen free everywhere else; ``pieces``: ((rows, cols), top m, freed) of cells held occupied, quiet 100 frames
    like the walls."""
    logodds = np.full((60, 120), cfg.logodds_min, np.float32)
    top = np.zeros((60, 120), np.float32)
    freed = np.ones((60, 120), np.bool_)
    for c in (slice(38, 42), slice(78, 82)):
        logodds[:, c], top[:, c], freed[:, c] = 2.0, 2.0, False
        logodds[25:37, c], top[25:37, c], freed[25:37, c] = cfg.logodds_min, 0.0, True
    for (rows, cols), t, f in pieces:
        logodds[rows, cols], top[rows, cols], freed[rows, cols] = 0.9, t, f
    return OccupancyGrid((0, 0), 0.05, logodds, top, freed, np.full((60, 120), 100, np.int32))


def test_the_cut_rule_lets_go_a_person_who_shut_a_door_and_nothing_else():
    """transient_cut_m: a piece below a standing height in the first door, on floor seen free before it, goes (the
    plain rule keeps it); the same not seen free before (the second door), a person in the open, a piece larger
    than transient_piece_m2 and the walls (quiet, but one large piece, never seen free) stay."""
    cut = dataclasses.replace(OccupancyConfig(cell_m=0.05), transient_frames=50, transient_cut_m=0.22)
    door, other, open_floor = (slice(30, 32), slice(39, 41)), (slice(30, 32), slice(79, 81)), (slice(10, 12),
                                                                                              slice(10, 12))
    g = _two_doors_grid(cut, [(door, 0.96, True), (other, 1.5, False), (open_floor, 1.5, True)])
    nothing = np.zeros(g.shape, np.bool_)
    after = let_go(g, cut, g.logodds, g.top_m, nothing)
    assert after.free(cut)[door].all() and (after.top_m[door] == 0).all()
    assert (after.logodds != g.logodds).sum() == 4                  # only the first door's piece
    plain = dataclasses.replace(cut, transient_cut_m=0.0)
    by_plain = let_go(g, plain, g.logodds, g.top_m, nothing)           # the person in the open only
    assert not by_plain.free(plain)[door].any() and by_plain.free(plain)[open_floor].all()
    # too big a piece: the door's 0.01 m2 above transient_piece_m2; the floor of a door shut whole joins its walls,
    # one piece with them, far too big
    small = dataclasses.replace(cut, transient_piece_m2=0.005)
    assert not let_go(g, small, g.logodds, g.top_m, nothing).free(small)[door].any()
    g3 = _two_doors_grid(cut, [((slice(25, 37), slice(78, 82)), 1.5, True)])
    assert not let_go(g3, cut, g3.logodds, g3.top_m, nothing).free(cut)[25:37, 78:82].any()
    # a return in the last transient_frames frames keeps it (the person is still there)
    g4 = OccupancyGrid(g.origin_ij, g.cell_m, g.logodds, g.top_m, g.freed, np.where(
        np.arange(120) == 39, 10, g.quiet).astype(np.int32))
    assert not let_go(g4, cut, g4.logodds, g4.top_m, nothing).free(cut)[door].any()


def test_transient_people_frames_lets_go_only_a_piece_with_people_returns_near_it():
    """transient_people_frames: the door's piece goes only where it, or a cell within transient_clear_m of it,
    held people returns in that many frames (someone seen moving there); furniture never seen moving stays."""
    cut = dataclasses.replace(OccupancyConfig(cell_m=0.05), transient_frames=50, transient_cut_m=0.22,
                              transient_people_frames=2)
    door = (slice(30, 32), slice(39, 41))
    g = _two_doors_grid(cut, [(door, 0.96, True)])
    nothing = np.zeros(g.shape, np.bool_)
    assert not let_go(g, cut, g.logodds, g.top_m, nothing).free(cut)[door].any()      # no people returns
    off = dataclasses.replace(cut, transient_people_frames=0)
    assert let_go(g, off, g.logodds, g.top_m, nothing).free(off)[door].all()
    for (i, j), frames, goes in (((32, 40), 2, True), ((32, 40), 1, False), ((31, 43), 2, True),
                                 ((31, 44), 2, False), ((10, 10), 5, False)):
        people = np.zeros(g.shape, np.int32)
        people[i, j] = frames                  # (31, 43): 0.15 m from the piece's edge cell; (31, 44): 0.2 m
        gp = dataclasses.replace(g, people=people)
        assert let_go(gp, cut, g.logodds, g.top_m, nothing).free(cut)[door].all() == goes, ((i, j), frames)
    # the frame's own people cells are counted before the test: one more frame makes 2
    people = np.zeros(g.shape, np.int32)
    people[30, 39] = 1
    seen = people > 0
    after = let_go(dataclasses.replace(g, people=people), cut, g.logodds, g.top_m, nothing, seen)
    assert after.people[30, 39] == 2 and after.free(cut)[door].all()


def test_rays_passing_high_over_a_low_obstacle_leave_it_occupied():
    seat = (2.03, 1.33, 2.43, 1.73, 0.5)
    depth, K, T, _ = _room_frame(boxes=[seat], x=0.3)             # seen from 1.7 m
    beta = np.zeros_like(depth)
    g = OccupancyGrid.empty(CFG.cell_m)
    for _ in range(3):
        g = update_occupancy(g, CFG, depth, K, T, beta)
    ij = tuple(g.world_to_cell(np.array([2.05, 1.5])))
    assert g.states(CFG)[ij] == CellState.OCCUPIED and 0.4 < g.top_m[ij] <= 0.5
    # from 1 m the seat is below the field of view and no ray hits it; the lowest rays cross its
    # cell at 0.6 m and more, which says nothing about a 0.5 m seat
    empty_depth, K, T, _ = _room_frame(boxes=[seat], x=1.0)
    kept, cleared = g, g
    for _ in range(8):
        kept = update_occupancy(kept, CFG, empty_depth, K, T, beta)
        cleared = update_occupancy(cleared, dataclasses.replace(CFG, clear_below_m=math.inf), empty_depth, K, T, beta)
    assert kept.states(CFG)[ij] == CellState.OCCUPIED
    assert cleared.states(CFG)[ij] == CellState.FREE                # the whole-ray rule erases it
    assert kept.states(CFG)[tuple(kept.world_to_cell(np.array([3.5, 1.5])))] == CellState.FREE   # floor near the wall


def test_grid_grows_without_moving_what_it_knows():
    depth, K, T, _ = _room_frame()
    beta = np.zeros_like(depth)
    g = OccupancyGrid.allocate((0.5, 1.0), (1.5, 2.0), CFG.cell_m)
    assert g.shape == (10, 10)
    for _ in range(6):                                          # 6 frames: the floor is held at logodds_min (freed)
        g = update_occupancy(g, CFG, depth, K, T, beta)
    assert g.freed.any() and g.quiet.max() == 6
    assert g.shape[1] * CFG.cell_m >= 3.5
    wall_ij = g.world_to_cell(np.array([4.05, 1.5]))
    before = g.logodds[tuple(wall_ij)]
    assert g.grown_to_include(np.array([1.0, 1.0]), np.array([2.0, 2.0]), CFG.grow_chunk_m) is g
    g2 = g.grown_to_include(np.array([-0.3, 0.5]), np.array([1.0, 1.0]), CFG.grow_chunk_m)
    assert g2.origin_xy_m[0] == pytest.approx(-2.0) and g2.origin_ij[1] == -20     # snapped to 2 m chunks
    assert g2.shape[1] == g.shape[1] + 20
    assert g2.logodds[tuple(g2.world_to_cell(np.array([4.05, 1.5])))] == before
    for a, b in ((g.freed, g2.freed), (g.quiet, g2.quiet), (g.top_m, g2.top_m)):   # the per-cell history moves too
        assert b.sum() == a.sum() and b[tuple(g2.world_to_cell(np.array([4.05, 1.5])))] == a[tuple(wall_ij)]
    np.testing.assert_allclose(g2.cell_to_world(g2.world_to_cell(np.array([1.23, 2.34]))), [1.25, 2.35])


def test_update_is_pure():
    depth, K, T, _ = _room_frame()
    g0 = OccupancyGrid.allocate((0, 0), (4, 3), CFG.cell_m)
    snapshot = g0.logodds.copy()
    update_occupancy(g0, CFG, depth, K, T, np.zeros_like(depth))
    np.testing.assert_array_equal(g0.logodds, snapshot)


def test_bad_config_values_raise_config_error():
    with pytest.raises(ConfigError):
        OccupancyConfig(band_lo_m=2.0, band_hi_m=1.0)
    with pytest.raises(ConfigError):
        dataclasses.replace(CFG, l_free=0.3)
    with pytest.raises(ConfigError):
        OccupancyConfig(pixel_stride=0)
    with pytest.raises(ConfigError, match="transient_frames"):
        OccupancyConfig(transient_frames=-1)
    with pytest.raises(ConfigError, match="transient_top_m"):
        OccupancyConfig(transient_top_m=1.6)
    with pytest.raises(ConfigError, match="transient_cut_m"):
        OccupancyConfig(transient_cut_m=-0.1)
    with pytest.raises(ConfigError, match="transient_cut_min_m2"):
        OccupancyConfig(transient_cut_min_m2=-1.0)
    with pytest.raises(ConfigError, match="transient_people_frames"):
        OccupancyConfig(transient_people_frames=-1)
    with pytest.raises(ConfigError, match="transient_ring_free"):
        OccupancyConfig(transient_ring_free=1.5)
