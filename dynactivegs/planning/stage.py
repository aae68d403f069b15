"""The planning stage: ``step(cfg, rec, state, rng) -> (state, PlanningOut)`` (DESIGN.md §3, §5 Planning).

Per step:

1. U_m of ``rec.fields`` is projected to the floor (:mod:`dynactivegs.fields.project`) and
   folded into a per-cell temporal average kept in the state, eq. (13)
   ``U_m(t) = (1 - gamma) U_m(t-1) + gamma U_m now``. The average lives on the floor map,
   not on edges, so it survives graph rebuilds; averaging along an edge is linear, so the
   edge mean of the averaged map is the eq. (13) average of the edge means.
2. Edge costs on the selection's graph, eq. (11) ``c(e) = len(e) + l_m * mean U_m along e``
   with the mean over the straight segment between the edge's nodes (``SelectionOut`` carries
   node positions and lengths, not the cell chains), by planner variant: ``shortest``
   (length only), ``dyn_edge`` (current U_m), ``dyn_edge_temporal`` (the eq. 13 average).
   Edges passing within ``block_radius_m`` of a place where the robot was recently blocked
   cost ``block_penalty_m`` more.
3. The path is re-planned (Dijkstra from the target node; the path starts at a node near the
   robot that it can drive to straight, the one with the cheapest way there counting the turns,
   :func:`_source`, and ends at the target position) when the target or graph changed, the robot
   was blocked, or ``replan_every`` steps passed; otherwise the robot keeps following the stored
   path.
4. The next discrete action (:func:`dynactivegs.planning.actions.next_action`): turn toward
   the next waypoint, forward when aligned, final turn to the target yaw, STOP at the target.
   Where the selection's map of the obstacles around the robot (``SelectionOut.local_clear_m``)
   says the aimed step would graze one, the robot steers to the nearest heading toward the
   waypoint whose step keeps clear (:func:`dynactivegs.planning.actions.steer_clear`).
5. Local collision check: a forward move that the current depth frame says would hit
   something (:func:`~dynactivegs.planning.actions.forward_blocked`), or a forward move at
   the previous step that did not move the robot (a bump), blocks: the spot is penalised,
   the path is re-planned at once. If the next move is still a forward move into what the
   depth frame shows, the robot first turns to aim exactly at its waypoint, then waits (STOP)
   for the way to clear; a spot only remembered re-routes the path but never makes it wait.
6. Turning away: after ``bump_evade_after`` bumps in a row without moving (something it cannot
   see keeps stopping it, e.g. a person at the edge of the field of view), or ``wait_evade_after``
   waits in a row before something it sees (a person standing in the way, or waiting for the robot
   to give way), the robot turns by ``evade_turn_deg`` toward the side with more room and takes
   one forward step; while the depth frame shows that step blocked (with ``evade_map_check``, or the
   known obstacles around it) it turns on, up to a half turn.
   Then it re-plans.

No dead-locks: ``PlanningOut.stuck`` reports the robot has not left a small disc for
``actions.stuck_steps`` steps with an unreached target; the selection stage applies the
same rule to its own pose history (it cannot read planning) and picks another target.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace

import numpy as np

from dynactivegs.errors import check_config
from dynactivegs.fields.project import FloorMap, motion_floor_map, segment_means
from dynactivegs.planning.actions import (ActionConfig, PathStep, StuckState, clear_headings, forward_blocked,
                                          is_stuck, next_action, side_clearance, steer_clear, update_stuck)
from dynactivegs.planning.paths import PathConfig, dijkstra, ema_update, variant_edge_cost
from dynactivegs.records import PlanningOut, RobotPose2D, SelectionOut, StepRecord, robot_pose_of
from dynactivegs.selection.voronoi import GraphArrays, edge_list_arrays, nearest_clear_node
from dynactivegs.sim.robot import Action, wrap_angle


@dataclass(frozen=True, slots=True)
class PlanningConfig:
    """Planner variant and weights (eqs. 11, 13), path following, collision check and replanning."""

    path: PathConfig = field(default_factory=PathConfig)
    """Planner variant (shortest | dyn_edge | dyn_edge_temporal, the paper's Table 5), l_m of eq. (11), gamma of eq. (13)."""
    actions: ActionConfig = field(default_factory=ActionConfig)
    """Robot geometry and step sizes (defaults match the simulator's RobotConfig), stuck rule."""
    um_band_lo_m: float = 0.1
    """U_m is projected to the floor from voxels between this height ..."""
    um_band_hi_m: float = 1.9
    """... and this height (where people are)."""
    sample_spacing_m: float = 0.1
    """Spacing of the samples of U_m along an edge."""
    replan_every: int = 5
    """With nothing else changed, the path is re-planned every this many steps (U_m moves on)."""
    block_penalty_m: float = 3.0
    """Extra cost of an edge near a place where the robot was recently blocked. Nearly every block is a person:
    in 4 full runs of 600 steps, 210 of the 213 blocks by something seen had most of the swept rectangle's
    returns on a person. At 20 m the robot turned toward detours of many metres around someone who moved on
    a few steps later, and back when the block expired; at 3 m it detours only around the corner and
    otherwise waits for the way to clear."""
    block_radius_m: float = 0.4
    """Edges passing within this distance of a blocked spot get the penalty."""
    block_hold_steps: int = 15
    """A blocked spot is remembered for this many steps."""
    bump_tol_m: float = 0.05
    """A forward action after which the robot moved less than this was blocked (a bump)."""
    bump_evade_after: int = 2
    """After this many bumps in a row (the robot did not move in between; turns do not count as moving), the
    robot turns away by evade_turn_deg, toward the side with more room, tries one forward step and re-plans.
    The simulator keeps the robot 0.3 m off a person's centre, wider than their body, and a person standing at
    the edge of the field of view is then missed by the depth check: with full on apartment-00, seed 0,
    1000 steps, 71 of the run's 104 collisions came from one 74-step stand-off in which the robot tried the
    same forward step every step. Measured closed-loop (benchmarks/results/apartment-1000-evade: baseline and
    full, 4 apartment scenes, seeds 0 and 1, 1000 steps, against the same 16 runs without it): full's
    collisions per run fell from 45.4 to 31.9 (apartment-00 seed 0: from 104 to 32, the longest run of
    consecutive ones from 71 to 2). Acc cm / C.R. % / PSNR dB went from 3.34 / 89.8 / 23.18 to
    3.95 / 86.7 / 22.73 for full (two runs that explored less, one of them locked in a narrow passage) and
    from 5.66 / 85.7 / 22.46 to 4.51 / 88.1 / 22.60 for baseline, whose collisions hardly changed: 8 pairs do
    not separate the change from the closed loop's run-to-run spread. 0: never turn away, keep trying."""
    wait_evade_after: int = 6
    """After this many waits in a row before something the camera sees in the way (the robot has not moved in
    between), the robot turns away as after bump_evade_after bumps: someone who stays in the way is standing
    there or waiting for the robot to give way, not crossing. Without it, full on apartment-00, seed 2, 1000
    steps, spent 114 steps waiting in 14 stand-offs of up to 21 steps each, with a person 0.48 m away (body
    to body) until the selection gave up on the target; over full's 12 runs on the 4 apartment scenes, seeds
    0-2, 390 of the 677 waiting steps were in stand-offs longer than 6 steps; with it, none of 427. Closed
    loop, 12 pairs (benchmarks/results/apartment-1000-waitevade, with selection.stuck_move_tol_m 0.3): full
    beats baseline on Acc, C.R. and PSNR in 8 of 12 pairs (2 before); full's mean Acc / C.R. / PSNR stayed
    (3.00 / 90.0 / 22.91 against 2.96 / 90.0 / 23.15), baseline's fell (3.47 / 89.5 / 22.97 against
    3.35 / 90.8 / 23.78). 0: wait until the way clears or the selection gives up on the target."""
    evade_turn_deg: float = 60.0
    """How far the robot turns away after bump_evade_after bumps or wait_evade_after waits in a row."""
    evade_map_check: bool = False
    """The turn-away's forward step must also keep clear of the known obstacles around the robot
    (:func:`~dynactivegs.planning.actions.clear_headings` on ``SelectionOut.local_clear_m``), not only of what the
    depth frame shows; where it does not, the robot turns on as where the camera sees the step blocked. Why: a
    robot standing beside a door jamb turns away from a person in the doorway toward the wall, where the
    corner by its side is out of the camera's view: `full` with selection.face_gain_weight 1 on apartment-00,
    seed 1, 1000 steps, at (4.39, 6.02) m, 0.19 m from the jamb's corner, bumped the corner at 63 deg after
    each turn-away and the jamb at -177 deg on its path after each re-plan, steps 372-450, until the selection
    gave up on the target (the person waited at 0.48 m, body to body, the whole time); the check refuses those
    three steps. Over machine3's 48 logs at the defaults (`full` and `baseline`, 12 apartment and 12 loop pairs;
    benchmarks/evade_steps.py, open loop) 59 of 189 turn-away steps bumped: the check refuses 41 of them and 47
    of the 130 that moved. Off until measured closed loop. False: the depth frame alone decides."""
    evade_reach_m: float = 1.0
    """The side with more room: the one whose nearest depth return (body height band) within this distance is
    farther; with none on either side, the one with less U_m on the floor within this distance; else left."""
    source_radius_m: float = 1.0
    """The path may start at any node within this distance of the robot and three graph hops of the nearest
    node; the one with the cheapest path counting the way there and the turns (metres of forward steps a
    turn takes as long as) wins. 0: always the nearest node, which is often behind a robot between
    nodes, and a rebuilt graph whose routes swap back and forth makes it turn on the spot."""

    def __post_init__(self) -> None:
        check_config(self.um_band_lo_m < self.um_band_hi_m, "planning.um_band_lo_m", self.um_band_lo_m,
                     "below planning.um_band_hi_m")
        check_config(self.sample_spacing_m > 0.0, "planning.sample_spacing_m", self.sample_spacing_m, "> 0 m")
        check_config(self.replan_every >= 1, "planning.replan_every", self.replan_every, ">= 1")
        check_config(self.block_penalty_m >= 0.0, "planning.block_penalty_m", self.block_penalty_m, ">= 0")
        check_config(self.source_radius_m >= 0.0, "planning.source_radius_m", self.source_radius_m, ">= 0 m")
        check_config(self.block_radius_m >= 0.0, "planning.block_radius_m", self.block_radius_m, ">= 0 m")
        check_config(self.block_hold_steps >= 0, "planning.block_hold_steps", self.block_hold_steps, ">= 0")
        check_config(0.0 < self.bump_tol_m < self.actions.forward_step_m, "planning.bump_tol_m", self.bump_tol_m,
                     "in (0, actions.forward_step_m)")
        check_config(self.bump_evade_after >= 0, "planning.bump_evade_after", self.bump_evade_after, ">= 0 (0: never)")
        check_config(self.wait_evade_after >= 0, "planning.wait_evade_after", self.wait_evade_after, ">= 0 (0: never)")
        check_config(0.0 < self.evade_turn_deg <= 180.0, "planning.evade_turn_deg", self.evade_turn_deg,
                     "in (0, 180] deg")
        check_config(self.evade_reach_m > 0.0, "planning.evade_reach_m", self.evade_reach_m, "> 0 m")


@dataclass(frozen=True, slots=True)
class PlanningState:
    """Everything planning keeps between steps."""

    ema_origin_ij: tuple[int, int]       # integer floor-cell offset of the EMA map's cell (0, 0)
    ema: np.ndarray                      # float64 (X, Y) eq. (13) average of the floor U_m
    graph_key: bytes                     # digest of the graph the path was planned on
    target_key: tuple[float, float, float] | None
    path_xy_m: np.ndarray                # float64 (P, 2) waypoints (the last is the target position)
    path_cost: float
    next_waypoint: int                   # index of the first waypoint not yet reached
    planned_step: int
    blocks: tuple[tuple[float, float, int], ...]   # (x, y, remembered until this step)
    last_xy_m: tuple[float, float] | None
    last_action: int
    stuck: StuckState
    bumps_in_row: int                    # bumps since the robot last moved
    waits_in_row: int                    # waits before something seen in the way since the robot last moved
    evade: tuple[int, ...]               # actions still to take turning away (after bumps or waits in a row)

    def __post_init__(self) -> None:
        self.ema.flags.writeable = False
        self.path_xy_m.flags.writeable = False


def init_state(cfg: PlanningConfig) -> PlanningState:
    """Step 0's state: no map average, no path."""
    assert isinstance(cfg, PlanningConfig)
    return PlanningState((0, 0), np.zeros((0, 0)), b"", None, np.zeros((0, 2)), math.nan, 0, -1, (), None,
                         int(Action.STOP), StuckState(), 0, 0, ())


def _graph_key(sel: SelectionOut) -> bytes:
    h = hashlib.blake2b(digest_size=16)
    for a in (sel.node_xy_m, sel.edges, sel.edge_length_m):
        h.update(np.ascontiguousarray(a).tobytes())
        h.update(str(a.shape).encode())
    return h.digest()


def _ema_map(cfg: PlanningConfig, state: PlanningState, now: FloorMap) -> tuple[tuple[int, int], np.ndarray, FloorMap]:
    """Eq. (13) on the floor map: the state's average grown to the current map and updated with it."""
    o_new = tuple(int(v) for v in np.round(now.origin_xy_m / now.cell_m))
    X, Y = now.values.shape
    old = np.zeros((X, Y))
    if state.ema.size:
        di, dj = state.ema_origin_ij[0] - o_new[0], state.ema_origin_ij[1] - o_new[1]
        assert di >= 0 and dj >= 0, "the fields grid only grows"
        h, w = state.ema.shape
        old[di:di + h, dj:dj + w] = state.ema
    ema = ema_update(old, now.values, cfg.path.ema_gamma)
    return o_new, ema, FloorMap(now.origin_xy_m.copy(), now.cell_m, ema)


def _segment_point_dist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(((p - a) * ab).sum(axis=1) / np.maximum((ab * ab).sum(axis=1), 1e-12), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * ab - p).T)


def _block_reach(acfg: ActionConfig) -> float:
    """How far ahead of the robot a blocked spot is remembered: one forward step and the robot's radius."""
    return acfg.forward_step_m + acfg.radius_m


def _block_ahead(blocks, robot_xy: np.ndarray, fwd: np.ndarray, acfg: ActionConfig) -> bool:
    """Whether a remembered blocked spot lies in the rectangle one forward step sweeps (as in forward_blocked)."""
    for x, y, _ in blocks:
        rel = np.array([x, y]) - robot_xy
        ahead = float(rel @ fwd)
        side = float(rel[0] * -fwd[1] + rel[1] * fwd[0])
        if 0.0 < ahead <= _block_reach(acfg) + 1e-9 and abs(side) <= acfg.radius_m:
            return True
    return False


def _source(cfg: PlanningConfig, sel: SelectionOut, arrays: GraphArrays, to_target: np.ndarray, pred: np.ndarray,
            robot_xy: np.ndarray, robot_yaw: float) -> int:
    """The node the path starts at (-1: the target is unreachable from near the robot).

    Candidates: the nearest node the robot can drive to straight (``SelectionOut.node_leg_clear``;
    the nearest of all when there is none), and the nodes within ``source_radius_m`` of the robot
    at most three graph hops from it (a node that close and more hops away could lie behind a
    wall) with a clear way too. Each costs the straight way to it, the turns (toward it, then onto
    its next edge; a turn step is worth one forward step) and its eq. (11) cost to the target."""
    d = np.hypot(*(sel.node_xy_m - robot_xy).T)
    clear = sel.node_leg_clear
    near = nearest_clear_node(sel.node_xy_m, robot_xy, clear)
    cand = {near}
    if cfg.source_radius_m > 0.0:
        ring = {near}
        for _ in range(3):
            ring = {int(w) for a in ring for w in np.concatenate([arrays.v[arrays.u == a], arrays.u[arrays.v == a]])}
            cand |= {w for w in ring if d[w] <= cfg.source_radius_m and clear[w]}
    acfg = cfg.actions
    per_rad = acfg.forward_step_m / math.radians(acfg.turn_step_deg)
    best, best_cost = -1, math.inf
    for s in sorted(cand):
        if not math.isfinite(to_target[s]):
            continue
        heading = robot_yaw
        turn = 0.0
        if d[s] > acfg.reach_tol_m:
            bearing = math.atan2(*(sel.node_xy_m[s] - robot_xy)[::-1])
            turn, heading = abs(wrap_angle(bearing - heading)), bearing
        nxt = int(pred[s])
        if nxt >= 0:
            turn += abs(wrap_angle(math.atan2(*(sel.node_xy_m[nxt] - sel.node_xy_m[s])[::-1]) - heading))
        total = float(d[s]) + per_rad * turn + float(to_target[s])
        if total < best_cost - 1e-9:
            best, best_cost = s, total
    return best


def _plan(cfg: PlanningConfig, sel: SelectionOut, now_map: FloorMap | None, ema_map: FloorMap | None,
          blocks, robot_xy: np.ndarray, robot_yaw: float) -> tuple[np.ndarray, float]:
    """Waypoints (P, 2) from the robot to the target and the path's eq. (11) cost; (empty, nan) without a path."""
    n = len(sel.node_xy_m)
    if n == 0 or sel.target_node < 0:
        return np.zeros((0, 2)), math.nan
    arrays = edge_list_arrays(n, sel.edges, sel.edge_length_m)
    u, v = arrays.u, arrays.v
    a, b = sel.node_xy_m[u], sel.node_xy_m[v]
    zero = np.zeros(len(u))
    um_now = segment_means(now_map, a, b, cfg.sample_spacing_m) if now_map is not None and len(u) else zero
    um_ema = segment_means(ema_map, a, b, cfg.sample_spacing_m) if ema_map is not None and len(u) else zero
    cost = variant_edge_cost(cfg.path, arrays.length_m, um_now, um_ema)          # eq. (11)
    for x, y, _ in blocks:
        if len(u):
            near = _segment_point_dist(np.array([x, y]), a, b) <= cfg.block_radius_m
            cost = cost + np.where(near, cfg.block_penalty_m, 0.0)
    to_target, pred = dijkstra(arrays, np.maximum(cost, 1e-9), int(sel.target_node))   # undirected: costs to the target
    source = _source(cfg, sel, arrays, to_target, pred, robot_xy, robot_yaw)
    if source < 0:
        return np.zeros((0, 2)), math.nan
    nodes, total = [source], float(to_target[source])
    while nodes[-1] != int(sel.target_node):
        nodes.append(int(pred[nodes[-1]]))
    wp = sel.node_xy_m[nodes]
    # start from the second node when the robot is already between the first two and can drive to it straight
    if (len(nodes) >= 2 and sel.node_leg_clear[nodes[1]]
            and np.hypot(*(robot_xy - wp[1])) <= np.hypot(*(wp[0] - wp[1]))):
        wp = wp[1:]
    if np.hypot(*(wp[-1] - sel.target_xy_m)) > 1e-6:
        wp = np.concatenate([wp, sel.target_xy_m[None]])
    return wp.astype(np.float64), float(total)


def _steer(cfg: PlanningConfig, pose: RobotPose2D, ps: PathStep, sel: SelectionOut, blocks, now: int) -> Action:
    """``ps``'s action, or a turn toward a heading whose step keeps clear of the known obstacles around the robot
    (with ``actions.steer_skip_blocked``, not one it was blocked on from here: :func:`_blocked_yaws`)."""
    barred = _blocked_yaws(cfg, blocks, pose, now) if cfg.actions.steer_skip_blocked else ()
    return steer_clear(pose, ps, sel.local_clear_m, sel.local_origin_xy_m, sel.local_cell_m, cfg.actions, barred)


def _blocked_yaws(cfg: PlanningConfig, blocks, pose: RobotPose2D, now: int) -> list[float]:
    """Headings the robot was blocked on from where it stands (``actions.steer_skip_blocked``). A blocked spot is
    remembered one forward step and the robot's radius ahead of where the robot stood, so one at that distance
    (within bump_tol_m: the robot has not moved since) lies on the heading it was blocked on. A block on the
    heading the robot faces, from this step or the last, is left out: the robot waits there, or tries again."""
    reach = _block_reach(cfg.actions)
    half = 0.5 * math.radians(cfg.actions.turn_step_deg)
    out = []
    for x, y, until in blocks:
        dx, dy = x - pose.x_m, y - pose.y_m
        if abs(math.hypot(dx, dy) - reach) > cfg.bump_tol_m:
            continue
        yaw = math.atan2(dy, dx)
        if until - cfg.block_hold_steps >= now - 1 and abs(wrap_angle(yaw - pose.yaw_rad)) <= half + 1e-6:
            continue
        out.append(yaw)
    return out


def _evade_turn(cfg: PlanningConfig, rec: StepRecord, now_map: FloorMap | None, robot_xy: np.ndarray,
                yaw_rad: float) -> Action:
    """The way to turn away from a spot the robot keeps bumping into: toward the side with more room."""
    f = rec.frame
    left, right = side_clearance(f.depth_m, f.K, f.T_world_cam, cfg.actions, cfg.evade_reach_m)
    if left != right:
        return Action.TURN_LEFT if left > right else Action.TURN_RIGHT
    if now_map is not None:
        r = np.arange(cfg.actions.radius_m, cfg.evade_reach_m + 1e-9, cfg.sample_spacing_m)
        a = np.radians(np.arange(10.0, 171.0, 20.0))
        rr, aa = np.meshgrid(r, a)
        def side_sum(sign: float) -> float:
            ang = yaw_rad + sign * aa
            pts = robot_xy + np.stack([rr * np.cos(ang), rr * np.sin(ang)], axis=-1)
            return float(now_map.sample(pts).sum())
        um_left, um_right = side_sum(1.0), side_sum(-1.0)
        if um_left != um_right:
            return Action.TURN_LEFT if um_left < um_right else Action.TURN_RIGHT
    return Action.TURN_LEFT


def step(cfg: PlanningConfig, rec: StepRecord, state: PlanningState | None,
         rng: np.random.Generator) -> tuple[PlanningState, PlanningOut]:
    """Plan (or keep following) a path to the selected target and return the next discrete action.

    Reads ``rec.frame`` (T_world_cam for the robot's pose, depth_m and K for the collision
    check, step), ``rec.fields.u_m`` and ``rec.selection`` (graph, target). Deterministic;
    ``rng`` is not used.
    """
    assert rec.selection is not None and rec.fields is not None, "planning runs after fields and selection"
    state = init_state(cfg) if state is None else state
    f, sel = rec.frame, rec.selection
    now = int(f.step)
    pose = robot_pose_of(f)
    robot_xy = np.array([pose.x_m, pose.y_m])
    acfg = cfg.actions

    has_grid = 0 not in rec.fields.u_m.shape
    now_map = motion_floor_map(rec.fields, cfg.um_band_lo_m, cfg.um_band_hi_m) if has_grid else None
    if now_map is not None:
        ema_origin, ema, ema_map = _ema_map(cfg, state, now_map)
    else:
        ema_origin, ema, ema_map = state.ema_origin_ij, state.ema, None

    blocks = tuple(b for b in state.blocks if b[2] > now)
    step_m = (math.inf if state.last_xy_m is None
              else math.hypot(robot_xy[0] - state.last_xy_m[0], robot_xy[1] - state.last_xy_m[1]))
    bumped = state.last_action == int(Action.FORWARD) and step_m < cfg.bump_tol_m
    fwd = np.array([math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)])
    ahead = robot_xy + fwd * _block_reach(acfg)
    if bumped:
        blocks = blocks + ((float(ahead[0]), float(ahead[1]), now + cfg.block_hold_steps),)
    moved = state.last_xy_m is not None and step_m >= cfg.bump_tol_m
    bumps_in_row = 0 if moved else state.bumps_in_row + int(bumped)
    waits_in_row = 0 if moved else state.waits_in_row
    evade = state.evade
    if not evade and ((cfg.bump_evade_after and bumps_in_row >= cfg.bump_evade_after)
                      or (cfg.wait_evade_after and waits_in_row >= cfg.wait_evade_after)):
        turns = max(1, math.ceil(cfg.evade_turn_deg / acfg.turn_step_deg - 1e-9))
        more = max(0, math.ceil(180.0 / acfg.turn_step_deg - 1e-9) - turns)
        turn, fwd_a = int(_evade_turn(cfg, rec, now_map, robot_xy, pose.yaw_rad)), int(Action.FORWARD)
        # evade_turn_deg, then a forward step; where the camera sees that step blocked, one more turn step
        # and another try, up to a half turn (a person standing close ahead still blocks the step at 60 deg)
        evade = (turn,) * turns + (fwd_a, turn) * more + (fwd_a,)
        bumps_in_row = waits_in_row = 0

    target_key = (float(sel.target_xy_m[0]), float(sel.target_xy_m[1]), float(sel.target_yaw_rad))
    gkey = _graph_key(sel)
    new_target = target_key != state.target_key
    stuck_state = StuckState() if new_target else state.stuck
    stuck_state = update_stuck(stuck_state, robot_xy[0], robot_xy[1], acfg)

    path, cost, k, planned_step = state.path_xy_m, state.path_cost, state.next_waypoint, state.planned_step
    replanned = False
    evading = False
    if evade and sel.mode != "none" and sel.target_node >= 0:
        # turning away from a spot it kept bumping into or waiting at, then one step forward where nothing
        # is seen; the path is dropped, so the step after the last of these re-plans
        first, evade = Action(evade[0]), evade[1:]
        if first == Action.FORWARD:
            seen = forward_blocked(f.depth_m, f.K, f.T_world_cam, acfg)
            if not seen and cfg.evade_map_check:
                seen = not clear_headings(sel.local_clear_m, sel.local_origin_xy_m, sel.local_cell_m, pose,
                                          np.array([pose.yaw_rad]), acfg)[0]
            if not seen:
                evade = ()                                 # the step is clear: take it, then re-plan
            elif evade:
                first, evade = Action(evade[0]), evade[1:]  # seen blocked: turn on
            else:
                first = None                               # blocked at a half turn: back to the path
        if first is not None:
            action, path, cost, k, blocked, evading = first, np.zeros((0, 2)), math.nan, 0, True, True
    else:
        evade = ()
    if evading:
        pass                                               # the turn-away chose the action
    elif sel.mode == "none" or sel.target_node < 0:
        action, path, cost, k, blocked = Action.TURN_LEFT, np.zeros((0, 2)), math.nan, 0, False   # look around
    else:
        if (new_target or gkey != state.graph_key or bumped or len(path) == 0
                or now - planned_step >= cfg.replan_every):
            path, cost = _plan(cfg, sel, now_map, ema_map, blocks, robot_xy, pose.yaw_rad)
            k, planned_step, replanned = 0, now, True
        prefer = Action(state.last_action) if state.last_action in (int(Action.TURN_LEFT), int(Action.TURN_RIGHT)) \
            else None
        ps = next_action(pose, path[k:], sel.target_yaw_rad, acfg, prefer)
        action, k = _steer(cfg, pose, ps, sel, blocks, now), k + ps.next_waypoint
        blocked = False
        seen_block = action == Action.FORWARD and forward_blocked(f.depth_m, f.K, f.T_world_cam, acfg)
        if action == Action.FORWARD and (seen_block or _block_ahead(blocks, robot_xy, fwd, acfg)):
            blocked = True
            if seen_block:
                # only fresh evidence starts or renews a block: one remembered block must not renew
                # itself every step, or the robot waits in front of it forever
                blocks = blocks + ((float(ahead[0]), float(ahead[1]), now + cfg.block_hold_steps),)
            path, cost = _plan(cfg, sel, now_map, ema_map, blocks, robot_xy, pose.yaw_rad)
            k, planned_step, replanned = 0, now, True
            ps = next_action(pose, path, sel.target_yaw_rad, acfg, prefer)
            action, k = _steer(cfg, pose, ps, sel, blocks, now), ps.next_waypoint
            if action == Action.FORWARD and seen_block:
                # Still forward into what the camera sees. First aim exactly (a step at up to
                # forward_tol_deg off can graze a door jamb the aligned step clears), then wait.
                action = next_action(pose, path, sel.target_yaw_rad, replace(acfg, forward_tol_deg=0.0),
                                     prefer).action
                if action == Action.FORWARD:
                    action = Action.STOP                   # the way is still blocked: wait for it to clear
                    waits_in_row += 1
            # A block only remembered (nothing seen ahead now) re-routes but never makes the robot
            # wait: a forward move into it that fails is a bump, which renews it.
        if len(path) == 0:
            action = Action.TURN_LEFT                      # no path to the target: look around

    reached = action == Action.STOP and not blocked
    stuck = is_stuck(stuck_state, acfg) and not reached
    new_state = PlanningState(ema_origin, ema, gkey, target_key, np.asarray(path, np.float64), float(cost), int(k),
                              int(planned_step), blocks, (float(robot_xy[0]), float(robot_xy[1])), int(action),
                              stuck_state, int(bumps_in_row), int(waits_in_row), tuple(int(a) for a in evade))
    out = PlanningOut(action=int(action), path_xy_m=np.concatenate([robot_xy[None], path[k:]]) if len(path) else
                      np.zeros((0, 2)), path_cost=float(cost), replanned=replanned, blocked=blocked, stuck=stuck)
    return new_state, out
