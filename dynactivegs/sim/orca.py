"""Optimal Reciprocal Collision Avoidance (ORCA) for disc agents in the plane.

Implements J. van den Berg, S. J. Guy, M. Lin, D. Manocha, "Reciprocal n-body collision
avoidance", ISRR 2009 / Springer Tracts in Advanced Robotics 70, 2011 ("the paper"), as a
plain function on arrays, compiled with numba.

For every controlled agent A and every neighbour B the velocity obstacle
``VO^tau_{A|B} = {v | exists t in [0, tau]: t v in D(p_B - p_A, r_A + r_B)}`` (paper,
"Preliminaries") is truncated at the time horizon ``tau``; ``u`` is the vector from the
relative velocity ``v_A - v_B`` to the closest point of the VO boundary and ``n`` the
outward normal there. The half-plane of permitted velocities is (paper, "Optimal
Reciprocal Collision Avoidance")::

    ORCA^tau_{A|B} = { v | (v - (v_A + c u)) . n >= 0 }

with responsibility ``c = 1/2`` between two controlled agents (both avoid) and ``c = 1``
against a non-reciprocal agent (here the robot, which does not avoid people). The new
velocity is the point of ``D(0, v_max) ∩ (∩_B ORCA_{A|B})`` closest to the preferred
velocity (paper, "n-Body Collision Avoidance", the linear program of "Linear
Programming"); when that set is empty the 3D linear program of "Densely Packed
Conditions" picks the velocity that minimises the largest violation of the agent
half-planes while keeping the static-obstacle half-planes hard.

A line is stored as a point ``p`` and a unit direction ``d``; the permitted side is on its
left, ``det(d, v - p) >= 0``.

Static obstacles ("Static Obstacles" in the paper) are given as points: the centres of
the blocked cells of an occupancy grid that border free space. Each is treated as a static
disc (velocity 0, full responsibility, time horizon ``obstacle_time_horizon_s``) whose
*combined* radius with the agent is ``radius_m + obstacle_radius_m``. Discs instead of
line segments because a grid boundary has no clean polygon structure (one-cell notches,
diagonal staircases) and discs need no convexity bookkeeping; their number is kept small
by the same pruning as for segments: obstacles are processed nearest first and a disc
whose truncated VO already lies in the forbidden side of an earlier obstacle line is
skipped (valid because every obstacle line keeps the origin permitted, so the forbidden
side is closed under scaling by factors >= 1, and the truncated VO is the union of
scaled copies of its cut-off disc). Every static half-plane contains ``v = 0`` when the
agent does not overlap the disc, so the hard constraints of the 3D program stay feasible;
for an agent already overlapping a disc the half-plane forbids only approaching the
disc's centre (``v . p_rel <= 0``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

_EPS = 1e-5


# ---------------------------------------------------------------------------------------
# obstacle lookup

@dataclass(frozen=True)
class ObstacleIndex:
    """Static obstacle points bucketed on a coarse square grid for range queries.

    ``points_xy_m (M, 2)`` sorted by bucket; bucket ``(by, bx)`` holds
    ``points_xy_m[start[by * nx + bx] : start[by * nx + bx + 1]]``.
    """

    points_xy_m: np.ndarray     # float64 (M, 2)
    start: np.ndarray           # int64 (ny * nx + 1,)
    origin_xy_m: np.ndarray     # float64 (2,)
    cell_m: float
    nx: int
    ny: int

    @staticmethod
    def build(points_xy_m: np.ndarray, cell_m: float = 1.0) -> "ObstacleIndex":
        """Index ``points_xy_m (M, 2)`` with buckets of ``cell_m`` metres."""
        pts = np.asarray(points_xy_m, dtype=np.float64).reshape(-1, 2)
        assert cell_m > 0
        if len(pts) == 0:
            return ObstacleIndex(pts, np.zeros(2, np.int64), np.zeros(2), float(cell_m), 1, 1)
        origin = pts.min(axis=0) - cell_m
        nx, ny = (np.floor((pts.max(axis=0) - origin) / cell_m).astype(np.int64) + 2)
        b = np.floor((pts - origin) / cell_m).astype(np.int64)
        key = b[:, 1] * nx + b[:, 0]
        order = np.argsort(key, kind="stable")
        start = np.searchsorted(key[order], np.arange(nx * ny + 1)).astype(np.int64)
        return ObstacleIndex(np.ascontiguousarray(pts[order]), start, origin, float(cell_m), int(nx), int(ny))

    @staticmethod
    def empty() -> "ObstacleIndex":
        return ObstacleIndex.build(np.zeros((0, 2)))


# ---------------------------------------------------------------------------------------
# linear programs (paper, "Linear Programming" and "Densely Packed Conditions")

@numba.njit(cache=True, inline="always")
def _det(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


@numba.njit(cache=True)
def _lp1(lp: np.ndarray, ld: np.ndarray, i: int, radius: float, opt_x: float, opt_y: float,
         direction_opt: bool, out: np.ndarray) -> bool:
    """Optimise on line ``i`` subject to lines ``0..i-1`` and the speed disc; False if infeasible."""
    px, py, dx, dy = lp[i, 0], lp[i, 1], ld[i, 0], ld[i, 1]
    dot = px * dx + py * dy
    disc = dot * dot + radius * radius - (px * px + py * py)
    if disc < 0.0:
        return False                      # the line misses the speed disc
    sq = np.sqrt(disc)
    t_left = -dot - sq
    t_right = -dot + sq
    for j in range(i):
        denom = _det(dx, dy, ld[j, 0], ld[j, 1])
        numer = _det(ld[j, 0], ld[j, 1], px - lp[j, 0], py - lp[j, 1])
        if abs(denom) <= _EPS:
            if numer < 0.0:
                return False              # parallel and on the forbidden side of line j
            continue
        t = numer / denom
        if denom >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False
    if direction_opt:
        t = t_right if opt_x * dx + opt_y * dy > 0.0 else t_left
    else:
        t = dx * (opt_x - px) + dy * (opt_y - py)
        t = min(max(t, t_left), t_right)
    out[0] = px + t * dx
    out[1] = py + t * dy
    return True


@numba.njit(cache=True)
def _lp2(lp: np.ndarray, ld: np.ndarray, n: int, radius: float, opt_x: float, opt_y: float,
         direction_opt: bool, out: np.ndarray) -> int:
    """The 2D program over lines ``0..n-1``: returns n on success, else the index of the first line that failed.

    On failure ``out`` holds the optimum over the lines before the failing one.
    """
    if direction_opt:
        out[0] = opt_x * radius
        out[1] = opt_y * radius
    elif opt_x * opt_x + opt_y * opt_y > radius * radius:
        norm = np.sqrt(opt_x * opt_x + opt_y * opt_y)
        out[0] = opt_x / norm * radius
        out[1] = opt_y / norm * radius
    else:
        out[0] = opt_x
        out[1] = opt_y
    keep = np.empty(2)
    for i in range(n):
        if _det(ld[i, 0], ld[i, 1], lp[i, 0] - out[0], lp[i, 1] - out[1]) > 0.0:
            keep[0] = out[0]
            keep[1] = out[1]
            if not _lp1(lp, ld, i, radius, opt_x, opt_y, direction_opt, out):
                out[0] = keep[0]
                out[1] = keep[1]
                return i
    return n


@numba.njit(cache=True)
def _lp3(lp: np.ndarray, ld: np.ndarray, n: int, n_obst: int, begin: int, radius: float,
         out: np.ndarray) -> None:
    """Minimise the largest violation of lines ``n_obst..n-1`` keeping lines ``0..n_obst-1`` hard.

    This is the 3D program of the paper's "Densely Packed Conditions" solved by
    projecting onto each violated line in turn, starting at line ``begin`` where the 2D
    program failed; ``out`` enters as that program's partial result.
    """
    distance = 0.0
    plp = np.empty((n, 2))
    pld = np.empty((n, 2))
    tmp = np.empty(2)
    for i in range(begin, n):
        if _det(ld[i, 0], ld[i, 1], lp[i, 0] - out[0], lp[i, 1] - out[1]) <= distance:
            continue                      # line i is violated by no more than the current worst
        m = 0
        for j in range(n_obst):
            plp[m, 0], plp[m, 1], pld[m, 0], pld[m, 1] = lp[j, 0], lp[j, 1], ld[j, 0], ld[j, 1]
            m += 1
        for j in range(n_obst, i):
            det = _det(ld[i, 0], ld[i, 1], ld[j, 0], ld[j, 1])
            if abs(det) <= _EPS:
                if ld[i, 0] * ld[j, 0] + ld[i, 1] * ld[j, 1] > 0.0:
                    continue              # same direction: line j adds nothing
                qx = 0.5 * (lp[i, 0] + lp[j, 0])
                qy = 0.5 * (lp[i, 1] + lp[j, 1])
            else:
                t = _det(ld[j, 0], ld[j, 1], lp[i, 0] - lp[j, 0], lp[i, 1] - lp[j, 1]) / det
                qx = lp[i, 0] + t * ld[i, 0]
                qy = lp[i, 1] + t * ld[i, 1]
            # the bisector of lines i and j: where their violations are equal
            ex = ld[j, 0] - ld[i, 0]
            ey = ld[j, 1] - ld[i, 1]
            norm = np.sqrt(ex * ex + ey * ey)
            plp[m, 0], plp[m, 1], pld[m, 0], pld[m, 1] = qx, qy, ex / norm, ey / norm
            m += 1
        tmp[0], tmp[1] = out[0], out[1]
        # optimise in the direction normal to line i, into its permitted side
        if _lp2(plp, pld, m, radius, -ld[i, 1], ld[i, 0], True, out) < m:
            out[0], out[1] = tmp[0], tmp[1]   # numerical trouble only: keep the previous result
        distance = _det(ld[i, 0], ld[i, 1], lp[i, 0] - out[0], lp[i, 1] - out[1])


@numba.njit(cache=True)
def _solve(lp: np.ndarray, ld: np.ndarray, n: int, n_obst: int, radius: float, pref_x: float,
           pref_y: float, out: np.ndarray) -> None:
    fail = _lp2(lp, ld, n, radius, pref_x, pref_y, False, out)
    if fail < n:
        _lp3(lp, ld, n, n_obst, fail, radius, out)


# ---------------------------------------------------------------------------------------
# half-planes (paper, "Optimal Reciprocal Collision Avoidance")

@numba.njit(cache=True)
def _agent_line(rel_px: float, rel_py: float, rel_vx: float, rel_vy: float, radius: float,
                inv_tau: float, inv_dt: float, vx: float, vy: float, responsibility: float,
                lp: np.ndarray, ld: np.ndarray, k: int) -> None:
    """Line ``k`` := ORCA^tau_{A|B} for relative position p_B - p_A and relative velocity v_A - v_B."""
    dist_sq = rel_px * rel_px + rel_py * rel_py
    r_sq = radius * radius
    if dist_sq > r_sq:
        # w: from the centre of the cut-off disc (p / tau, r / tau) to the relative velocity
        wx = rel_vx - inv_tau * rel_px
        wy = rel_vy - inv_tau * rel_py
        w_sq = wx * wx + wy * wy
        dot1 = wx * rel_px + wy * rel_py
        if dot1 < 0.0 and dot1 * dot1 > r_sq * w_sq:
            # closest boundary point is on the cut-off circle
            w_len = np.sqrt(w_sq)
            ux_n, uy_n = wx / w_len, wy / w_len
            dx, dy = uy_n, -ux_n
            s = radius * inv_tau - w_len
            ux, uy = s * ux_n, s * uy_n
        else:
            # closest boundary point is on a leg of the cone
            leg = np.sqrt(dist_sq - r_sq)
            if _det(rel_px, rel_py, wx, wy) > 0.0:
                dx = (rel_px * leg - rel_py * radius) / dist_sq
                dy = (rel_px * radius + rel_py * leg) / dist_sq
            else:
                dx = -(rel_px * leg + rel_py * radius) / dist_sq
                dy = -(-rel_px * radius + rel_py * leg) / dist_sq
            dot2 = rel_vx * dx + rel_vy * dy
            ux, uy = dot2 * dx - rel_vx, dot2 * dy - rel_vy
    else:
        # already overlapping: resolve within one time step (cut-off disc at tau = dt)
        wx = rel_vx - inv_dt * rel_px
        wy = rel_vy - inv_dt * rel_py
        w_len = np.sqrt(wx * wx + wy * wy)
        if w_len < 1e-12:
            wx, wy, w_len = -rel_px, -rel_py, max(np.sqrt(dist_sq), 1e-12)
            if np.sqrt(dist_sq) < 1e-12:
                wx, wy, w_len = 1.0, 0.0, 1.0
        ux_n, uy_n = wx / w_len, wy / w_len
        dx, dy = uy_n, -ux_n
        s = radius * inv_dt - w_len
        ux, uy = s * ux_n, s * uy_n
    lp[k, 0] = vx + responsibility * ux
    lp[k, 1] = vy + responsibility * uy
    ld[k, 0] = dx
    ld[k, 1] = dy


@numba.njit(cache=True)
def _agent_lines(a: int, pos: np.ndarray, vel: np.ndarray, radius: np.ndarray, max_speed: np.ndarray,
                 other_pos: np.ndarray, other_vel: np.ndarray, other_radius: np.ndarray,
                 obst_pts: np.ndarray, obst_start: np.ndarray, obst_origin: np.ndarray, obst_cell: float,
                 obst_nx: int, obst_ny: int, obst_radius: float, neighbor_dist: float, tau: float,
                 tau_obst: float, dt: float, lp: np.ndarray, ld: np.ndarray) -> tuple[int, int]:
    """Fill ``lp, ld`` with agent ``a``'s obstacle lines then agent lines; returns (n_lines, n_obstacle_lines)."""
    px, py = pos[a, 0], pos[a, 1]
    vx, vy = vel[a, 0], vel[a, 1]
    n = 0
    # --- static obstacle discs, nearest first, skipping those already covered
    r_obst = radius[a] + obst_radius
    reach = tau_obst * max_speed[a] + r_obst
    inv_tau_o = 1.0 / tau_obst
    if len(obst_pts) > 0 and r_obst > 0.0:
        bx0 = int(np.floor((px - reach - obst_origin[0]) / obst_cell))
        bx1 = int(np.floor((px + reach - obst_origin[0]) / obst_cell))
        by0 = int(np.floor((py - reach - obst_origin[1]) / obst_cell))
        by1 = int(np.floor((py + reach - obst_origin[1]) / obst_cell))
        bx0, bx1 = max(bx0, 0), min(bx1, obst_nx - 1)
        by0, by1 = max(by0, 0), min(by1, obst_ny - 1)
        count = 0
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                count += obst_start[by * obst_nx + bx + 1] - obst_start[by * obst_nx + bx]
        cand = np.empty(count, np.int64)
        cdist = np.empty(count)
        m = 0
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                b = by * obst_nx + bx
                for q in range(obst_start[b], obst_start[b + 1]):
                    ox = obst_pts[q, 0] - px
                    oy = obst_pts[q, 1] - py
                    d2 = ox * ox + oy * oy
                    if d2 < reach * reach:
                        cand[m] = q
                        cdist[m] = d2
                        m += 1
        order = np.argsort(cdist[:m], kind="mergesort")
        for oi in range(m):
            q = cand[order[oi]]
            ox = obst_pts[q, 0] - px
            oy = obst_pts[q, 1] - py
            d2 = ox * ox + oy * oy
            if d2 <= r_obst * r_obst:
                # overlapping the disc: forbid only approaching its centre (v . p_rel <= 0)
                d = np.sqrt(d2)
                if d < 1e-12:
                    continue
                lp[n, 0] = 0.0
                lp[n, 1] = 0.0
                ld[n, 0] = -oy / d
                ld[n, 1] = ox / d
                n += 1
                continue
            cx, cy = ox * inv_tau_o, oy * inv_tau_o
            covered = False
            for j in range(n):
                if _det(ld[j, 0], ld[j, 1], cx - lp[j, 0], cy - lp[j, 1]) <= -r_obst * inv_tau_o + _EPS:
                    covered = True
                    break
            if covered:
                continue
            _agent_line(ox, oy, vx, vy, r_obst, inv_tau_o, 1.0 / dt, vx, vy, 1.0, lp, ld, n)
            n += 1
    n_obst = n
    # --- other controlled agents (reciprocal, responsibility 1/2)
    inv_tau = 1.0 / tau
    inv_dt = 1.0 / dt
    nd_sq = neighbor_dist * neighbor_dist
    for b in range(len(pos)):
        if b == a:
            continue
        rx, ry = pos[b, 0] - px, pos[b, 1] - py
        if rx * rx + ry * ry >= nd_sq:
            continue
        _agent_line(rx, ry, vx - vel[b, 0], vy - vel[b, 1], radius[a] + radius[b], inv_tau, inv_dt,
                    vx, vy, 0.5, lp, ld, n)
        n += 1
    # --- non-reciprocal agents (the robot): full responsibility
    for b in range(len(other_pos)):
        rx, ry = other_pos[b, 0] - px, other_pos[b, 1] - py
        if rx * rx + ry * ry >= nd_sq:
            continue
        _agent_line(rx, ry, vx - other_vel[b, 0], vy - other_vel[b, 1], radius[a] + other_radius[b],
                    inv_tau, inv_dt, vx, vy, 1.0, lp, ld, n)
        n += 1
    return n, n_obst


@numba.njit(cache=True)
def _max_obstacle_candidates(pos: np.ndarray, radius: np.ndarray, max_speed: np.ndarray, obst_start: np.ndarray,
                             obst_origin: np.ndarray, obst_cell: float, obst_nx: int, obst_ny: int,
                             obst_radius: float, tau_obst: float) -> int:
    best = 0
    for a in range(len(pos)):
        reach = tau_obst * max_speed[a] + radius[a] + obst_radius
        bx0 = max(int(np.floor((pos[a, 0] - reach - obst_origin[0]) / obst_cell)), 0)
        bx1 = min(int(np.floor((pos[a, 0] + reach - obst_origin[0]) / obst_cell)), obst_nx - 1)
        by0 = max(int(np.floor((pos[a, 1] - reach - obst_origin[1]) / obst_cell)), 0)
        by1 = min(int(np.floor((pos[a, 1] + reach - obst_origin[1]) / obst_cell)), obst_ny - 1)
        c = 0
        for by in range(by0, by1 + 1):
            for bx in range(bx0, bx1 + 1):
                c += obst_start[by * obst_nx + bx + 1] - obst_start[by * obst_nx + bx]
        best = max(best, c)
    return best


@numba.njit(cache=True)
def _orca_kernel(pos, vel, pref, radius, max_speed, other_pos, other_vel, other_radius, obst_pts, obst_start,
                 obst_origin, obst_cell, obst_nx, obst_ny, obst_radius, neighbor_dist, tau, tau_obst, dt):
    n_agents = len(pos)
    cap = n_agents + len(other_pos) + _max_obstacle_candidates(
        pos, radius, max_speed, obst_start, obst_origin, obst_cell, obst_nx, obst_ny, obst_radius, tau_obst)
    lp = np.empty((cap, 2))
    ld = np.empty((cap, 2))
    out = np.empty((n_agents, 2))
    res = np.empty(2)
    for a in range(n_agents):
        n, n_obst = _agent_lines(a, pos, vel, radius, max_speed, other_pos, other_vel, other_radius, obst_pts,
                                 obst_start, obst_origin, obst_cell, obst_nx, obst_ny, obst_radius, neighbor_dist,
                                 tau, tau_obst, dt, lp, ld)
        _solve(lp, ld, n, n_obst, max_speed[a], pref[a, 0], pref[a, 1], res)
        out[a, 0] = res[0]
        out[a, 1] = res[1]
    return out


# ---------------------------------------------------------------------------------------
# public API

def _as2(x: np.ndarray | None, n_rows: int | None = None) -> np.ndarray:
    a = np.zeros((0, 2)) if x is None else np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 2)
    assert n_rows is None or a.shape == (n_rows, 2), (a.shape, n_rows)
    return a


def orca_velocities(pos_xy_m: np.ndarray, vel_mps: np.ndarray, pref_vel_mps: np.ndarray, radius_m: np.ndarray,
                    max_speed_mps: np.ndarray, *, dt_s: float, time_horizon_s: float,
                    obstacle_time_horizon_s: float, neighbor_dist_m: float,
                    other_xy_m: np.ndarray | None = None, other_vel_mps: np.ndarray | None = None,
                    other_radius_m: np.ndarray | None = None, obstacles: ObstacleIndex | None = None,
                    obstacle_radius_m: float = 0.0) -> np.ndarray:
    """New collision-avoiding velocities for N agents (one ORCA step, all agents simultaneously).

    Args:
        pos_xy_m: float (N, 2) agent positions.
        vel_mps: float (N, 2) current velocities (``v_A^opt`` of the paper: the current velocity).
        pref_vel_mps: float (N, 2) preferred velocities.
        radius_m: float (N,) agent radii.
        max_speed_mps: float (N,) speed limits (radius of the LP's velocity disc).
        dt_s: simulation step; only used to resolve agents that already overlap.
        time_horizon_s: ``tau`` for agents.
        obstacle_time_horizon_s: ``tau`` for static obstacles.
        neighbor_dist_m: agents whose centres are farther than this are ignored.
        other_xy_m, other_vel_mps, other_radius_m: (K, 2), (K, 2), (K,) non-reciprocal agents
            (the robot) that the N agents avoid with full responsibility.
        obstacles: static obstacle points (see the module docstring).
        obstacle_radius_m: added to an agent's radius to give the combined radius of a static disc.

    Returns:
        float64 (N, 2) new velocities, each within its agent's speed limit.
    """
    pos = _as2(pos_xy_m)
    n = len(pos)
    vel = _as2(vel_mps, n)
    pref = _as2(pref_vel_mps, n)
    radius = np.ascontiguousarray(radius_m, dtype=np.float64).reshape(-1)
    max_speed = np.ascontiguousarray(max_speed_mps, dtype=np.float64).reshape(-1)
    assert radius.shape == (n,) and max_speed.shape == (n,)
    opos = _as2(other_xy_m)
    k = len(opos)
    ovel = _as2(other_vel_mps if other_vel_mps is not None else np.zeros((k, 2)), k)
    orad = np.ascontiguousarray(other_radius_m if other_radius_m is not None else np.zeros(k),
                                dtype=np.float64).reshape(-1)
    assert orad.shape == (k,)
    assert dt_s > 0 and time_horizon_s > 0 and obstacle_time_horizon_s > 0 and neighbor_dist_m > 0
    obs = obstacles if obstacles is not None else ObstacleIndex.empty()
    if n == 0:
        return np.zeros((0, 2))
    return _orca_kernel(pos, vel, pref, radius, max_speed, opos, ovel, orad, obs.points_xy_m, obs.start,
                        obs.origin_xy_m, obs.cell_m, obs.nx, obs.ny, float(obstacle_radius_m),
                        float(neighbor_dist_m), float(time_horizon_s), float(obstacle_time_horizon_s), float(dt_s))


def orca_lines(agent: int, pos_xy_m: np.ndarray, vel_mps: np.ndarray, radius_m: np.ndarray,
               max_speed_mps: np.ndarray, *, dt_s: float, time_horizon_s: float, obstacle_time_horizon_s: float,
               neighbor_dist_m: float, other_xy_m: np.ndarray | None = None,
               other_vel_mps: np.ndarray | None = None, other_radius_m: np.ndarray | None = None,
               obstacles: ObstacleIndex | None = None,
               obstacle_radius_m: float = 0.0) -> tuple[np.ndarray, np.ndarray, int]:
    """The half-planes ORCA builds for one agent (arguments as in :func:`orca_velocities`).

    Returns ``points (L, 2)``, ``directions (L, 2)`` (unit) and ``n_obstacle``: the first
    ``n_obstacle`` lines come from static obstacles. Velocity ``v`` is permitted by line
    ``l`` iff ``det(directions[l], v - points[l]) >= 0``.
    """
    pos = _as2(pos_xy_m)
    n = len(pos)
    obs = obstacles if obstacles is not None else ObstacleIndex.empty()
    opos = _as2(other_xy_m)
    k = len(opos)
    ovel = _as2(other_vel_mps if other_vel_mps is not None else np.zeros((k, 2)), k)
    orad = np.ascontiguousarray(other_radius_m if other_radius_m is not None else np.zeros(k), dtype=np.float64)
    radius = np.ascontiguousarray(radius_m, dtype=np.float64).reshape(-1)
    max_speed = np.ascontiguousarray(max_speed_mps, dtype=np.float64).reshape(-1)
    cap = n + k + len(obs.points_xy_m)
    lp = np.empty((cap, 2))
    ld = np.empty((cap, 2))
    cnt, n_obst = _agent_lines(agent, pos, _as2(vel_mps, n), radius, max_speed, opos, ovel, orad,
                               obs.points_xy_m, obs.start, obs.origin_xy_m, obs.cell_m, obs.nx, obs.ny,
                               float(obstacle_radius_m), float(neighbor_dist_m), float(time_horizon_s),
                               float(obstacle_time_horizon_s), float(dt_s), lp, ld)
    return lp[:cnt].copy(), ld[:cnt].copy(), int(n_obst)


def solve_orca_lp(points: np.ndarray, directions: np.ndarray, n_obstacle: int, max_speed_mps: float,
                  pref_vel_mps: np.ndarray) -> np.ndarray:
    """float64 (2,): the velocity within ``max_speed_mps`` closest to ``pref_vel_mps`` permitted by all lines.

    If no velocity satisfies every line, the first ``n_obstacle`` lines are kept hard and
    the largest violation of the others is minimised (the paper's 3D program).
    """
    lp = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
    ld = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 2)
    assert lp.shape == ld.shape and 0 <= n_obstacle <= len(lp)
    pref = np.asarray(pref_vel_mps, dtype=np.float64).reshape(2)
    out = np.empty(2)
    _solve(lp, ld, len(lp), int(n_obstacle), float(max_speed_mps), float(pref[0]), float(pref[1]), out)
    return out
