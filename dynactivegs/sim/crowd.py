"""Walking people: goals, grid paths, ORCA avoidance and a hard no-collision guard.

Each person walks from goal to goal through free space. A goal is a random reachable
place at least ``cfg.min_goal_dist_m`` away (straight line); the path to it is planned
with Dijkstra on an 8-connected graph of the navigable cells (for the person's radius) at
about 0.1 m resolution, then shortened by string pulling with line-of-sight tests on the
full-resolution navigable grid. Per substep:

1. Preferred velocity: toward the current waypoint at the person's speed (slowing to
   arrive exactly at the goal). A waypoint is skipped as soon as the next one is in
   line of sight.
2. ORCA (:mod:`dynactivegs.sim.orca`) against the other people (reciprocal), the robot
   (non-reciprocal: people take full responsibility) and the static obstacles.
3. Hard guard, person by person in a fixed order: the move is accepted only if the new
   position is navigable for the person's radius and it does not increase the overlap
   with any other person (at its already-updated position) or with the robot disc;
   otherwise a move along only x or only y is tried, else the person stays put. Hence
   people never walk into walls, furniture, each other or the robot, whatever ORCA says.

A person whose remaining path length does not shrink by ``cfg.stuck_speed_frac`` of what
its speed covers in ``cfg.stuck_timeout_s`` within that time (standing in a jam, or inching
into one) picks a new goal, planned on a graph from which the cells other people and the
robot stand on are removed (so someone jammed at a door turns away from the jam); one whose
waypoint stays out of sight for a second replans to the same goal.
The gait phase advances by 2 pi per stride of walked distance (stride proportional to
height) and the heading turns smoothly toward the walking direction.

Everything is deterministic: the generator passed in is used only at construction and
when choosing goals, and the numeric kernels are fixed-order loops.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from dynactivegs.sim.config import CrowdConfig
from dynactivegs.errors import ConfigError
from dynactivegs.sim.freespace import FreeSpace, grid_graph
from dynactivegs.sim.humans import HumanLook, people_mesh, sample_look, stride_length_m
from dynactivegs.sim.orca import ObstacleIndex, orca_velocities

_PLAN_RES_M = 0.1             # target cell size of the path-planning graph
_GOAL_TOL_M = 0.1             # a waypoint or the goal this close counts as reached
_PROGRESS_M = 0.05            # shortening the remaining path by at least this much counts as progress
_BLIND_REPLAN_S = 1.0         # waypoint out of sight this long -> replan to the same goal
_HEADING_TAU_S = 0.25         # time constant of the heading filter
_HEADING_RATE_RPS = math.pi   # the heading turns at most this fast
_GAIT_SPEED_TAU_S = 0.3       # time constant of the speed that drives the limb swing
_SPAWN_MARGIN_M = 0.05        # extra gap between spawned people


# ---------------------------------------------------------------------------------------
# numba kernels on the navigable grid (same cell convention as FreeSpace.world_to_cell)

@numba.njit(cache=True, inline="always")
def _nav_at(nav: np.ndarray, ox: float, oy: float, res: float, x: float, y: float) -> bool:
    j = int(np.floor((x - ox) / res))
    i = int(np.floor((y - oy) / res))
    if i < 0 or j < 0 or i >= nav.shape[0] or j >= nav.shape[1]:
        return False
    return nav[i, j]


@numba.njit(cache=True)
def _segment_clear(nav: np.ndarray, ox: float, oy: float, res: float, ax: float, ay: float,
                   bx: float, by: float) -> bool:
    """Same test as FreeSpace.segment_navigable: samples every res/2 along a -> b are navigable."""
    dx, dy = bx - ax, by - ay
    n = max(2, int(np.ceil(np.sqrt(dx * dx + dy * dy) / (0.5 * res))) + 1)
    for k in range(n):
        t = k / (n - 1)
        if not _nav_at(nav, ox, oy, res, ax + t * dx, ay + t * dy):
            return False
    return True


@numba.njit(cache=True)
def _preferred(pos, speed, wp, wp_start, wp_index, dt, nav, ox, oy, res, out_pref, out_visible, out_at_goal):
    """Advance waypoints and write preferred velocities (P, 2); flags whether the waypoint is visible / goal reached."""
    for i in range(len(pos)):
        last = wp_start[i + 1] - 1
        k = wp_start[i] + wp_index[i]
        px, py = pos[i, 0], pos[i, 1]
        # skip ahead while the next waypoint is in sight or the current one is passed
        while k < last:
            d = np.hypot(wp[k, 0] - px, wp[k, 1] - py)
            if d < _GOAL_TOL_M or _segment_clear(nav, ox, oy, res, px, py, wp[k + 1, 0], wp[k + 1, 1]):
                k += 1
            else:
                break
        wp_index[i] = k - wp_start[i]
        tx, ty = wp[k, 0] - px, wp[k, 1] - py
        d = np.hypot(tx, ty)
        out_at_goal[i] = k == last and d < _GOAL_TOL_M
        out_visible[i] = _segment_clear(nav, ox, oy, res, px, py, wp[k, 0], wp[k, 1])
        if d < 1e-9:
            out_pref[i, 0] = 0.0
            out_pref[i, 1] = 0.0
            continue
        s = speed[i]
        if k == last:
            s = min(s, d / dt)            # arrive at the goal without overshooting
        out_pref[i, 0] = tx / d * s
        out_pref[i, 1] = ty / d * s


@numba.njit(cache=True)
def _move_ok(i, x, y, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r) -> bool:
    if not _nav_at(nav, ox, oy, res, x, y):
        return False
    px, py = pos[i, 0], pos[i, 1]
    for j in range(len(pos)):
        if j == i:
            continue
        rr = radius[i] + radius[j]
        new_ov = rr - np.hypot(x - pos[j, 0], y - pos[j, 1])
        if new_ov > 0.0 and new_ov > rr - np.hypot(px - pos[j, 0], py - pos[j, 1]):
            return False
    if robot_r > 0.0:
        rr = radius[i] + robot_r
        new_ov = rr - np.hypot(x - robot_x, y - robot_y)
        if new_ov > 0.0 and new_ov > rr - np.hypot(px - robot_x, py - robot_y):
            return False
    return True


@numba.njit(cache=True)
def _guarded_moves(pos, vel, radius, dt, nav, ox, oy, res, robot_x, robot_y, robot_r, out_step):
    """Move people one at a time (index order), accepting only safe moves; writes the displacement (P, 2)."""
    for i in range(len(pos)):
        px, py = pos[i, 0], pos[i, 1]
        dx, dy = vel[i, 0] * dt, vel[i, 1] * dt
        nx, ny = px, py
        if _move_ok(i, px + dx, py + dy, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r):
            nx, ny = px + dx, py + dy
        elif abs(dx) >= abs(dy):
            if _move_ok(i, px + dx, py, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r):
                nx = px + dx
            elif _move_ok(i, px, py + dy, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r):
                ny = py + dy
        else:
            if _move_ok(i, px, py + dy, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r):
                ny = py + dy
            elif _move_ok(i, px + dx, py, pos, radius, nav, ox, oy, res, robot_x, robot_y, robot_r):
                nx = px + dx
        out_step[i, 0] = nx - px
        out_step[i, 1] = ny - py
        pos[i, 0] = nx
        pos[i, 1] = ny


# ---------------------------------------------------------------------------------------
# planning graph

def _obstacle_boundary_xy(fs: FreeSpace) -> np.ndarray:
    """float64 (N, 2): centres of blocked cells next to free cells, including cells just outside the grid."""
    blocked = np.pad(fs.blocked, 1, constant_values=True)
    near_free = ndimage.binary_dilation(~blocked, structure=np.ones((3, 3), bool))
    ij = np.argwhere(blocked & near_free) - 1
    return fs.cell_to_world(ij)


class _PlanGraph:
    """8-connected graph over coarse cells whose fine cells are all navigable."""

    def __init__(self, nav: np.ndarray, res_m: float, origin_xy_m: np.ndarray) -> None:
        f = max(1, int(round(_PLAN_RES_M / res_m)))
        h, w = nav.shape
        hc, wc = -(-h // f), -(-w // f)
        padded = np.zeros((hc * f, wc * f), bool)
        padded[:h, :w] = nav
        coarse = padded.reshape(hc, f, wc, f).all(axis=(1, 3))
        if not coarse.any():
            raise ConfigError("crowd: no free space wide enough for a person; lower crowd.radius_m")
        self.factor = f
        self.cell_m = f * res_m
        self.origin_xy_m = origin_xy_m
        self.coarse = coarse
        ids = -np.ones(coarse.shape, np.int64)
        ids[coarse] = np.arange(int(coarse.sum()))
        self.ids = ids
        self.graph, self.cells = grid_graph(coarse, self.cell_m)    # cells: (n, 2) row, col
        self.centres_xy_m = origin_xy_m + (self.cells[:, ::-1] + 0.5) * self.cell_m
        n = len(self.cells)
        self._edge_row = np.repeat(np.arange(n), np.diff(self.graph.indptr))
        self._tree = cKDTree(self.centres_xy_m)
        # nearest coarse node for any coarse cell (people can stand in cells that are not nodes)
        _, near = ndimage.distance_transform_edt(~coarse, return_indices=True)
        self.nearest_id = ids[near[0], near[1]]

    def node_of(self, xy_m: np.ndarray) -> int:
        ij = np.floor((xy_m - self.origin_xy_m) / self.cell_m).astype(np.int64)[::-1]
        ij = np.clip(ij, 0, np.array(self.coarse.shape) - 1)
        return int(self.nearest_id[ij[0], ij[1]])

    def search(self, src: int, closed_xy_m: np.ndarray | None = None,
               closed_radius_m: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Path lengths (n,) in metres (inf if unreachable) and predecessors (n,) from node ``src``.

        Nodes within ``closed_radius_m (K,)`` of ``closed_xy_m (K, 2)`` (except ``src``) are
        left out of the search.
        """
        graph = self.graph
        if closed_xy_m is not None and len(closed_xy_m):
            closed = np.zeros(len(self.centres_xy_m), bool)
            for hits in self._tree.query_ball_point(closed_xy_m, closed_radius_m):
                closed[hits] = True
            closed[src] = False
            data = np.where(closed[self._edge_row] | closed[graph.indices], np.inf, graph.data)
            graph = sparse.csr_matrix((data, graph.indices, graph.indptr), shape=graph.shape)
        dist, pred = csgraph.dijkstra(graph, directed=True, indices=src, return_predecessors=True)
        return dist, pred

    def path_xy(self, pred: np.ndarray, src: int, dst: int) -> np.ndarray:
        nodes = [dst]
        while nodes[-1] != src:
            nodes.append(int(pred[nodes[-1]]))
            assert nodes[-1] >= 0, "destination is unreachable from the source"
        return self.centres_xy_m[nodes[::-1]]


# ---------------------------------------------------------------------------------------

class Crowd:
    """The people of one scene and their motion; see the module docstring."""

    def __init__(self, cfg: CrowdConfig, freespace: FreeSpace, rng: np.random.Generator,
                 avoid_xy_m: np.ndarray, avoid_radius_m: float) -> None:
        """Spawn the people.

        Args:
            cfg: crowd parameters.
            freespace: the scene's floor map; people walk in ``freespace.navigable(cfg.radius_m)``.
            rng: the crowd's own generator (spawn, looks, speeds, goals).
            avoid_xy_m: float (2,) centre of a disc nobody spawns on (the robot).
            avoid_radius_m: radius of that disc.
        """
        avoid_xy_m = np.asarray(avoid_xy_m, dtype=np.float64)
        assert avoid_xy_m.shape == (2,)
        self.cfg = cfg
        self.freespace = freespace
        self._rng = rng
        self._nav = np.ascontiguousarray(freespace.navigable(cfg.radius_m))
        self._origin = freespace.origin_xy_m.astype(np.float64)
        self._res = float(freespace.res_m)
        count = cfg.count if cfg.count >= 0 else max(1, int(freespace.free_area_m2() // cfg.area_per_person_m2))
        self._plan = _PlanGraph(self._nav, self._res, self._origin) if count > 0 else None
        self._obstacles = ObstacleIndex.build(_obstacle_boundary_xy(freespace), cell_m=1.0)
        # ORCA's static discs sit on blocked-cell centres; a navigable position is at least
        # r + res/2 - res/sqrt(2) from every one of them, so that is the combined radius used
        # (the hard guard, not ORCA, enforces navigability exactly)
        self._obstacle_radius_m = self._res * (0.5 - math.sqrt(0.5))

        self._pos = self._spawn(count, avoid_xy_m, float(avoid_radius_m))
        p = len(self._pos)
        self._radius = np.full(p, cfg.radius_m)
        self._looks = tuple(sample_look(rng) for _ in range(p))
        self._height = np.array([lk.height_m for lk in self._looks])
        self._speed = cfg.speed_mps * rng.uniform(0.8, 1.2, size=p)
        self._vel = np.zeros((p, 2))
        self._gait_phase = rng.uniform(0.0, 2.0 * np.pi, size=p)
        self._gait_speed = np.zeros(p)
        self._time_s = 0.0
        self._walked_m = np.zeros(p)
        self._goals_reached = np.zeros(p, np.int64)
        self._paths: list[np.ndarray] = [np.zeros((1, 2))] * p
        self._wp_index = np.zeros(p, np.int64)
        self._progress_d = np.full(p, np.inf)
        self._progress_m = np.maximum(_PROGRESS_M, cfg.stuck_speed_frac * self._speed * cfg.stuck_timeout_s)
        self._progress_t = np.zeros(p)
        self._blind_s = np.zeros(p)
        self._goal_tree: list[tuple[int, np.ndarray] | None] = [None] * p
        self._robot_xy, self._robot_r = avoid_xy_m, float(avoid_radius_m)
        for i in range(p):
            self._new_goal(i)
        self._pack_paths()
        first = np.array([path[0] for path in self._paths]).reshape(-1, 2) - self._pos
        self._heading = np.where(np.hypot(first[:, 0], first[:, 1]) > 1e-9, np.arctan2(first[:, 1], first[:, 0]),
                                 rng.uniform(-np.pi, np.pi, size=p))

    # ------------------------------------------------------------------ construction helpers
    def _spawn(self, count: int, avoid_xy_m: np.ndarray, avoid_radius_m: float) -> np.ndarray:
        r = self.cfg.radius_m
        placed: list[np.ndarray] = []
        for _ in range(200):
            if len(placed) == count:
                break
            for c in self.freespace.sample_navigable(self._rng, 256, r):
                if len(placed) == count:
                    break
                if np.hypot(*(c - avoid_xy_m)) < r + avoid_radius_m + _SPAWN_MARGIN_M:
                    continue
                if placed and np.min(np.hypot(*(np.array(placed) - c).T)) < 2 * r + _SPAWN_MARGIN_M:
                    continue
                placed.append(c)
        if len(placed) < count:
            raise ConfigError(f"crowd.count={count} people of radius {r} m do not fit in this scene's free space; "
                              f"only {len(placed)} could be placed")
        return np.array(placed, dtype=np.float64).reshape(-1, 2)

    def _new_goal(self, i: int, around_people: bool = False) -> None:
        """Pick a reachable goal at least min_goal_dist_m away and plan the path to it.

        With ``around_people`` (used when the person is stuck, typically in a jam at a
        door) the planning graph loses the nodes that other people and the robot stand
        on, so the goal and path lead away from the jam instead of into it.
        """
        src = self._plan.node_of(self._pos[i])
        if around_people:
            xy = [np.delete(self._pos, i, axis=0)]
            rr = [self._radius[i] + np.delete(self._radius, i)]
            if self._robot_r > 0:
                xy.append(self._robot_xy[None])
                rr.append(np.array([self._radius[i] + self._robot_r]))
            dist, pred = self._plan.search(src, np.concatenate(xy), np.concatenate(rr))
        else:
            dist, pred = self._plan.search(src)
        reachable = np.flatnonzero(np.isfinite(dist))
        straight = np.hypot(*(self._plan.centres_xy_m[reachable] - self._pos[i]).T)
        far = reachable[straight >= self.cfg.min_goal_dist_m]
        if len(far) == 0:  # a small or jammed region: take the farther half of what is reachable
            far = reachable[straight >= 0.5 * straight.max()]
        dst = int(far[self._rng.integers(len(far))])
        self._set_path(i, self._plan.path_xy(pred, src, dst))
        self._progress_d[i] = np.inf
        self._progress_t[i] = self._time_s

    def _replan(self, i: int) -> None:
        """Plan again to the current goal from where the person stands.

        The shortest-path tree rooted at the goal is computed at the first replan for a
        goal and reused for later ones (the graph is symmetric, so following predecessors
        from any node leads to the goal along a shortest path).
        """
        goal_node = self._plan.node_of(self._paths[i][-1])
        if self._goal_tree[i] is None or self._goal_tree[i][0] != goal_node:
            _, pred = self._plan.search(goal_node)
            self._goal_tree[i] = (goal_node, pred)
        pred = self._goal_tree[i][1]
        src = self._plan.node_of(self._pos[i])
        if src != goal_node and pred[src] < 0:
            self._new_goal(i)
            return
        nodes = [src]
        while nodes[-1] != goal_node:
            nodes.append(int(pred[nodes[-1]]))
        self._set_path(i, self._plan.centres_xy_m[nodes])

    def _set_path(self, i: int, nodes_xy: np.ndarray) -> None:
        pts = np.concatenate([self._pos[i][None], nodes_xy])
        keep = [0]
        a = 0
        for k in range(1, len(pts) - 1):   # string pulling: keep a node only where sight is lost
            if not _segment_clear(self._nav, self._origin[0], self._origin[1], self._res,
                                  pts[a, 0], pts[a, 1], pts[k + 1, 0], pts[k + 1, 1]):
                keep.append(k)
                a = k
        keep.append(len(pts) - 1)
        self._paths[i] = pts[keep[1:]] if len(keep) > 1 else pts[-1:]
        self._wp_index[i] = 0
        self._blind_s[i] = 0.0
        self._packed = None

    def _pack_paths(self) -> None:
        lengths = np.array([len(pth) for pth in self._paths], np.int64)
        self._wp_start = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
        self._wp = np.ascontiguousarray(np.concatenate(self._paths)) if self._paths else np.zeros((0, 2))
        rest = []
        for pth in self._paths:    # path length from each waypoint on to the goal
            seg = np.hypot(*np.diff(pth, axis=0).T)
            rest.append(np.concatenate([np.cumsum(seg[::-1])[::-1], [0.0]]))
        self._wp_rest = np.concatenate(rest) if rest else np.zeros(0)
        self._packed = True

    # ------------------------------------------------------------------ simulation
    def step(self, dt_s: float, robot_xy_m: np.ndarray, robot_vel_mps: np.ndarray, robot_radius_m: float) -> None:
        """Advance the crowd by ``dt_s`` seconds in substeps of at most ``cfg.substep_s``.

        Args:
            dt_s: simulated time to advance, > 0.
            robot_xy_m: float (2,) robot position (held fixed during the step).
            robot_vel_mps: float (2,) robot velocity, used by ORCA's prediction.
            robot_radius_m: robot disc radius; 0 means there is no robot.
        """
        assert dt_s > 0
        robot_xy_m = np.asarray(robot_xy_m, dtype=np.float64).reshape(2)
        robot_vel_mps = np.asarray(robot_vel_mps, dtype=np.float64).reshape(2)
        self._robot_xy, self._robot_r = robot_xy_m, float(robot_radius_m)
        n_sub = max(1, int(math.ceil(dt_s / self.cfg.substep_s - 1e-9)))
        h = dt_s / n_sub
        for _ in range(n_sub):
            self._substep(h, robot_xy_m, robot_vel_mps, float(robot_radius_m))

    def _substep(self, h: float, robot_xy: np.ndarray, robot_vel: np.ndarray, robot_r: float) -> None:
        p = len(self._pos)
        if p == 0:
            self._time_s += h
            return
        cfg = self.cfg
        if self._packed is None:
            self._pack_paths()
        pref = np.empty((p, 2))
        visible = np.empty(p, np.bool_)
        at_goal = np.empty(p, np.bool_)
        ox, oy = self._origin
        _preferred(self._pos, self._speed, self._wp, self._wp_start, self._wp_index, h, self._nav, ox, oy,
                   self._res, pref, visible, at_goal)
        if robot_r > 0:
            others = dict(other_xy_m=robot_xy[None], other_vel_mps=robot_vel[None],
                          other_radius_m=np.array([robot_r]))
        else:
            others = {}
        new_vel = orca_velocities(self._pos, self._vel, pref, self._radius, self._speed, dt_s=h,
                                  time_horizon_s=cfg.time_horizon_s,
                                  obstacle_time_horizon_s=cfg.obstacle_time_horizon_s,
                                  neighbor_dist_m=cfg.neighbor_dist_m, obstacles=self._obstacles,
                                  obstacle_radius_m=self._obstacle_radius_m, **others)
        moved = np.empty((p, 2))
        _guarded_moves(self._pos, new_vel, self._radius, h, self._nav, ox, oy, self._res,
                       robot_xy[0], robot_xy[1], robot_r, moved)
        self._time_s += h
        self._vel = moved / h
        dist = np.hypot(moved[:, 0], moved[:, 1])
        self._walked_m += dist
        self._gait_phase = np.mod(self._gait_phase + 2.0 * np.pi * dist / stride_length_m(self._height), 2.0 * np.pi)
        speed = dist / h
        self._gait_speed += (speed - self._gait_speed) * min(1.0, h / _GAIT_SPEED_TAU_S)
        walking = speed > 0.05
        target = np.arctan2(self._vel[:, 1], self._vel[:, 0])
        turn = np.mod(target - self._heading + np.pi, 2.0 * np.pi) - np.pi
        turn = np.clip(turn * min(1.0, h / _HEADING_TAU_S), -_HEADING_RATE_RPS * h, _HEADING_RATE_RPS * h)
        self._heading = np.where(walking, np.mod(self._heading + turn + np.pi, 2.0 * np.pi) - np.pi, self._heading)

        # bookkeeping: goals, progress (remaining path length), line of sight
        k = self._wp_start[:-1] + self._wp_index
        remaining = np.hypot(*(self._wp[k] - self._pos).T) + self._wp_rest[k]
        progressed = remaining < self._progress_d - self._progress_m
        self._progress_d = np.where(progressed, remaining, self._progress_d)
        self._progress_t = np.where(progressed, self._time_s, self._progress_t)
        self._blind_s = np.where(visible, 0.0, self._blind_s + h)
        for i in np.flatnonzero(at_goal):
            self._goals_reached[i] += 1
            self._new_goal(i)
        for i in np.flatnonzero(~at_goal & (self._time_s - self._progress_t > cfg.stuck_timeout_s)):
            self._new_goal(i, around_people=True)
        for i in np.flatnonzero(~at_goal & (self._blind_s > _BLIND_REPLAN_S)):
            self._replan(i)

    # ------------------------------------------------------------------ state
    @property
    def positions_xy_m(self) -> np.ndarray:
        """float64 (P, 2) floor positions (a copy)."""
        return self._pos.copy()

    @property
    def velocities_mps(self) -> np.ndarray:
        """float64 (P, 2) velocities over the last substep."""
        return self._vel.copy()

    @property
    def headings_rad(self) -> np.ndarray:
        """float64 (P,) facing directions in (-pi, pi], 0 = +x."""
        return self._heading.copy()

    @property
    def heights_m(self) -> np.ndarray:
        """float64 (P,) standing heights."""
        return self._height.copy()

    @property
    def radii_m(self) -> np.ndarray:
        """float64 (P,) collision radii."""
        return self._radius.copy()

    @property
    def preferred_speeds_mps(self) -> np.ndarray:
        """float64 (P,) each person's walking speed."""
        return self._speed.copy()

    @property
    def gait_phase_rad(self) -> np.ndarray:
        """float64 (P,) gait phases in [0, 2 pi)."""
        return self._gait_phase.copy()

    @property
    def looks(self) -> tuple[HumanLook, ...]:
        return self._looks

    @property
    def time_s(self) -> float:
        """Simulated time since construction."""
        return self._time_s

    @property
    def goals_xy_m(self) -> np.ndarray:
        """float64 (P, 2) current goals."""
        return np.array([pth[-1] for pth in self._paths]).reshape(-1, 2)

    @property
    def goals_reached(self) -> np.ndarray:
        """int64 (P,) number of goals each person has reached."""
        return self._goals_reached.copy()

    @property
    def distance_walked_m(self) -> np.ndarray:
        """float64 (P,) path length each person has walked."""
        return self._walked_m.copy()

    def __len__(self) -> int:
        return len(self._pos)

    def mesh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The people's posed meshes: vertices float32 (V, 3), faces int32 (F, 3), face colours uint8 (F, 3)."""
        return people_mesh(self._looks, self._pos, self._heading, self._gait_phase, self._gait_speed)

    def overlaps_disc(self, xy_m: np.ndarray, radius_m: float) -> bool:
        """Whether a disc (centre (2,), radius in metres) overlaps any person's disc."""
        xy_m = np.asarray(xy_m, dtype=np.float64).reshape(2)
        if len(self._pos) == 0:
            return False
        d = np.hypot(self._pos[:, 0] - xy_m[0], self._pos[:, 1] - xy_m[1])
        return bool(np.any(d < self._radius + radius_m))
