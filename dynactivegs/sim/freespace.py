"""The navigable 2D map at robot height, computed from the static mesh.

Used by the simulator for spawning and collision, by the crowd for path following, and by
the evaluation. Never by the planner: the planner only knows what the robot has seen.

Grid convention: cell ``(i, j)`` (row ``i`` along +y, column ``j`` along +x) covers
``[x0 + j r, x0 + (j+1) r) x [y0 + i r, y0 + (i+1) r)`` where ``(x0, y0) = origin_xy_m`` and
``r = res_m``; its centre is at ``origin + (j + 0.5, i + 0.5) r``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage


@dataclass(frozen=True)
class FreeSpace:
    """Occupancy of the floor plane: where there is floor, and where obstacles stand."""

    origin_xy_m: np.ndarray       # float64 (2,), world xy of the grid's lower-left corner
    res_m: float                  # cell size
    floor: np.ndarray             # bool (H, W), a walkable floor surface exists under the cell
    occupied: np.ndarray          # bool (H, W), some static surface lies in the body's height band
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        assert self.floor.shape == self.occupied.shape and self.floor.ndim == 2
        assert self.origin_xy_m.shape == (2,)
        self.floor.flags.writeable = False
        self.occupied.flags.writeable = False

    @staticmethod
    def from_grid(occupied: np.ndarray, res_m: float, origin_xy_m=(0.0, 0.0),
                  floor: np.ndarray | None = None) -> "FreeSpace":
        """A map from a hand-made occupancy array (floor everywhere unless given)."""
        occupied = np.asarray(occupied, dtype=bool).copy()
        floor = np.ones_like(occupied) if floor is None else np.asarray(floor, dtype=bool).copy()
        return FreeSpace(np.asarray(origin_xy_m, dtype=np.float64), float(res_m), floor, occupied)

    @property
    def shape(self) -> tuple[int, int]:
        return self.floor.shape  # type: ignore[return-value]

    # ------------------------------------------------------------------ coordinates
    def world_to_cell(self, xy_m: np.ndarray) -> np.ndarray:
        """Integer cell indices ``(..., 2)`` as (row, col) for world points ``(..., 2)``; may be out of range."""
        xy_m = np.asarray(xy_m, dtype=np.float64)
        ij = np.floor((xy_m - self.origin_xy_m) / self.res_m).astype(np.int64)
        return ij[..., ::-1]

    def cell_to_world(self, ij: np.ndarray) -> np.ndarray:
        """World xy ``(..., 2)`` of the centres of cells ``(..., 2)`` given as (row, col)."""
        ij = np.asarray(ij)
        return self.origin_xy_m + (ij[..., ::-1].astype(np.float64) + 0.5) * self.res_m

    def in_bounds(self, ij: np.ndarray) -> np.ndarray:
        h, w = self.shape
        return (ij[..., 0] >= 0) & (ij[..., 0] < h) & (ij[..., 1] >= 0) & (ij[..., 1] < w)

    # ------------------------------------------------------------------ derived maps
    @property
    def blocked(self) -> np.ndarray:
        """Cells a body centre can never occupy: no floor, or an obstacle."""
        return self._cached("blocked", lambda: ~self.floor | self.occupied)

    @property
    def clearance_m(self) -> np.ndarray:
        """float64 (H, W): distance from each cell centre to the nearest blocked cell's boundary (0 inside)."""
        def compute() -> np.ndarray:
            padded = np.pad(~self.blocked, 1, constant_values=False)  # outside the grid is blocked
            d = ndimage.distance_transform_edt(padded)[1:-1, 1:-1] * self.res_m
            return np.where(self.blocked, 0.0, np.maximum(d - 0.5 * self.res_m, 0.0))
        return self._cached("clearance", compute)

    def navigable(self, radius_m: float) -> np.ndarray:
        """bool (H, W): cells where a disc of ``radius_m`` fits, restricted to the largest connected component."""
        def compute() -> np.ndarray:
            ok = ~self.blocked & (self.clearance_m >= radius_m)
            labels, n = ndimage.label(ok)
            if n == 0:
                return ok
            sizes = np.bincount(labels.ravel())
            sizes[0] = 0
            return labels == int(np.argmax(sizes))
        return self._cached(("navigable", round(radius_m, 6)), compute)

    def free_area_m2(self) -> float:
        """Area of floor not covered by obstacles, in the largest connected region."""
        return float(self.navigable(0.0).sum()) * self.res_m ** 2

    def is_navigable(self, xy_m: np.ndarray, radius_m: float) -> np.ndarray:
        """bool (...): whether discs of ``radius_m`` centred at ``xy_m (..., 2)`` fit in free space."""
        ij = self.world_to_cell(xy_m)
        ok = self.in_bounds(ij)
        nav = self.navigable(radius_m)
        h, w = self.shape
        out = np.zeros(ij.shape[:-1], dtype=bool)
        out[ok] = nav[np.clip(ij[..., 0], 0, h - 1), np.clip(ij[..., 1], 0, w - 1)][ok]
        return out

    def segment_navigable(self, a_xy_m: np.ndarray, b_xy_m: np.ndarray, radius_m: float) -> bool:
        """Whether a disc of ``radius_m`` can slide along the segment a -> b without leaving free space."""
        a = np.asarray(a_xy_m, dtype=np.float64)
        b = np.asarray(b_xy_m, dtype=np.float64)
        n = max(2, int(np.ceil(np.linalg.norm(b - a) / (0.5 * self.res_m))) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return bool(self.is_navigable(a + t * (b - a), radius_m).all())

    def obstacle_points_xy(self) -> np.ndarray:
        """float64 (N, 2): centres of blocked cells that touch a non-blocked cell (the obstacle boundary)."""
        def compute() -> np.ndarray:
            inner = ndimage.binary_erosion(self.blocked, structure=np.ones((3, 3), bool), border_value=True)
            edge = self.blocked & ~inner
            return self.cell_to_world(np.argwhere(edge))
        return self._cached("obstacle_points", compute)

    def sample_navigable(self, rng: np.random.Generator, n: int, radius_m: float) -> np.ndarray:
        """float64 (n, 2): uniformly random points (cell centre plus jitter) where a disc of ``radius_m`` fits."""
        cells = np.argwhere(self.navigable(radius_m))
        if len(cells) == 0:
            raise ValueError(f"no navigable cell for radius {radius_m} m")
        pick = cells[rng.integers(0, len(cells), size=n)]
        return self.cell_to_world(pick)

    def _cached(self, key, compute):
        if key not in self._cache:
            value = compute()
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            self._cache[key] = value
        return self._cache[key]
