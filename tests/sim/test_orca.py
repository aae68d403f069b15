"""ORCA: the linear programs against brute force, half-planes respected, agents avoid each other and walls."""

from __future__ import annotations

import numpy as np
import pytest

from dynactivegs.sim.orca import ObstacleIndex, orca_lines, orca_velocities, solve_orca_lp

ORCA = dict(time_horizon_s=2.0, obstacle_time_horizon_s=2.0, neighbor_dist_m=5.0)


def _violation(points: np.ndarray, dirs: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(L,) or (L, K): how far ``v`` lies on the forbidden (right) side of each line; <= 0 is permitted."""
    d = v[..., None, :] - points if v.ndim == 1 else v[:, None, :] - points[None]
    return -(dirs[..., 0] * d[..., 1] - dirs[..., 1] * d[..., 0])


def _disc_grid(radius: float, n: int = 801) -> np.ndarray:
    g = np.linspace(-radius, radius, n)
    x, y = np.meshgrid(g, g)
    pts = np.stack([x.ravel(), y.ravel()], axis=1)
    return pts[np.hypot(pts[:, 0], pts[:, 1]) <= radius]


def _random_lines(rng: np.random.Generator, n: int, vmax: float, feasible_at: np.ndarray | None):
    ang = rng.uniform(-np.pi, np.pi, n)
    dirs = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    points = rng.uniform(-vmax, vmax, (n, 2))
    if feasible_at is not None:  # move each line so that feasible_at is on its permitted side
        viol = _violation(points, dirs, feasible_at)
        normal = np.stack([-dirs[:, 1], dirs[:, 0]], axis=1)     # left normal
        shift = np.maximum(viol, 0.0) + rng.uniform(0.0, 0.2 * vmax, n)
        points = points - normal * shift[:, None] * (viol > -0.05)[:, None]
    return points, dirs


def test_2d_program_matches_brute_force_on_feasible_sets():
    """Reference: the best permitted point of a 601x601 grid over the speed disc.

    The LP optimum is feasible (to 1e-9) and at most one grid diagonal (2 vmax / 600 * sqrt 2)
    farther from the preferred velocity than the best feasible grid point.
    """
    rng = np.random.default_rng(0)
    vmax = 1.0
    grid = _disc_grid(vmax, 601)
    cell = 2 * vmax / 600 * np.sqrt(2)
    for trial in range(30):
        n = int(rng.integers(1, 9))
        inside = rng.uniform(-0.5, 0.5, 2)
        points, dirs = _random_lines(rng, n, vmax, feasible_at=inside)
        pref = rng.uniform(-1.5, 1.5, 2)
        v = solve_orca_lp(points, dirs, 0, vmax, pref)
        assert _violation(points, dirs, v).max() < 1e-9, f"trial {trial}: LP result violates a line"
        assert np.hypot(*v) <= vmax + 1e-9, f"trial {trial}: |v|={np.hypot(*v)} above vmax"
        ok = (_violation(points, dirs, grid) <= 0).all(axis=1)
        best = np.hypot(*(grid[ok] - pref).T).min()
        got = np.hypot(*(v - pref))
        assert got <= best + cell, f"trial {trial}: LP distance {got:.4f} vs brute force {best:.4f}"


def test_3d_program_minimises_the_worst_violation_keeping_hard_lines():
    """Infeasible sets: hard (obstacle) lines hold and the largest soft violation is within one grid
    diagonal of the brute-force min-max over the disc."""
    rng = np.random.default_rng(1)
    vmax = 1.0
    grid = _disc_grid(vmax, 401)
    cell = 2 * vmax / 400 * np.sqrt(2)
    tested = 0
    for trial in range(100):
        n_hard = int(rng.integers(0, 3))
        hard_p, hard_d = _random_lines(rng, n_hard, vmax, feasible_at=np.zeros(2))
        soft_p, soft_d = _random_lines(rng, int(rng.integers(3, 8)), vmax, feasible_at=None)
        points, dirs = np.concatenate([hard_p, soft_p]), np.concatenate([hard_d, soft_d])
        pref = rng.uniform(-1, 1, 2)
        hard_ok = (_violation(hard_p, hard_d, grid) <= 0).all(axis=1) if n_hard else np.ones(len(grid), bool)
        soft = _violation(soft_p, soft_d, grid).max(axis=1)
        if (soft[hard_ok] <= 0).any():
            continue                      # feasible: the 2D program's case
        tested += 1
        v = solve_orca_lp(points, dirs, n_hard, vmax, pref)
        if n_hard:
            assert _violation(hard_p, hard_d, v).max() < 1e-7, f"trial {trial}: a hard line is violated"
        worst = _violation(soft_p, soft_d, v).max()
        best = soft[hard_ok].min()
        assert worst <= best + cell, f"trial {trial}: worst violation {worst:.4f} vs brute force {best:.4f}"
        assert np.hypot(*v) <= vmax + 1e-9
    assert tested >= 15, f"only {tested} infeasible sets were generated"


def test_new_velocities_respect_their_half_planes():
    rng = np.random.default_rng(2)
    wall = np.stack([np.linspace(-2, 6, 161), np.full(161, -0.6)], axis=1)
    obstacles = ObstacleIndex.build(wall, cell_m=1.0)
    checked = 0
    for trial in range(20):
        n = 8
        pos = np.stack([rng.uniform(-1, 5, n), rng.uniform(0, 3, n)], axis=1)
        vel = rng.normal(0, 0.3, (n, 2))
        pref = rng.normal(0, 0.5, (n, 2))
        radius = np.full(n, 0.25)
        vmax = np.full(n, 0.6)
        robot = dict(other_xy_m=rng.uniform(0, 3, (1, 2)), other_vel_mps=rng.normal(0, 0.3, (1, 2)),
                     other_radius_m=np.array([0.18]))
        new = orca_velocities(pos, vel, pref, radius, vmax, dt_s=0.1, obstacles=obstacles, **robot, **ORCA)
        assert new.shape == (n, 2)
        assert (np.hypot(*new.T) <= vmax + 1e-9).all(), "a velocity exceeds the speed limit"
        for a in range(n):
            p, d, n_obst = orca_lines(a, pos, vel, radius, vmax, dt_s=0.1, obstacles=obstacles, **robot, **ORCA)
            assert np.allclose(new[a], solve_orca_lp(p, d, n_obst, vmax[a], pref[a]))
            viol = _violation(p, d, new[a])
            assert viol[:n_obst].max(initial=-1) < 1e-7, f"trial {trial} agent {a}: obstacle line violated"
            if viol.max() < 1e-7:
                checked += 1
                continue
            # infeasible: 3D program; no velocity in the disc satisfies every line
            grid = _disc_grid(vmax[a], 201)
            assert not (_violation(p, d, grid) <= 0).all(axis=1).any(), \
                f"trial {trial} agent {a}: feasible velocities exist but the result violates by {viol.max():.3g}"
    assert checked >= 100, f"only {checked} of 160 agents had feasible programs"


def test_obstacle_lines_from_a_wall_are_pruned():
    wall = np.stack([np.linspace(-5, 5, 201), np.full(201, -0.5)], axis=1)
    p, d, n_obst = orca_lines(0, np.zeros((1, 2)), np.array([[0.3, -0.2]]), np.array([0.3]), np.array([0.5]),
                              dt_s=0.1, obstacles=ObstacleIndex.build(wall), **ORCA)
    in_range = int((np.hypot(*wall.T) < 2 * 0.5 + 0.3).sum())
    assert 1 <= n_obst <= 20 and n_obst < in_range / 2, f"{n_obst} obstacle lines for {in_range} wall points in range"


def _simulate(pos, goals, radius, vmax, steps, dt=0.1, obstacles=None, obstacle_radius_m=0.0, robot=None):
    pos = pos.astype(float).copy()
    vel = np.zeros_like(pos)
    track = [pos.copy()]
    for _ in range(steps):
        d = goals - pos
        dn = np.hypot(*d.T)[:, None]
        pref = d / np.maximum(dn, 1e-9) * np.minimum(vmax[:, None], dn / dt)
        vel = orca_velocities(pos, vel, pref, radius, vmax, dt_s=dt, obstacles=obstacles,
                              obstacle_radius_m=obstacle_radius_m, **(robot or {}), **ORCA)
        pos = pos + dt * vel
        track.append(pos.copy())
    return np.array(track)


def _min_pair_gap(track, radius):
    d = np.hypot(*(track[:, :, None] - track[:, None, :]).transpose(3, 0, 1, 2))
    n = track.shape[1]
    d[:, np.arange(n), np.arange(n)] = np.inf
    return (d - (radius[:, None] + radius[None])).min()


def test_two_agents_heading_at_each_other_swap_without_collision():
    # 5 cm off the common line: exactly mirror-symmetric head-on agents are an equilibrium of
    # ORCA (both only slow down), as in the paper's formulation
    start = np.array([[-3.0, 0.0], [3.0, 0.05]])
    radius, vmax = np.full(2, 0.3), np.full(2, 0.5)
    track = _simulate(start, start[::-1], radius, vmax, steps=250)
    gap = _min_pair_gap(track, radius)
    assert gap > -1e-6, f"agents overlap by {-gap:.4f} m"
    end_err = np.hypot(*(track[-1] - start[::-1]).T).max()
    assert end_err < 0.01, f"agents end {end_err:.3f} m from their goals"
    assert np.abs(track[:, :, 1]).max() > 0.25, "agents passed through each other's line without sidestepping"


def test_three_crossing_streams_reach_their_goals_without_collision():
    ys = np.array([-1.0, 0.0, 1.0])
    start = np.concatenate([np.stack([np.full(3, -4.0), ys], 1),           # going +x
                            np.stack([np.full(3, 4.0), ys + 0.3], 1),      # going -x
                            np.stack([1.2 * ys + 0.2, np.full(3, -4.0)], 1)])  # going +y
    goal = start * np.array([-1.0, 1.0])
    goal[6:] = start[6:] * np.array([1.0, -1.0])
    radius, vmax = np.full(9, 0.3), np.full(9, 0.6)
    track = _simulate(start, goal, radius, vmax, steps=400)
    gap = _min_pair_gap(track, radius)
    # one 0.1 s step of discretisation: ORCA's guarantee is for continuous time
    assert gap > -0.005, f"agents overlap by {-gap:.4f} m"
    end_err = np.hypot(*(track[-1] - goal).T).max()
    assert end_err < 0.01, f"an agent ends {end_err:.3f} m from its goal"


def test_people_give_way_to_a_non_reciprocal_robot():
    """The robot drives straight at a person and does not avoid; the person must take it all."""
    radius, vmax = np.array([0.3]), np.array([0.5])
    pos, vel = np.array([[0.0, 0.0]]), np.zeros((1, 2))
    robot_xy, robot_v = np.array([4.0, 0.02]), np.array([-0.5, 0.0])
    worst = np.inf
    for _ in range(160):
        robot = dict(other_xy_m=robot_xy[None], other_vel_mps=robot_v[None], other_radius_m=np.array([0.18]))
        vel = orca_velocities(pos, vel, np.zeros((1, 2)), radius, vmax, dt_s=0.1, **robot, **ORCA)
        pos = pos + 0.1 * vel
        robot_xy = robot_xy + 0.1 * robot_v
        worst = min(worst, np.hypot(*(pos[0] - robot_xy)) - 0.48)
    assert worst > -1e-3, f"the robot came {-worst:.4f} m into the person"


def test_agent_slides_along_a_wall_and_stops_at_it():
    wall = np.stack([np.linspace(-5, 10, 301), np.full(301, -0.5)], axis=1)
    obstacles = ObstacleIndex.build(wall)
    radius, vmax = np.array([0.3]), np.array([0.5])
    # aim diagonally into the wall: the agent ends up sliding along it
    pos, vel = np.array([[0.0, 0.5]]), np.zeros((1, 2))
    for _ in range(120):
        vel = orca_velocities(pos, vel, np.array([[0.3, -0.4]]), radius, vmax, dt_s=0.1, obstacles=obstacles, **ORCA)
        pos = pos + 0.1 * vel
        gap = np.hypot(*(wall - pos[0]).T).min() - 0.3
        assert gap > -1e-3, f"agent at {pos[0]} is {-gap:.4f} m inside the wall"
    assert abs(vel[0, 1]) < 1e-3 and vel[0, 0] > 0.29, f"sliding velocity {vel[0]}, expected about (0.3, 0)"


def test_empty_inputs():
    out = orca_velocities(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0),
                          dt_s=0.1, **ORCA)
    assert out.shape == (0, 2)
    v = orca_velocities(np.zeros((1, 2)), np.zeros((1, 2)), np.array([[1.0, 0.0]]), np.array([0.3]),
                        np.array([0.5]), dt_s=0.1, obstacles=ObstacleIndex.empty(), **ORCA)
    assert np.allclose(v, [[0.5, 0.0]]), f"a lone agent should go at its speed limit toward its goal, got {v}"


@pytest.mark.parametrize("cell_m", [0.3, 1.0, 5.0])
def test_obstacle_index_bucket_size_does_not_change_the_result(cell_m):
    rng = np.random.default_rng(5)
    pts = rng.uniform(-3, 3, (300, 2))
    pts = pts[np.hypot(*pts.T) > 1.0]
    pos = rng.uniform(-0.5, 0.5, (4, 2))
    pref = rng.normal(0, 0.5, (4, 2))
    args = (pos, np.zeros((4, 2)), pref, np.full(4, 0.2), np.full(4, 0.5))
    ref = orca_velocities(*args, dt_s=0.1, obstacles=ObstacleIndex.build(pts, 100.0), **ORCA)
    got = orca_velocities(*args, dt_s=0.1, obstacles=ObstacleIndex.build(pts, cell_m), **ORCA)
    assert np.allclose(ref, got, atol=1e-12), np.abs(ref - got).max()
