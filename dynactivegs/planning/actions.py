"""From a path to the robot's next discrete action; local collision check; stuck detection.

- :func:`next_action`: turn toward the next waypoint, go forward when aligned within half a
  turn step, at the end turn to the target yaw, then STOP (DESIGN.md §5 Planning: "the path
  turned into the next discrete action").
- :func:`forward_blocked`: whether the next forward move would run into something seen in
  the current depth frame (people included, whatever their uncertainty): points in the body's
  height band inside the rectangle the robot's disc sweeps in one step (:func:`forward_hits`).
- :func:`side_clearance`: the nearest return on each side of the robot, for turning away from
  something it keeps bumping into.
- :func:`steer_clear`: where the known obstacles around the robot (the selection's
  ``local_clear_m``) say the aimed forward step would graze one, the nearest heading toward
  the waypoint whose step keeps clear (:func:`clear_headings`).
- :class:`StuckState` / :func:`update_stuck`: the robot has not left a small disc for k steps
  (blocked by a person in a doorway, turning back and forth), so the caller should pick
  another target.

Actions are :class:`dynactivegs.sim.robot.Action`; yaw is counter-clockwise from +x, radians.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from dynactivegs.sim.config import RobotConfig
from dynactivegs.errors import check_config
from dynactivegs.records import RobotPose2D
from dynactivegs.selection.occupancy import backproject
from dynactivegs.sim.robot import Action, wrap_angle



@dataclass(frozen=True, slots=True)
class ActionConfig:
    """Path following, the local collision check and the stuck rule."""

    forward_step_m: float = 0.25
    """Distance of one forward action (match RobotConfig.forward_step_m)."""
    turn_step_deg: float = 10.0
    """Angle of one turn action (match RobotConfig.turn_step_deg)."""
    radius_m: float = 0.18
    """The robot's collision radius (match RobotConfig.radius_m)."""
    reach_tol_m: float = 0.15
    """A waypoint within this distance counts as reached; keep it above half the forward step so a step never overshoots it back and forth."""
    target_tol_m: float = 0.3
    """The last waypoint, the target position, counts as reached within this distance (match selection.reach_tol_m,
    within which selection counts the target reached): the robot just turns to the target's heading there. At
    reach_tol_m it drove to a target 0.2 m behind it (a half turn, a step, a half turn back) for a view it could
    have had by turning on the spot."""
    band_lo_m: float = 0.1
    """Depth points lower than this above the floor do not block (floor)."""
    band_hi_m: float = 1.5
    """Depth points higher than this do not block (above the robot's body)."""
    min_blocking_points: int = 3
    """This many depth points in the swept rectangle block the move (fewer are treated as noise)."""
    forward_tol_deg: float = 15.0
    """Following a path, the robot steps forward once heading within this of the waypoint it aims at
    (a 0.25 m step at 15 deg drifts 6.5 cm sideways); turning to exactly +-5 deg makes it zig-zag."""
    turn_commit_deg: float = 120.0
    """A turn in progress is kept for heading errors above this the other way (the far side of a bearing
    behind the robot); 180 never keeps it."""
    steer_search_deg: float = 45.0
    """:func:`steer_clear` looks for a heading whose forward step keeps clear of the known obstacles within this
    of the waypoint's bearing; 0: never (the robot steers by its path alone). In a passage a few centimetres
    wider than the robot, a step at up to forward_tol_deg off grazes a wall the exact heading clears: full on
    apartment-03, seed 0, 1000 steps, spent 581 of steps 332-930 in one such passage, bumping at its ends and
    re-targeting to the other end after each bump (75.0 % C.R.); with steering it passed through in 24 steps
    (92.1 %). Measured closed-loop (benchmarks/results/apartment-1000-steer: full, 4 apartment scenes, seeds
    0 and 1, against the same 8 runs without it): collisions with no person within 1 m fell from 39 to 5, all
    collisions from 31.9 to 23.0 per run, and the mean went from 3.95 cm / 86.7 % / 22.73 dB to
    2.87 / 92.0 / 23.96."""
    clear_margin_m: float = 0.02
    """A forward step keeps clear when the robot's edge stays this far from the known obstacles along it (or,
    where it stands nearer already, gets no nearer)."""
    steer_tight: bool = True
    """:func:`steer_clear` with no heading clear: the robot steps on the heading (within steer_search_deg of the
    bearing) whose step keeps farthest from the known obstacles, when the map says its body fits there (the
    smallest distance along the step at least radius_m; clear_margin_m and the no-nearer rule are waived), and
    turns toward it first. False: the path's own action stays, and the depth check and the bump rule deal with
    it. Why: a robot that squeezed into a pocket behind furniture (full with selection.cut_hold_local,
    apartment-01, seed 2, at (8.88, 5.67) m) had no clear heading out. Its path's heading (-171 deg) passed a
    corner 0.13 m from the robot's centre in the map, and it bumped there; -151 deg kept 0.185 m, more than the
    robot's 0.18 m radius. Measured together with selection.cut_hold_local and selection.discs_spare_trail (see
    cut_hold_local); on by default with them."""
    steer_skip_blocked: bool = True
    """:func:`steer_clear` does not take a heading on which the robot was blocked from where it stands (the
    camera saw the step blocked, or the step failed: the planner's remembered blocked spots,
    planning.block_hold_steps long), unless it faces that heading and the block is from this step or the last
    one (it is waiting for the way to clear, or tries a step once more before bump_evade_after). Without it, the
    depth check and the map can disagree for good: motion_view on apartment-01, seed 0, 1000 steps, in a pocket
    at (8.79, 5.62) m, turned between -152.8 and -162.8 deg from step 300 to the end (50.2 % C.R.). At -152.8
    the camera saw the step blocked and the robot turned to aim exactly at its path (-163 deg); at -162.8 the
    map said that step comes too near an obstacle and -152.8 does not, and it turned back (`full` and
    plan_dyn_edge made the same run). With it, that run reached the same spot at step 410 and left it at step 479
    (3.78 cm / 88.2 % / 22.49 dB; benchmarks/results/apartment-1000-ablation). On by default since
    benchmarks/results/apartment-1000-skip: `full` and `baseline` on the 12 (scene, seed) pairs with it, where
    `full` on seed 0 was 3.20 / 91.6 / 23.76 against 4.02 / 81.3 / 21.68 without it on the same machine
    (`baseline` 4.56 / 86.9 / 23.03 against 3.75 / 89.1 / 23.46: two scenes better, two worse, no wedge).
    False: the map alone chooses the heading."""
    stuck_steps: int = 40
    """Steps without leaving a disc of stuck_move_tol_m after which the robot is stuck (above a full turn of steps)."""
    stuck_move_tol_m: float = 0.3
    """Radius of the disc the robot must leave to count as moving (match selection.stuck_move_tol_m)."""

    def __post_init__(self) -> None:
        check_config(0.01 <= self.forward_step_m <= 2.0, "actions.forward_step_m", self.forward_step_m, "in [0.01, 2] m")
        check_config(0.5 <= self.turn_step_deg <= 90.0, "actions.turn_step_deg", self.turn_step_deg, "in [0.5, 90] deg")
        check_config(0.0 < self.radius_m <= 1.0, "actions.radius_m", self.radius_m, "in (0, 1] m")
        check_config(0.5 * self.forward_step_m < self.reach_tol_m, "actions.reach_tol_m", self.reach_tol_m,
                 "above half of actions.forward_step_m")
        check_config(self.target_tol_m >= self.reach_tol_m, "actions.target_tol_m", self.target_tol_m,
                     ">= actions.reach_tol_m")
        check_config(0.0 <= self.forward_tol_deg <= 45.0, "actions.forward_tol_deg", self.forward_tol_deg,
                     "in [0, 45] deg")
        check_config(0.0 <= self.turn_commit_deg <= 180.0, "actions.turn_commit_deg", self.turn_commit_deg,
                     "in [0, 180] deg")
        check_config(0.0 <= self.band_lo_m < self.band_hi_m, "actions.band_lo_m", self.band_lo_m, "in [0, band_hi_m)")
        check_config(self.min_blocking_points >= 1, "actions.min_blocking_points", self.min_blocking_points, ">= 1")
        check_config(0.0 <= self.steer_search_deg <= 90.0, "actions.steer_search_deg", self.steer_search_deg,
                     "in [0, 90] deg (0: off)")
        check_config(0.0 <= self.clear_margin_m <= 0.5, "actions.clear_margin_m", self.clear_margin_m, "in [0, 0.5] m")
        check_config(self.stuck_steps >= 1, "actions.stuck_steps", self.stuck_steps, ">= 1")
        check_config(self.stuck_move_tol_m > 0.0, "actions.stuck_move_tol_m", self.stuck_move_tol_m, "> 0 m")

    @staticmethod
    def for_robot(robot: RobotConfig) -> "ActionConfig":
        """Step sizes, radius and height band taken from the robot's config; the rest default."""
        return ActionConfig(forward_step_m=robot.forward_step_m, turn_step_deg=robot.turn_step_deg,
                            radius_m=robot.radius_m, reach_tol_m=max(0.15, 0.6 * robot.forward_step_m),
                            band_hi_m=robot.body_height_m)


@dataclass(frozen=True, slots=True)
class PathStep:
    """The next action and how far along the waypoints the robot is."""

    action: Action
    next_waypoint: int            # index of the first waypoint not yet reached (== len(waypoints) when all are)
    aim_rad: float | None = None  # bearing of the waypoint aimed at; None when turning to the target's heading


def _turn_toward(err_rad: float, half_step_rad: float, prefer: Action | None = None,
                 commit_rad: float = math.pi) -> Action | None:
    """The turn that reduces the heading error ``err_rad`` the shorter way (None when within half a step).

    With ``prefer`` (the turn just taken), an error of more than ``commit_rad`` the other way is
    turned through the long way instead: a bearing behind the robot that wobbles from one side
    to the other would otherwise make it turn back and forth on the spot.
    """
    if abs(err_rad) <= half_step_rad + 1e-9:
        return None
    turn = Action.TURN_LEFT if err_rad > 0 else Action.TURN_RIGHT
    if prefer in (Action.TURN_LEFT, Action.TURN_RIGHT) and turn != prefer and abs(err_rad) > commit_rad:
        return prefer
    return turn


def next_action(pose: RobotPose2D, waypoints_xy_m: np.ndarray, target_yaw_rad: float | None,
                cfg: ActionConfig, prefer_turn: Action | None = None) -> PathStep:
    """The next discrete action to follow ``waypoints_xy_m`` (K, 2) and end facing ``target_yaw_rad``.

    Waypoints up to the last one within ``reach_tol_m`` of the robot are taken as reached, and so
    is one the robot is already alongside the next segment of; all are once the last one is within
    ``target_tol_m``. Then: turn toward the farthest
    waypoint whose chord from the robot stays within ``radius_m`` of the waypoints it skips,
    until the heading error is at most ``cfg.forward_tol_deg`` (or half a turn step), go forward;
    with all waypoints reached, turn to ``target_yaw_rad`` (the shorter way) and STOP once
    within half a turn step (``None``: STOP at once). ``prefer_turn``: the turn the
    robot just took; it is kept for heading errors above ``cfg.turn_commit_deg`` the other way.
    """
    commit = math.radians(cfg.turn_commit_deg)
    wp = np.asarray(waypoints_xy_m, np.float64).reshape(-1, 2)
    half = 0.5 * math.radians(cfg.turn_step_deg)
    d = np.hypot(wp[:, 0] - pose.x_m, wp[:, 1] - pose.y_m)
    within = np.nonzero(d <= cfg.reach_tol_m)[0]
    k = int(within[-1]) + 1 if len(within) else 0
    if len(wp) and d[-1] <= cfg.target_tol_m:
        k = len(wp)
    # Already alongside the segment wp[k] -> wp[k+1]: skip wp[k] rather than turn back to it
    # (the nearest graph node is often behind a robot that is between two nodes).
    xy = np.array([pose.x_m, pose.y_m])
    while k + 1 < len(wp):
        seg = wp[k + 1] - wp[k]
        t = float(np.dot(xy - wp[k], seg) / max(float(np.dot(seg, seg)), 1e-12))
        off = float(np.linalg.norm(wp[k] + min(max(t, 0.0), 1.0) * seg - xy))
        if not (0.0 < t < 1.0 and off <= cfg.radius_m + cfg.reach_tol_m):
            break
        k += 1
    # Cut wiggles of the skeleton: head straight for the farthest waypoint j such that every
    # waypoint skipped lies within the robot's radius of the chord robot -> wp[j] (the skeleton
    # keeps at least that clearance, so the chord stays in free space; the depth check guards
    # the rest). A turn step costs as much as a forward step, so zig-zags are slow.
    j = k
    while j + 1 < len(wp):
        chord = wp[j + 1] - xy
        n2 = max(float(np.dot(chord, chord)), 1e-12)
        mid = wp[k:j + 1]
        t = np.clip((mid - xy) @ chord / n2, 0.0, 1.0)
        if np.max(np.linalg.norm(xy + t[:, None] * chord - mid, axis=1)) > cfg.radius_m:
            break
        j += 1
    k_aim = j
    if k == len(wp):
        if target_yaw_rad is None:
            return PathStep(Action.STOP, k)
        turn = _turn_toward(wrap_angle(target_yaw_rad - pose.yaw_rad), half, prefer_turn, commit)
        return PathStep(Action.STOP if turn is None else turn, k)
    bearing = math.atan2(wp[k_aim, 1] - pose.y_m, wp[k_aim, 0] - pose.x_m)
    go = max(half, math.radians(cfg.forward_tol_deg))
    turn = _turn_toward(wrap_angle(bearing - pose.yaw_rad), go, prefer_turn, commit)
    return PathStep(Action.FORWARD if turn is None else turn, k, bearing)


def _returns_around_robot(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                          stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The depth returns in the robot's frame: height z, metres ahead, metres to the left, flat pixel index.

    The camera is taken to sit above the robot's centre looking along its heading (the optical
    axis projected to the floor)."""
    pts, pix = backproject(depth_m, K, T_world_cam, stride)
    fwd = T_world_cam[:2, 2].astype(np.float64)
    norm = math.hypot(fwd[0], fwd[1])
    assert norm > 1e-6, "camera looks straight up or down"
    fwd = fwd / norm
    rel = pts[:, :2] - T_world_cam[:2, 3]
    return pts[:, 2], rel @ fwd, rel @ np.array([-fwd[1], fwd[0]]), pix


def forward_hits(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, cfg: ActionConfig,
                 stride: int = 1) -> np.ndarray:
    """int64 flat pixel indices (row-major into (H, W)) of the returns one forward step would hit.

    The camera is assumed to sit above the robot's centre (its position projected to the
    floor) looking along the robot's heading (its optical axis projected to the floor).
    Hits: height in ``[band_lo_m, band_hi_m]``, ahead by ``(0, forward_step + radius]``
    and at most ``radius`` to either side. ``depth_m`` float32 (H, W), 0 = no return.
    """
    z, ahead, side, pix = _returns_around_robot(depth_m, K, T_world_cam, stride)
    hit = ((z >= cfg.band_lo_m) & (z <= cfg.band_hi_m) & (ahead > 0.0)
           & (ahead <= cfg.forward_step_m + cfg.radius_m) & (np.abs(side) <= cfg.radius_m))
    return pix[hit]


def forward_blocked(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, cfg: ActionConfig,
                    stride: int = 1) -> bool:
    """Whether one forward step would hit something seen in this depth frame (:func:`forward_hits`).

    The camera sees nothing below its lower field-of-view edge near the robot (at 1.25 m and
    60 deg vertical FOV, only points above ~1 m are visible 0.4 m ahead), so low obstacles
    must come from the occupancy map; this check catches walls and people.
    """
    return len(forward_hits(depth_m, K, T_world_cam, cfg, stride)) >= cfg.min_blocking_points


def side_clearance(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, cfg: ActionConfig,
                   reach_m: float, stride: int = 1) -> tuple[float, float]:
    """Distance (m) from the robot's centre to the nearest return on its left and on its right (inf: none).

    Counted are returns in the body's height band within ``reach_m`` of the robot and not behind
    it (ahead > -radius); a return straight ahead counts for both sides. The side with the larger
    clearance is the one to turn toward when the robot keeps bumping into something.
    """
    z, ahead, side, _ = _returns_around_robot(depth_m, K, T_world_cam, stride)
    dist = np.hypot(ahead, side)
    near = (z >= cfg.band_lo_m) & (z <= cfg.band_hi_m) & (ahead > -cfg.radius_m) & (dist <= reach_m)
    left = dist[near & (side >= 0.0)]
    right = dist[near & (side <= 0.0)]
    return (float(left.min()) if len(left) else math.inf, float(right.min()) if len(right) else math.inf)


_SQUEEZE_GAIN_M = 0.01
"""A squeezed robot turns to a step that keeps at least this much farther from the obstacles (:func:`steer_clear`)."""


def _step_distances(clear_m: np.ndarray, origin_xy_m: np.ndarray, cell_m: float, pose: RobotPose2D,
                    yaws: np.ndarray, cfg: ActionConfig) -> np.ndarray:
    """float64 (len(yaws), n + 1): the window's distance (bilinear) along one forward step per heading, sampled
    every half cell from the robot's position (column 0); inf off the window."""
    n = max(2, int(math.ceil(cfg.forward_step_m / (0.5 * cell_m))))
    t = np.arange(n + 1) / n * cfg.forward_step_m                        # metres along the step, 0 = here
    xy = np.array([pose.x_m, pose.y_m]) + t[None, :, None] * np.stack([np.cos(yaws), np.sin(yaws)], -1)[:, None, :]
    col = (xy[..., 0] - origin_xy_m[0]) / cell_m - 0.5
    row = (xy[..., 1] - origin_xy_m[1]) / cell_m - 0.5
    size = clear_m.shape[0]
    d = ndimage.map_coordinates(clear_m.astype(np.float64), [row.ravel(), col.ravel()], order=1,
                                mode="nearest").reshape(row.shape)
    d[(row < -0.5) | (row > size - 0.5) | (col < -0.5) | (col > size - 0.5)] = np.inf
    return d


def _clear(d: np.ndarray, cell_m: float, cfg: ActionConfig) -> np.ndarray:
    """bool per row of :func:`_step_distances`: the step keeps clear (:func:`clear_headings`)."""
    # below radius + margin, a sample may not fall more than a quarter cell (bilinear noise) under the largest
    # distance before it: a step that leaves one obstacle for another nearer one is not clear either
    peak = np.maximum.accumulate(d, axis=1)[:, :-1]
    need = np.minimum(cfg.radius_m + cfg.clear_margin_m, peak - 0.25 * cell_m)
    return np.all(d[:, 1:] >= need, axis=1)


def clear_headings(clear_m: np.ndarray, origin_xy_m: np.ndarray, cell_m: float, pose: RobotPose2D,
                   yaws_rad: np.ndarray, cfg: ActionConfig) -> np.ndarray:
    """bool per heading in ``yaws_rad``: whether one forward step from the robot's position keeps clear of the known
    obstacles of the window ``clear_m`` (float32 (L, L), distance to the nearest obstacle, cell ``[i, j]`` centred
    at ``origin + ((j, i) + 0.5) * cell``).

    Along the step, sampled every half cell, the distance (bilinear) must stay at least
    ``radius + clear_margin_m``; where it is below that (the robot stands nearer already), it may not
    fall by more than a quarter cell under the largest distance earlier on the step: the robot may
    move along an obstacle or away from it, not into it, nor away from one into another.
    Samples off the window count as clear."""
    yaws = np.asarray(yaws_rad, np.float64).reshape(-1)
    if clear_m.size == 0:
        return np.ones(len(yaws), bool)
    return _clear(_step_distances(clear_m, origin_xy_m, cell_m, pose, yaws, cfg), cell_m, cfg)


def steer_clear(pose: RobotPose2D, step: PathStep, clear_m: np.ndarray, origin_xy_m: np.ndarray, cell_m: float,
                cfg: ActionConfig, blocked_yaws_rad: Sequence[float] = ()) -> Action:
    """The action of ``step`` (from :func:`next_action`), or a turn toward a heading whose step keeps clear.

    Applies when the robot goes for a waypoint (``step.aim_rad`` set, a forward step or a turn toward it)
    within ``cfg.steer_search_deg`` of its heading. Among the headings a whole number of turn steps away
    and within ``steer_search_deg`` of the bearing, those whose forward step keeps clear of the known
    obstacles (:func:`clear_headings`) are candidates; the robot steps forward on the nearest (in turn steps)
    candidate within ``forward_tol_deg`` of the bearing, else on the candidate nearest the bearing, and turns
    toward it first. A robot squeezed already (nearer than ``radius + clear_margin_m`` to an obstacle of the
    window) takes, of the candidates within ``forward_tol_deg``, the nearest in turns whose step keeps within
    a centimetre as far from the obstacles as the best one (the smallest distance along the step): the map
    is a few centimetres off the world, and a step that drifts closer within the map's noise can still
    graze; a centimetre's gain is worth a turn step, less is not (in a passage barely wider than that
    the robot would zig-zag from side to side). With every heading clear this is what
    :func:`next_action` does; with none, the action stays (the depth check and the bump rule deal
    with it). ``blocked_yaws_rad``: headings never to take (those within half a turn step of one), from
    ``cfg.steer_skip_blocked``; the caller picks them.
    """
    if (step.aim_rad is None or clear_m.size == 0 or cfg.steer_search_deg <= 0.0
            or step.action not in (Action.FORWARD, Action.TURN_LEFT, Action.TURN_RIGHT)):
        return step.action
    turn = math.radians(cfg.turn_step_deg)
    search = math.radians(cfg.steer_search_deg)
    err0 = wrap_angle(step.aim_rad - pose.yaw_rad)
    if abs(err0) > search + 1e-9:
        return step.action
    js = np.arange(math.ceil((err0 - search) / turn - 1e-9), math.floor((err0 + search) / turn + 1e-9) + 1)
    err = np.abs(err0 - js * turn)
    d = _step_distances(clear_m, origin_xy_m, cell_m, pose, pose.yaw_rad + js * turn, cfg)
    ok = _clear(d, cell_m, cfg)
    barred = np.zeros(len(js), bool)
    for y in blocked_yaws_rad:
        barred |= np.abs(wrap_angle(pose.yaw_rad + js * turn - y)) <= 0.5 * turn + 1e-6
    ok &= ~barred
    if not ok.any():
        if not cfg.steer_tight:
            return step.action
        low = np.where(barred, -np.inf, d[:, 1:].min(axis=1))
        best = np.lexsort((np.abs(js), -low))[0]              # farthest from the obstacles, then fewest turns
        if low[best] < cfg.radius_m:
            return step.action
        j = int(js[best])
        return Action.FORWARD if j == 0 else Action.TURN_LEFT if j > 0 else Action.TURN_RIGHT
    aligned = ok & (err <= max(0.5 * turn, math.radians(cfg.forward_tol_deg)) + 1e-9)
    pool = np.nonzero(aligned if aligned.any() else ok)[0]
    if aligned.any() and d[0, 0] < cfg.radius_m + cfg.clear_margin_m:
        # squeezed (nearer than radius + margin to something): of the aligned steps that keep within a
        # centimetre as far from it as the best one, the nearest in turns
        low = d[pool, 1:].min(axis=1)
        near_best = low >= low.max() - _SQUEEZE_GAIN_M
        pool, key = pool[near_best], (np.abs(js[pool[near_best]]), -low[near_best])
    elif aligned.any():
        key = (np.abs(js[pool]), err[pool])
    else:
        key = (err[pool], np.abs(js[pool]))
    j = int(js[pool[np.lexsort(key[::-1])[0]]])
    return Action.FORWARD if j == 0 else Action.TURN_LEFT if j > 0 else Action.TURN_RIGHT


@dataclass(frozen=True, slots=True)
class StuckState:
    """Where the robot last counted as moving, and for how many steps since it has stayed near there."""

    anchor_xy_m: tuple[float, float] | None = None
    steps_still: int = 0


def update_stuck(state: StuckState, x_m: float, y_m: float, cfg: ActionConfig) -> StuckState:
    """The stuck state after the robot is observed at ``(x_m, y_m)``: leaving the anchor disc resets the count."""
    if state.anchor_xy_m is None or math.hypot(x_m - state.anchor_xy_m[0], y_m - state.anchor_xy_m[1]) > cfg.stuck_move_tol_m:
        return StuckState((float(x_m), float(y_m)), 0)
    return StuckState(state.anchor_xy_m, state.steps_still + 1)


def is_stuck(state: StuckState, cfg: ActionConfig) -> bool:
    """Whether the robot has not moved for ``stuck_steps`` steps (the caller should pick another target and reset)."""
    return state.steps_still >= cfg.stuck_steps
