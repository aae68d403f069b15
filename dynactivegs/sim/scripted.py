"""A scripted driver that tours the scene using the simulator's ground-truth free space.

For demos, tests and benchmarks that need a robot path without the planner (for example a
fixed path through an apartment with people walking through the view). The pipeline's own
planner never uses ground-truth free space; this driver is not part of the method.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse.csgraph import dijkstra

from dynactivegs.sim.freespace import FreeSpace, grid_graph
from dynactivegs.sim.robot import Action, wrap_angle


class ScriptedDriver:
    """Visits random far-apart goals in the free space, turning toward each waypoint and
    driving forward when aligned. Deterministic given ``rng``."""

    def __init__(self, freespace: FreeSpace, radius_m: float, rng: np.random.Generator,
                 turn_step_rad: float = math.radians(10.0), min_goal_dist_m: float = 3.0) -> None:
        self.fs = freespace
        self.rng = rng
        self.turn = turn_step_rad
        self.min_goal = min_goal_dist_m
        # keep a margin so that the robot does not graze walls on diagonal moves
        self.mask = freespace.navigable(radius_m + freespace.res_m)
        if not self.mask.any():
            self.mask = freespace.navigable(radius_m)
        self.graph, self.cells = grid_graph(self.mask, freespace.res_m)
        self.path: list[np.ndarray] = []

    def _plan(self, xy: np.ndarray) -> None:
        start = int(np.argmin(((self.cells - self.fs.world_to_cell(xy)) ** 2).sum(axis=1)))
        dist, pred = dijkstra(self.graph, indices=start, return_predecessors=True)
        reach = np.flatnonzero(np.isfinite(dist))
        far = reach[np.linalg.norm(self.fs.cell_to_world(self.cells[reach]) - xy, axis=1) >= self.min_goal]
        pool = far if len(far) else reach
        node = int(pool[self.rng.integers(len(pool))])
        chain = []
        while node >= 0 and node != start:
            chain.append(node)
            node = int(pred[node])
        pts = self.fs.cell_to_world(self.cells[chain[::-1]]) if chain else np.zeros((0, 2))
        self.path = list(pts[::5]) + ([pts[-1]] if len(pts) else [])

    def act(self, x_m: float, y_m: float, yaw_rad: float, blocked: bool = False) -> Action:
        """The next action from the robot's pose; ``blocked`` says the last forward move failed."""
        xy = np.array([x_m, y_m])
        while self.path and np.linalg.norm(self.path[0] - xy) < 0.2:
            self.path.pop(0)
        if blocked and self.rng.random() < 0.3:
            self.path = []
        if not self.path:
            self._plan(xy)
            if not self.path:
                return Action.TURN_LEFT
        d = self.path[0] - xy
        err = wrap_angle(math.atan2(d[1], d[0]) - yaw_rad)
        if abs(err) > self.turn / 2 + 1e-9:
            return Action.TURN_LEFT if err > 0 else Action.TURN_RIGHT
        return Action.FORWARD
