"""A 2D occupancy grid of what the robot has seen, updated from RGB-D frames.

The grid holds log-odds per floor cell. It is the map that the Voronoi graph, subregions
and planner are built on (DESIGN.md §5 Selection: "a 2D occupancy map of the static scene;
people's returns are not made permanent obstacles").

Grid convention (the same as :mod:`dynactivegs.sim.freespace`): cell ``(i, j)`` (row ``i``
along +y, column ``j`` along +x) covers ``[x0 + j r, x0 + (j+1) r) x [y0 + i r, y0 + (i+1) r)``
with ``(x0, y0) = origin_xy_m`` and ``r = cell_m``; its centre is at
``origin + (j + 0.5, i + 0.5) r``. The origin is always an integer multiple of ``cell_m``
(stored as integer cell offsets) so that growing the grid never shifts cell boundaries.

Update rule for one frame (see :func:`update_occupancy`):

- Each valid pixel (depth > 0, within ``max_range_m``) is back-projected to a world point.
- Its ray's ground projection, from the camera's cell up to the point's cell, is *seen free*,
  except in cells where an obstacle has been seen that the ray passes over: a ray high above
  the floor says nothing about a low obstacle under it (a seat, a bed). Each cell keeps the
  top of the highest static obstacle return seen in it (``OccupancyGrid.top_m``); a ray
  clears such a cell only where it passes lower than that top (through where the obstacle
  was: a person who has walked on) or lower than ``clear_below_m``. Cells with no obstacle
  seen yet are cleared by any ray (the floor near the robot is below the field of view).
  The camera's own cell is free.
- Points lower than ``band_lo_m`` are floor: their own cell is seen free too.
- Points inside the body's height band ``[band_lo_m, band_hi_m]`` are obstacles: their cell
  is *seen occupied*, unless the pixel's uncertainty ``beta`` exceeds ``beta_max`` (probably
  a moving person): such a return still clears the cells before it but adds no occupancy.
- Points above the band (ceiling, wall tops) clear the cells before them; their own cell is
  left as it is.
- Per frame a cell gets at most one update: ``+l_occ`` if seen occupied (occupied wins
  over free), else ``+l_free`` if seen free. Log-odds are clamped to
  ``[logodds_min, logodds_max]``. Counting per frame rather than per ray makes the result
  independent of the ray order and of the pixel density.

A low obstacle not yet hit can be marked free by rays passing over it; once a ray hits it,
``l_occ`` outweighs ``l_free`` and rays passing over it no longer clear it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numba
import numpy as np
from scipy import ndimage

from dynactivegs.errors import check_config
from dynactivegs.selection.voronoi import traversable_mask



class CellState(IntEnum):
    """What a cell of the occupancy grid is believed to be."""

    UNKNOWN = 0
    FREE = 1
    OCCUPIED = 2


@dataclass(frozen=True, slots=True)
class OccupancyConfig:
    """How RGB-D frames update the 2D occupancy grid."""

    cell_m: float = 0.05
    """Cell size in metres."""
    band_lo_m: float = 0.1
    """Points lower than this above the floor are floor (free); the obstacle band starts here."""
    band_hi_m: float = 1.5
    """Points between band_lo_m and this height are obstacles for the robot's body."""
    clear_below_m: float = 0.4
    """A ray clears a cell with an obstacle seen in it only where it passes lower than this or than the
    obstacle's top (inf: every ray clears every cell it passes)."""
    max_range_m: float = 6.0
    """Returns farther than this (horizontal distance) are cut: the ray is free up to this range, no endpoint."""
    beta_max: float = 0.75
    """Pixels whose uncertainty beta is above this are treated as dynamic: they clear space but add no occupancy
    (fields.beta_static, the level of static surfaces: at 0.5 about a third of static returns were left out)."""
    l_free: float = -0.4
    """Log-odds added to a cell seen free in a frame."""
    l_occ: float = 0.85
    """Log-odds added to a cell seen occupied in a frame."""
    logodds_min: float = -2.0
    """Lower clamp of the log-odds (lets a wrongly free cell become occupied again in a few frames)."""
    logodds_max: float = 2.0
    """Upper clamp of the log-odds: a wrongly occupied cell, e.g. a person who stood still (a calm person's returns
    have a low beta), is cleared in 6 frames that see through it (at l_free -0.4). At 3.5 it took 10: on full,
    apartment-00, seed 1 (with recheck_on_reopen), a person stood 17 steps in the west doorway, the robot saw
    the doorway empty for 7 frames, and the cells left shut the graph there for the rest of the run
    (benchmarks/occupancy_errors.py on its log: 0.045 m2 of open floor held occupied at the end, 0 at 2.0;
    walls and furniture held free 1.32 -> 1.48 m2). Measured with full, 1000 steps, on apartment-00..03 x seeds
    0-2 (benchmarks/results/apartment-1000-lomax; Acc cm / C.R. % / PSNR dB, mean of 12, 3.5 -> 2.0): 3.00 /
    90.04 / 22.91 -> 2.82 / 90.72 / 23.22; apartment-00 seed 1 5.23 / 65.2 / 15.09 -> 3.15 / 76.7 / 17.20.
    Per run it is mixed: 5 runs better on all three, 5 worse."""
    free_below: float = -0.2
    """A cell with log-odds below this is FREE."""
    occupied_above: float = 0.2
    """A cell with log-odds above this is OCCUPIED; in between is UNKNOWN."""
    pixel_stride: int = 1
    """Use every n-th pixel in both image directions (1 = all pixels)."""
    grow_chunk_m: float = 2.0
    """When a frame reaches beyond the grid, the grid grows to the enclosing multiple of this many metres."""
    transient_frames: int = 50
    """A cell held occupied by someone who stood still is let go (made free again) after this many frames with no
    static obstacle return in it, when it is *transient*: it was held at ``logodds_min`` (seen free in several
    frames) before any obstacle was seen in it, so was every cell within ``transient_clear_m`` of it, and its
    returns reached ``transient_top_m`` (a standing person's height, not a table's or a chair's). A person who
    stood still has a low beta, so their returns become obstacles (``beta_max``), and only frames that see through
    the spot clear them again (``logodds_max``); a robot that walked away from the spot does not see it again
    and the cells cut the graph meanwhile. On ``motion_view``, apartment-00, seed 1 (1000 steps,
    benchmarks/results/apartment-1000-machine2/full_local_people_3), two people stood 35 steps inside the bedroom
    door at steps 265-300, the robot left for the far end of the flat, and the 0.095 m2 of floor they left
    occupied cut the kitchen (and the bathroom behind it) off the graph until step 590, when the robot came back
    past the spot: a bathroom never seen, 17.86 dB. Let go, a cell is free again with log-odds ``free_below +
    l_free``, so one occupied return makes it occupied again (the person is still there). Measured: on that
    run's logged frames, at 50 the kitchen is joined to the robot's graph again from step 340 on
    (benchmarks/occupancy_errors.py: open floor held occupied 0.095 -> 0.008 m2 at step 499); the same run in
    closed loop saw every room (99.3 % of the held-out views' surface, 25.26 dB). On ``full``, 1000 steps, the 4
    apartment scenes x seeds 0-2, one machine (benchmarks/results/apartment-1000-machine2/full_transient_50; Acc
    cm / C.R. % / PSNR dB, mean of 12, 0 -> 50): 2.53 / 92.9 / 24.25 -> 2.56 / 93.0 / 24.05; 2 runs the same, PSNR
    lower in 8 of the other 10 (-0.20 +- 0.52 dB over 12), none of them a failed run; ``baseline`` (12 pairs):
    2.92 / 92.1 / 24.26 -> 3.07 / 91.5 / 24.00, PSNR lower in 8. With it on both, full beat baseline on all three
    in 6 of the 12 pairs (3 with it off on both), but the criteria set before the runs also asked that the 24
    runs' mean PSNR drop by no more than 0.10 dB (it dropped 0.23), so the plain rule is not the default; the
    default 50 is for the cut rule (``transient_cut_m``, on by default), which lets only the pieces go that shut
    the graph. 0: never let go (cells clear only by frames that see through them; the defaults before the cut
    rule)."""
    transient_clear_m: float = 0.15
    """A cell is transient only where every cell within this distance was seen free before any obstacle (open
    floor around a person, not the inside of a shelf)."""
    transient_top_m: float = 1.2
    """A cell is transient (``transient_frames``) only where its highest static obstacle return (``top_m``)
    reached this height: a standing person; tables, seats and counters are lower."""
    transient_cut_m: float = 0.22
    """With ``transient_frames``, the *cut rule*: let a small piece of shut cells go only where its going joins
    pieces of the floor not held occupied (seen free or not seen yet) that a disc of this radius can travel and
    that were apart (the planner's robot radius plus margin, 0.22 m, for the Voronoi graph's own test): a person
    who stood in a doorway or a passage, not one who stood in the open, where the graph goes round them. A piece
    that joins nothing now may go later, when more is known around it. The pieces are 8-connected cells not
    believed free, each with an obstacle return but none for ``transient_frames`` frames and each seen free
    before its first return (``freed``), at most ``transient_piece_m2`` in all, with at least
    ``transient_ring_free`` of the floor within ``transient_clear_m`` round them free; unlike the plain rule no
    height is asked, so a person whose returns in a cell stayed below a standing height goes too, and so may a
    low thing on floor seen free before it (a chair moved in the way is tried again). Measured on ``full``,
    apartment-03 seed 0 (1000 steps, one machine, its logged frames): two pieces of two cells each parted the
    passage they stood in (truth clearance 0.36-0.45 m) and cut 2.6-5.6 m2 of floor off the robot from step about
    300 to the end; one (top 0.96 m) was seen free before, the other (top 1.50 m) was not. The plain rule let
    neither go; this one lets the first go at step 301. Closed loop (benchmarks/results/apartment-1000-machine3, 6
    pairs of full and baseline; only the 4 runs in whose frames it lets cells go differ): that run 23.39 -> 24.81 dB
    (Obs. views 88.6 -> 98.6 %). Over 12 pairs (apartment-00..03 x seeds 0-2, same machine,
    benchmarks/results/apartment-1000-machine3-cut; it let cells go in 12 of the 24 runs' logged frames, 1-3
    frames each, and only those were run again), with it on both against off on both: full 2.45 / 93.3 / 24.00
    against 2.53 / 93.1 / 23.87, baseline 3.04 / 92.2 / 24.42 against 2.89 / 92.3 / 24.46, the 24 runs' mean PSNR
    +0.04 dB, full beating baseline on all three in 3 of 12 pairs against 2; the criteria written before the last
    16 runs (more pairs won, mean PSNR at most 0.10 dB lower) held, so it is on by default. 0: the plain rule
    (every transient cell goes); ``transient_frames`` 0 turns both off."""
    transient_piece_m2: float = 0.2
    """With ``transient_cut_m``, the largest piece of shut cells that may go (a person's footprint; walls and
    furniture hold larger connected pieces)."""
    transient_ring_free: float = 0.75
    """With ``transient_cut_m``, the least share of the cells within ``transient_clear_m`` round a piece that must
    be believed free for it to go (a person stands on open floor; a fragment of a wall has unseen or occupied
    cells round it)."""
    transient_people_frames: int = 0
    """With ``transient_cut_m``, a piece goes only where some cell of it or within ``transient_clear_m`` of it held
    people returns (obstacle-band returns with beta above ``beta_max``: someone seen moving,
    :attr:`OccupancyGrid.people`) in at least this many frames: a person who walked there and then stood still,
    not a piece of furniture that was never seen moving. 0: no such test (the default). Measured open loop on 52
    logs at the defaults (benchmarks/let_go_events.py: machine3's 12 apartment runs where the cut rule let cells
    go, its 24 loop-suite runs and 16 runs of the face gains): the rule let 35 pieces go, 26 on the static
    scene's free floor (people) and 9 in furniture, and every one had people returns within transient_clear_m in
    3-49 frames (furniture 3-46, in its own cells 1-36): beta rises over furniture too. At 5 it would keep 3 of
    the 26 people pieces and 2 of the 9 furniture ones, at 10 9 and 3: no threshold tells them apart, so it
    stays 0."""
    transient_cut_min_m2: float = 0.5
    """With ``transient_cut_m``, pieces of the floor a disc can travel smaller than this (m2 of the disc's centre
    positions) do not count as joined: pockets beside furniture. Measured on ``full``, apartment-00 seed 0 (1000
    steps, logged frames): without it the rule let go twice, each time joining a pocket of 0.003-0.13 m2. At 0.25
    it would free a 0.33 m2 strip two people's pieces held parted for 116 steps (baseline, loop-03 seed 2), but over
    52 logs at the defaults on one machine (benchmarks/let_go_events.py, open loop) it lets 57 pieces go against 35:
    2 more on the static scene's free floor (people), 20 more in furniture."""

    def __post_init__(self) -> None:
        check_config(0.005 <= self.cell_m <= 1.0, "occupancy.cell_m", self.cell_m, "in [0.005, 1] m")
        check_config(0.0 <= self.band_lo_m < self.band_hi_m, "occupancy.band_lo_m", self.band_lo_m,
                 ">= 0 and below occupancy.band_hi_m")
        check_config(self.clear_below_m > self.band_lo_m, "occupancy.clear_below_m", self.clear_below_m,
                     "above occupancy.band_lo_m")
        check_config(self.max_range_m > 0.0, "occupancy.max_range_m", self.max_range_m, "> 0 m")
        check_config(self.beta_max > 0.0, "occupancy.beta_max", self.beta_max, "> 0")
        check_config(self.l_free < 0.0, "occupancy.l_free", self.l_free, "< 0")
        check_config(self.l_occ > 0.0, "occupancy.l_occ", self.l_occ, "> 0")
        check_config(self.logodds_min < self.free_below, "occupancy.logodds_min", self.logodds_min,
                 "below occupancy.free_below")
        check_config(self.free_below <= 0.0 <= self.occupied_above, "occupancy.free_below", self.free_below,
                 "<= 0 <= occupancy.occupied_above")
        check_config(self.occupied_above < self.logodds_max, "occupancy.logodds_max", self.logodds_max,
                 "above occupancy.occupied_above")
        check_config(1 <= self.pixel_stride <= 64, "occupancy.pixel_stride", self.pixel_stride, "in [1, 64]")
        check_config(self.grow_chunk_m >= self.cell_m, "occupancy.grow_chunk_m", self.grow_chunk_m, ">= occupancy.cell_m")
        check_config(self.transient_frames >= 0, "occupancy.transient_frames", self.transient_frames,
                     ">= 0 (0: never let a cell go)")
        check_config(self.band_lo_m < self.transient_top_m <= self.band_hi_m, "occupancy.transient_top_m",
                     self.transient_top_m, "in (occupancy.band_lo_m, occupancy.band_hi_m]")
        check_config(0.0 <= self.transient_cut_m <= 2.0, "occupancy.transient_cut_m", self.transient_cut_m,
                     "in [0, 2] m (0: let every transient piece go)")
        check_config(self.transient_people_frames >= 0, "occupancy.transient_people_frames",
                     self.transient_people_frames, ">= 0 (0: no people-return test)")
        check_config(self.transient_cut_min_m2 >= 0.0, "occupancy.transient_cut_min_m2", self.transient_cut_min_m2,
                     ">= 0 m2")
        check_config(self.transient_piece_m2 > 0.0, "occupancy.transient_piece_m2", self.transient_piece_m2, "> 0 m2")
        check_config(0.0 <= self.transient_ring_free <= 1.0, "occupancy.transient_ring_free", self.transient_ring_free,
                     "in [0, 1]")


@dataclass(frozen=True, slots=True)
class OccupancyGrid:
    """Log-odds occupancy of floor cells. Immutable: updates return a new grid."""

    origin_ij: tuple[int, int]    # (row, col) offset of cell (0, 0) in cell units: origin_xy = (col, row) * cell_m
    cell_m: float
    logodds: np.ndarray           # float32 (H, W); 0 = never seen
    top_m: np.ndarray | None = None   # float32 (H, W): highest static obstacle return seen in the cell (0: none)
    freed: np.ndarray | None = None   # bool (H, W): the cell was held at logodds_min before any obstacle was seen in it
    quiet: np.ndarray | None = None   # int32 (H, W): frames since the cell last had a static obstacle return
    people: np.ndarray | None = None  # int32 (H, W): frames in which the cell held a people return (a dynamic one)

    def __post_init__(self) -> None:
        assert self.logodds.ndim == 2 and self.logodds.dtype == np.float32
        for name, dtype in (("top_m", np.float32), ("freed", np.bool_), ("quiet", np.int32), ("people", np.int32)):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(self.logodds.shape, dtype))
            a = getattr(self, name)
            assert a.shape == self.logodds.shape and a.dtype == dtype, f"{name} {a.shape} {a.dtype}"
            a.flags.writeable = False
        self.logodds.flags.writeable = False

    # ------------------------------------------------------------------ construction
    @staticmethod
    def empty(cell_m: float) -> "OccupancyGrid":
        """A grid with no cells; the first update allocates what it needs."""
        return OccupancyGrid((0, 0), float(cell_m), np.zeros((0, 0), np.float32))

    @staticmethod
    def allocate(lo_xy_m, hi_xy_m, cell_m: float) -> "OccupancyGrid":
        """An all-unknown grid covering at least the box ``[lo, hi]`` (xy, metres), aligned to ``cell_m``."""
        lo = np.asarray(lo_xy_m, np.float64)
        hi = np.asarray(hi_xy_m, np.float64)
        assert lo.shape == (2,) and hi.shape == (2,) and np.all(hi >= lo)
        j0, i0 = np.floor(lo / cell_m).astype(np.int64)
        j1, i1 = np.ceil(hi / cell_m).astype(np.int64)
        h, w = max(int(i1 - i0), 1), max(int(j1 - j0), 1)
        return OccupancyGrid((int(i0), int(j0)), float(cell_m), np.zeros((h, w), np.float32))

    # ------------------------------------------------------------------ coordinates
    @property
    def shape(self) -> tuple[int, int]:
        return self.logodds.shape  # type: ignore[return-value]

    @property
    def origin_xy_m(self) -> np.ndarray:
        """float64 (2,): world xy of the grid's lower-left corner."""
        return np.array([self.origin_ij[1], self.origin_ij[0]], np.float64) * self.cell_m

    def world_to_cell(self, xy_m: np.ndarray) -> np.ndarray:
        """int64 (..., 2) (row, col) of the cells containing world points ``xy_m (..., 2)``; may be out of range."""
        g = np.floor(np.asarray(xy_m, np.float64) / self.cell_m).astype(np.int64)
        return np.stack([g[..., 1] - self.origin_ij[0], g[..., 0] - self.origin_ij[1]], axis=-1)

    def cell_to_world(self, ij: np.ndarray) -> np.ndarray:
        """float64 (..., 2) world xy of the centres of cells ``ij (..., 2)`` given as (row, col)."""
        ij = np.asarray(ij)
        return self.origin_xy_m + (ij[..., ::-1].astype(np.float64) + 0.5) * self.cell_m

    def in_bounds(self, ij: np.ndarray) -> np.ndarray:
        h, w = self.shape
        return (ij[..., 0] >= 0) & (ij[..., 0] < h) & (ij[..., 1] >= 0) & (ij[..., 1] < w)

    # ------------------------------------------------------------------ classification
    def states(self, cfg: OccupancyConfig) -> np.ndarray:
        """uint8 (H, W) of :class:`CellState` values."""
        out = np.full(self.shape, CellState.UNKNOWN, np.uint8)
        out[self.logodds < cfg.free_below] = CellState.FREE
        out[self.logodds > cfg.occupied_above] = CellState.OCCUPIED
        return out

    def free(self, cfg: OccupancyConfig) -> np.ndarray:
        """bool (H, W): cells believed free."""
        return self.logodds < cfg.free_below

    def occupied(self, cfg: OccupancyConfig) -> np.ndarray:
        """bool (H, W): cells believed occupied."""
        return self.logodds > cfg.occupied_above

    def unknown(self, cfg: OccupancyConfig) -> np.ndarray:
        """bool (H, W): cells neither believed free nor occupied."""
        return ~self.free(cfg) & ~self.occupied(cfg)

    # ------------------------------------------------------------------ growth
    def grown_to_include(self, lo_xy_m: np.ndarray, hi_xy_m: np.ndarray, chunk_m: float) -> "OccupancyGrid":
        """This grid, enlarged (new cells unknown) so that it covers ``[lo, hi]``.

        New bounds snap outwards to multiples of ``chunk_m`` (rounded to whole cells), so
        that a robot moving slowly outwards does not reallocate the grid every frame.
        Returns ``self`` when nothing needs to change.
        """
        chunk = max(1, int(round(chunk_m / self.cell_m)))
        g_lo = np.floor(np.asarray(lo_xy_m, np.float64) / self.cell_m).astype(np.int64)   # (col, row)
        g_hi = np.floor(np.asarray(hi_xy_m, np.float64) / self.cell_m).astype(np.int64) + 1
        h, w = self.shape
        i0, j0 = self.origin_ij
        if h and w and g_lo[1] >= i0 and g_lo[0] >= j0 and g_hi[1] <= i0 + h and g_hi[0] <= j0 + w:
            return self
        n_i0 = (int(g_lo[1]) // chunk) * chunk
        n_j0 = (int(g_lo[0]) // chunk) * chunk
        n_i1 = -((-int(g_hi[1])) // chunk) * chunk
        n_j1 = -((-int(g_hi[0])) // chunk) * chunk
        if h and w:
            n_i0, n_j0 = min(n_i0, i0), min(n_j0, j0)
            n_i1, n_j1 = max(n_i1, i0 + h), max(n_j1, j0 + w)
        old = (slice(i0 - n_i0, i0 - n_i0 + h), slice(j0 - n_j0, j0 - n_j0 + w))
        arrays = []
        for a in (self.logodds, self.top_m, self.freed, self.quiet, self.people):
            b = np.zeros((n_i1 - n_i0, n_j1 - n_j0), a.dtype)
            if h and w:
                b[old] = a
            arrays.append(b)
        return OccupancyGrid((n_i0, n_j0), self.cell_m, *arrays)


@dataclass(frozen=True, slots=True)
class FrameRays:
    """The 2D rays of one frame in grid coordinates (continuous cell units: x = col, y = row)."""

    start_g: np.ndarray           # float64 (2,) camera position, (x, y) in cell units of the grid
    start_z_m: float              # camera height
    end_g: np.ndarray             # float64 (N, 2) ray ends, (x, y) in cell units of the grid
    end_z_m: np.ndarray           # float64 (N,) height of the ray at its end (clipped at max_range_m)
    end_free: np.ndarray          # bool (N,) the end cell itself is seen free (floor return)
    end_occupied: np.ndarray      # bool (N,) the end cell is seen occupied (static obstacle return)
    end_people: np.ndarray        # bool (N,) the end is a people return: in the band, in range, beta above beta_max


def backproject(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, stride: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """World points of the valid pixels of a depth image.

    ``depth_m`` float32 (H, W) z-depth, 0 = no return; ``K`` (3, 3) with pixel centres at
    +0.5; ``T_world_cam`` (4, 4). Returns float64 (N, 3) world points and int64 (N,) flat pixel
    indices (row-major into (H, W)) of the pixels used (every ``stride``-th row and column).
    """
    assert depth_m.ndim == 2 and K.shape == (3, 3) and T_world_cam.shape == (4, 4)
    h, w = depth_m.shape
    rows = np.arange(0, h, stride)
    cols = np.arange(0, w, stride)
    d = depth_m[np.ix_(rows, cols)].astype(np.float64)
    ok = np.isfinite(d) & (d > 0)
    r_idx, c_idx = np.nonzero(ok)
    z = d[r_idx, c_idx]
    v = rows[r_idx] + 0.5
    u = cols[c_idx] + 0.5
    x = (u - K[0, 2] - K[0, 1] * (v - K[1, 2]) / K[1, 1]) / K[0, 0] * z
    y = (v - K[1, 2]) / K[1, 1] * z
    p_cam = np.stack([x, y, z], axis=1)
    p_world = p_cam @ T_world_cam[:3, :3].T + T_world_cam[:3, 3]
    return p_world, rows[r_idx] * w + cols[c_idx]


def body_band_returns(cfg: OccupancyConfig, depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                      beta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The frame's world points (every ``pixel_stride``-th pixel, :func:`backproject`), float64 (N, 3), their
    horizontal distance from the camera, float64 (N,), and per point bool (N,): inside the body's height band
    ``[band_lo_m, band_hi_m]``, and dynamic (beta above ``beta_max``). A point is beyond range where its distance
    exceeds ``max_range_m``."""
    assert beta.shape == depth_m.shape, f"beta {beta.shape} must match depth {depth_m.shape}"
    pts, pix = backproject(depth_m, K, T_world_cam, cfg.pixel_stride)
    dist = np.hypot(*(pts[:, :2] - T_world_cam[:2, 3]).T)
    z = pts[:, 2]
    return pts, dist, (z >= cfg.band_lo_m) & (z <= cfg.band_hi_m), beta.reshape(-1)[pix] > cfg.beta_max


def frame_rays(grid: OccupancyGrid, cfg: OccupancyConfig, depth_m: np.ndarray, K: np.ndarray,
               T_world_cam: np.ndarray, beta: np.ndarray,
               returns: tuple[np.ndarray, ...] | None = None) -> tuple[OccupancyGrid, FrameRays]:
    """Classify the frame's returns and express the rays in the (grown if needed) grid's coordinates.

    ``beta`` float32 (H, W): per-pixel uncertainty, high on probably-moving things. The grid
    is returned grown to contain the camera and all ray ends (log-odds unchanged). ``returns``: the
    frame's :func:`body_band_returns`, when the caller has them already (computed here otherwise).
    """
    if returns is None:
        returns = body_band_returns(cfg, depth_m, K, T_world_cam, beta)
    pts, dist, band, dynamic = returns
    cam_xy = T_world_cam[:2, 3].astype(np.float64)
    delta = pts[:, :2] - cam_xy
    far = dist > cfg.max_range_m
    scale = np.where(far, cfg.max_range_m / np.maximum(dist, 1e-12), 1.0)
    end_xy = cam_xy + delta * scale[:, None]
    z = pts[:, 2]
    cam_z = float(T_world_cam[2, 3])
    end_z = cam_z + (z - cam_z) * scale
    end_free = (z < cfg.band_lo_m) & ~far
    end_occ = band & ~far & ~dynamic
    end_people = band & ~far & dynamic
    lo = np.minimum(end_xy.min(axis=0), cam_xy) if len(end_xy) else cam_xy
    hi = np.maximum(end_xy.max(axis=0), cam_xy) if len(end_xy) else cam_xy
    grid = grid.grown_to_include(lo, hi, cfg.grow_chunk_m)
    off = np.array([grid.origin_ij[1], grid.origin_ij[0]], np.float64)
    return grid, FrameRays(cam_xy / grid.cell_m - off, cam_z, end_xy / grid.cell_m - off, end_z, end_free, end_occ,
                           end_people)


@numba.njit(cache=True, nogil=True)
def _trace_free(start_g, start_z, end_g, end_z, end_free, top_m, clear_below, seen_free):  # pragma: no cover
    """Amanatides-Woo traversal of every segment start -> end_k; marks a cell it passes as free where no
    obstacle was seen (top_m 0) or the ray's lowest height in it is below max(top_m, clear_below).

    The end cell is marked only where ``end_free[k]``. The number of cells of an exact
    traversal is 1 + |di| + |dj|, so the loop runs exactly that many steps (robust to round-off).
    """
    h, w = seen_free.shape
    x0, y0 = start_g[0], start_g[1]
    ci0, cj0 = int(math.floor(y0)), int(math.floor(x0))
    for k in range(end_g.shape[0]):
        x1, y1 = end_g[k, 0], end_g[k, 1]
        dz = end_z[k] - start_z
        ei, ej = int(math.floor(y1)), int(math.floor(x1))
        dx, dy = x1 - x0, y1 - y0
        sj = 1 if dx > 0 else -1
        si = 1 if dy > 0 else -1
        tdx = abs(1.0 / dx) if dx != 0 else np.inf
        tdy = abs(1.0 / dy) if dy != 0 else np.inf
        if dx > 0:
            tmx = (cj0 + 1 - x0) / dx
        elif dx < 0:
            tmx = (cj0 - x0) / dx
        else:
            tmx = np.inf
        if dy > 0:
            tmy = (ci0 + 1 - y0) / dy
        elif dy < 0:
            tmy = (ci0 - y0) / dy
        else:
            tmy = np.inf
        n = abs(ei - ci0) + abs(ej - cj0)
        i, j = ci0, cj0
        t_in = 0.0
        for s in range(n + 1):
            if s == n:
                if end_free[k] and 0 <= i < h and 0 <= j < w:
                    seen_free[i, j] = True
                break
            t_out = min(tmx, tmy, 1.0)
            low = start_z + min(t_in * dz, t_out * dz)             # the ray is straight: lowest at an end
            if 0 <= i < h and 0 <= j < w and (top_m[i, j] <= 0.0 or low < max(top_m[i, j], clear_below)):
                seen_free[i, j] = True
            t_in = t_out
            if tmx < tmy:
                tmx += tdx
                j += sj
            else:
                tmy += tdy
                i += si
    # the camera's own cell is always free
    if 0 <= ci0 < h and 0 <= cj0 < w:
        seen_free[ci0, cj0] = True


def _end_cells(rays: FrameRays, which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) int64 of the cells holding the ends of the rays ``which`` (bool (N,)), in ray order."""
    e = rays.end_g[which]
    return np.floor(e[:, 1]).astype(np.int64), np.floor(e[:, 0]).astype(np.int64)


def people_cells(shape: tuple[int, int], rays: FrameRays) -> np.ndarray:
    """bool (H, W): the cells holding the frame's people returns (:attr:`FrameRays.end_people`)."""
    seen = np.zeros(shape, np.bool_)
    seen[_end_cells(rays, rays.end_people)] = True     # the grid holds every ray end (frame_rays)
    return seen


def obstacle_tops(top_m: np.ndarray, rays: FrameRays) -> np.ndarray:
    """float32 (H, W): ``top_m`` raised to this frame's static obstacle returns (their heights)."""
    top = top_m.copy()
    np.maximum.at(top, _end_cells(rays, rays.end_occupied), rays.end_z_m[rays.end_occupied].astype(np.float32))
    return top


def seen_masks(shape: tuple[int, int], rays: FrameRays, top_m: np.ndarray,
               clear_below_m: float) -> tuple[np.ndarray, np.ndarray]:
    """bool (H, W) cells seen free and seen occupied by the rays of one frame (fast kernel);
    ``top_m`` (H, W): obstacle tops including this frame's (:func:`obstacle_tops`)."""
    seen_free = np.zeros(shape, np.bool_)
    _trace_free(rays.start_g, float(rays.start_z_m), np.ascontiguousarray(rays.end_g),
                np.ascontiguousarray(rays.end_z_m, dtype=np.float64), rays.end_free,
                np.ascontiguousarray(top_m, dtype=np.float32), float(clear_below_m), seen_free)
    seen_occ = np.zeros(shape, np.bool_)
    seen_occ[_end_cells(rays, rays.end_occupied)] = True
    return seen_free, seen_occ


def apply_seen(logodds: np.ndarray, seen_free: np.ndarray, seen_occ: np.ndarray, cfg: OccupancyConfig) -> np.ndarray:
    """float32 (H, W): one frame's log-odds update (occupied wins over free), clamped."""
    delta = np.where(seen_occ, np.float32(cfg.l_occ), np.where(seen_free, np.float32(cfg.l_free), np.float32(0.0)))
    return np.clip(logodds + delta, np.float32(cfg.logodds_min), np.float32(cfg.logodds_max)).astype(np.float32)


def update_occupancy(grid: OccupancyGrid, cfg: OccupancyConfig, depth_m: np.ndarray, K: np.ndarray,
                     T_world_cam: np.ndarray, beta: np.ndarray,
                     returns: tuple[np.ndarray, ...] | None = None) -> OccupancyGrid:
    """The grid after integrating one RGB-D frame (see the module docstring for the rule).

    ``depth_m`` float32 (H, W) z-depth in metres (0 = no return); ``K`` float64 (3, 3);
    ``T_world_cam`` float64 (4, 4) camera -> world; ``beta`` float32 (H, W) uncertainty.
    The grid grows when the frame reaches beyond it. Pure: ``grid`` is not modified. ``returns``: the frame's
    :func:`body_band_returns` when the caller has them already.
    """
    assert abs(grid.cell_m - cfg.cell_m) < 1e-12, "grid and config cell sizes differ"
    grid, rays = frame_rays(grid, cfg, depth_m, K, T_world_cam, beta, returns)
    top = obstacle_tops(grid.top_m, rays)
    seen_free, seen_occ = seen_masks(grid.shape, rays, top, cfg.clear_below_m)
    return let_go(grid, cfg, apply_seen(grid.logodds, seen_free, seen_occ, cfg), top, seen_occ,
                  people_cells(grid.shape, rays))


def let_go(grid: OccupancyGrid, cfg: OccupancyConfig, logodds: np.ndarray, top: np.ndarray,
           seen_occ: np.ndarray, seen_people: np.ndarray | None = None) -> OccupancyGrid:
    """The grid of one frame's update (``logodds`` and ``top`` after it, ``seen_occ`` its occupied cells,
    ``seen_people`` its cells with people returns, :func:`people_cells`), with the transient cells that had no
    static obstacle return for ``transient_frames`` frames made free again
    (:attr:`OccupancyConfig.transient_frames`; nothing changes at 0)."""
    freed = grid.freed | ((logodds <= np.float32(cfg.logodds_min)) & (top <= 0.0))
    quiet = np.where(seen_occ, 0, np.minimum(grid.quiet, np.iinfo(np.int32).max - 1) + 1).astype(np.int32)
    people = grid.people if seen_people is None else (
        np.minimum(grid.people, np.iinfo(np.int32).max - 1) + seen_people).astype(np.int32)
    stale = None
    if cfg.transient_frames > 0 and cfg.transient_cut_m > 0.0:               # the cut rule
        stale = shut_pieces(logodds, top, freed, quiet, grid.cell_m, cfg, people)
        if stale.any():
            open_floor = (logodds <= np.float32(cfg.occupied_above)) & ~stale     # free or not seen yet
            stale = joining_pieces(stale, open_floor, grid.cell_m, cfg.transient_cut_m, cfg.transient_cut_min_m2)
    elif cfg.transient_frames > 0:                                              # the plain rule
        stale = (freed & (quiet >= cfg.transient_frames) & (top >= np.float32(cfg.transient_top_m))
                 & (logodds > np.float32(cfg.free_below)))
        if stale.any():                            # the floor-all-round test only where a cell could go
            stale &= ndimage.binary_erosion(freed, structure=_clear_disc(cfg, grid.cell_m), border_value=0)
    if stale is not None and stale.any():
        logodds = np.where(stale, np.float32(cfg.free_below + cfg.l_free), logodds).astype(np.float32)
        top = np.where(stale, np.float32(0.0), top).astype(np.float32)
    return OccupancyGrid(grid.origin_ij, grid.cell_m, logodds, top, freed, quiet, people)


_EIGHT = np.ones((3, 3), np.bool_)                 # 8-connected pieces


def _around(sl: tuple[slice, slice], pad: int, shape: tuple[int, int]) -> tuple[slice, slice]:
    """The bounding box ``sl`` (``ndimage.find_objects``) grown by ``pad`` cells each way, clipped to ``shape``."""
    return tuple(slice(max(s.start - pad, 0), min(s.stop + pad, m)) for s, m in zip(sl, shape))


def _clear_disc(cfg: OccupancyConfig, cell_m: float) -> np.ndarray:
    """bool (2r+1, 2r+1): the cells within ``transient_clear_m`` of a centre cell (r in cells, rounded)."""
    r = int(round(cfg.transient_clear_m / cell_m))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return yy ** 2 + xx ** 2 <= r * r


def shut_pieces(logodds: np.ndarray, top: np.ndarray, freed: np.ndarray, quiet: np.ndarray, cell_m: float,
                cfg: OccupancyConfig, people: np.ndarray | None = None) -> np.ndarray:
    """bool (H, W): the cut rule's candidates (:attr:`OccupancyConfig.transient_cut_m`): 8-connected pieces of
    cells not believed free, each with an obstacle return (``top`` > 0) but none for ``transient_frames``
    frames, every cell ``freed``, of at most ``transient_piece_m2``, and with at least ``transient_ring_free`` of
    the cells within ``transient_clear_m`` round the piece believed free; with ``transient_people_frames``, also
    some cell of the piece or within ``transient_clear_m`` of it with people returns (``people``, int (H, W)
    frames, :attr:`OccupancyGrid.people`) in that many frames."""
    cand = (logodds > np.float32(cfg.free_below)) & (quiet >= cfg.transient_frames) & (top > 0.0)
    pieces, n = ndimage.label(cand, structure=_EIGHT)
    if n == 0:
        return cand
    flat = pieces.ravel()
    area = np.bincount(flat, minlength=n + 1) * cell_m ** 2
    n_freed = np.bincount(flat, weights=freed.ravel(), minlength=n + 1)
    ok = (area <= cfg.transient_piece_m2 + 1e-9) & (n_freed * cell_m ** 2 >= area - 1e-9)     # every cell freed
    ok[0] = False
    disc = _clear_disc(cfg, cell_m)
    r = disc.shape[0] // 2
    free = logodds < np.float32(cfg.free_below)
    for k, sl in enumerate(ndimage.find_objects(pieces), start=1):
        if not ok[k]:
            continue
        box = _around(sl, r, cand.shape)
        piece = pieces[box] == k
        near = ndimage.binary_dilation(piece, structure=disc)
        ring = near & ~piece
        ok[k] = ring.any() and free[box][ring].mean() >= cfg.transient_ring_free
        if ok[k] and cfg.transient_people_frames > 0:
            ok[k] = people is not None and int(people[box][near].max()) >= cfg.transient_people_frames
    return ok[pieces]


def joining_pieces(cells: np.ndarray, free: np.ndarray, cell_m: float, radius_m: float,
                   min_piece_m2: float = 0.0) -> np.ndarray:
    """bool (H, W): the 8-connected pieces of ``cells`` whose going (that piece made free, the others kept) joins
    floor that a disc of ``radius_m`` can travel (:func:`~dynactivegs.selection.voronoi.traversable_mask`) and that
    is apart now: some 8-connected blob of the floor that becomes passable touches two or more 8-connected pieces
    of the floor passable now, each of at least ``min_piece_m2``."""
    now = traversable_mask(free, cell_m, radius_m)
    now_lab, n_now = ndimage.label(now, structure=_EIGHT)
    if min_piece_m2 > 0.0 and n_now:
        area = np.bincount(now_lab.ravel(), minlength=n_now + 1) * cell_m ** 2
        now_lab = np.where(area[now_lab] >= min_piece_m2, now_lab, 0)
    pieces, n = ndimage.label(cells, structure=_EIGHT)
    keep = np.zeros(n + 1, np.bool_)
    pad = int(np.ceil(radius_m / cell_m)) + 1          # a piece changes the disc's floor within radius_m of it only
    for k, sl in enumerate(ndimage.find_objects(pieces), start=1):
        # the window holds every cell within 2 pads of the piece; the inner part's clearance test sees the
        # whole grid's obstacles (those within a pad), so the floor gained there is the whole grid's
        win = _around(sl, 2 * pad, cells.shape)
        inner = tuple(slice(s.start - ws.start, s.stop - ws.start) for s, ws in zip(_around(sl, pad, cells.shape), win))
        gained = (traversable_mask(free[win] | (pieces[win] == k), cell_m, radius_m) & ~now[win])[inner]
        lab_w = now_lab[win][inner]
        blobs, _ = ndimage.label(gained, structure=_EIGHT)
        for b, bs in enumerate(ndimage.find_objects(blobs), start=1):
            box = _around(bs, 1, gained.shape)
            ring = ndimage.binary_dilation(blobs[box] == b, structure=_EIGHT)
            touched = np.unique(lab_w[box][ring])
            if np.count_nonzero(touched) >= 2:
                keep[k] = True
                break
    return keep[pieces]
