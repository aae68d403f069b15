"""Path following to discrete actions, the local collision check, the stuck rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.config import RobotConfig
from dynactivegs.errors import ConfigError
from dynactivegs.planning.actions import (
    ActionConfig, StuckState, clear_headings, forward_blocked, is_stuck, next_action, side_clearance, steer_clear,
    update_stuck,
)
from dynactivegs.records import RobotPose2D
from dynactivegs.sim.robot import Action, apply_action, wrap_angle

from tests.selection.scenes import intrinsics, render_depth, view

CFG = ActionConfig()


def act(x, y, yaw_deg, wps, target_deg=None):
    return next_action(RobotPose2D(x, y, math.radians(yaw_deg)), np.array(wps, float),
                       None if target_deg is None else math.radians(target_deg), CFG)


def test_turns_toward_the_waypoint_and_goes_forward_when_aligned():
    assert act(0, 0, 0, [[2, 0]]).action == Action.FORWARD
    assert act(0, 0, 0, [[0, 2]]).action == Action.TURN_LEFT
    assert act(0, 0, 0, [[0, -2]]).action == Action.TURN_RIGHT
    assert act(0, 0, 0, [[-2, 0.01]]).action == Action.TURN_LEFT      # behind: the shorter way
    assert act(0, 0, 14.9, [[2, 0]]).action == Action.FORWARD          # within forward_tol_deg (15)
    assert act(0, 0, 15.2, [[2, 0]]).action == Action.TURN_RIGHT
    assert act(0, 0, 175, [[-2, -0.5]]).action == Action.TURN_LEFT     # across the +-180 deg seam


def test_a_turn_in_progress_is_kept_for_a_bearing_far_behind():
    # 150 deg to the right, but the robot has just been turning left: it keeps turning left
    assert act(0, 0, 0, [[-2, -1.15]]).action == Action.TURN_RIGHT
    cfg = ActionConfig()
    pose = RobotPose2D(0.0, 0.0, 0.0)
    assert next_action(pose, np.array([[-2, -1.15]]), None, cfg, Action.TURN_LEFT).action == Action.TURN_LEFT
    # 90 deg the other way is within turn_commit_deg: the shorter way wins
    assert next_action(pose, np.array([[0, -2]]), None, cfg, Action.TURN_LEFT).action == Action.TURN_RIGHT


def test_reached_waypoints_are_skipped_and_the_final_yaw_is_turned_to():
    step = act(0, 0, 0, [[0.1, 0.0], [1.0, 1.0]])
    assert step.next_waypoint == 1 and step.action == Action.TURN_LEFT
    assert act(0, 0, 0, [[0.05, 0.0]], 90).action == Action.TURN_LEFT
    assert act(0, 0, 170, [[0.05, 0.0]], -170).action == Action.TURN_LEFT
    assert act(0, 0, 88, [[0.05, 0.0]], 90).action == Action.STOP
    assert act(0, 0, 0, [[0.05, 0.0]]).action == Action.STOP
    assert act(0, 0, 0, np.zeros((0, 2)), None).action == Action.STOP


def test_following_an_l_shaped_path_with_the_simulator_actions_arrives_facing_the_target():
    robot = RobotConfig()
    cfg = ActionConfig.for_robot(robot)
    wps = np.array([[0.5, 0.0], [1.5, 0.1], [2.5, 0.0], [2.5, 1.0], [2.6, 2.0]])
    pose = RobotPose2D(0.0, 0.0, math.radians(-120))
    k, actions = 0, []
    for _ in range(200):
        step = next_action(pose, wps[k:], math.radians(45), cfg)
        k += step.next_waypoint
        actions.append(step.action)
        if step.action == Action.STOP:
            break
        pose = apply_action(pose, step.action, robot)
    assert actions[-1] == Action.STOP and len(actions) < 60
    assert math.hypot(pose.x_m - 2.6, pose.y_m - 2.0) <= cfg.target_tol_m
    assert abs(wrap_angle(pose.yaw_rad - math.radians(45))) <= math.radians(5) + 1e-9
    # no dithering: never a left turn right after a right turn or vice versa
    pairs = set(zip(actions[:-1], actions[1:]))
    assert (Action.TURN_LEFT, Action.TURN_RIGHT) not in pairs and (Action.TURN_RIGHT, Action.TURN_LEFT) not in pairs


W, H = 64, 36
K = intrinsics(W, H)


def blocked(x, y, yaw, boxes=()):
    T = view(x, y, yaw)
    depth, _ = render_depth(T, K, W, H, (4.0, 3.0), list(boxes))
    return forward_blocked(depth, K, T, CFG)


def test_forward_is_blocked_by_a_near_wall_or_person_ahead_only():
    assert blocked(3.7, 1.5, 0.0)                                    # wall 0.3 m ahead
    assert not blocked(3.0, 1.5, 0.0)                                # wall 1 m ahead
    assert not blocked(3.7, 1.5, math.pi)                            # turned away from it
    person = (2.3, 1.35, 2.6, 1.65, 1.75)
    assert blocked(2.0, 1.5, 0.0, [person])                          # person 0.3 m ahead
    assert not blocked(2.0, 0.8, 0.0, [person])                      # 0.7 m to the side
    assert not blocked(1.0, 1.5, 0.0, [person])                      # 1.3 m ahead
    T = view(3.7, 1.5, 0.0)
    assert not forward_blocked(np.zeros((H, W), np.float32), K, T, CFG)   # no returns, nothing known to block


def test_side_clearance_is_the_nearest_return_on_each_side():
    T = view(2.0, 1.5, 0.0)                                          # facing +x, the room's far wall 2 m ahead
    person = (2.2, 1.9, 2.5, 2.2, 1.75)                              # ahead on the left, its near corner 0.45 m away
    depth, _ = render_depth(T, K, W, H, (4.0, 3.0), [person])
    left, right = side_clearance(depth, K, T, CFG, reach_m=1.0)
    assert 0.4 < left < 0.6 and right == math.inf                    # the walls 1.5 m to the sides are out of reach
    left, right = side_clearance(depth, K, T, CFG, reach_m=3.0)
    assert 0.4 < left < 0.6 and 1.4 < right < 2.2                    # the right wall's visible part, or the far wall
    assert side_clearance(np.zeros((H, W), np.float32), K, T, CFG, 1.0) == (math.inf, math.inf)


def test_stuck_after_k_steps_without_moving_reset_by_motion():
    cfg = ActionConfig(stuck_steps=5)
    s = StuckState()
    for _ in range(5):
        s = update_stuck(s, 1.0, 1.0, cfg)
        assert not is_stuck(s, cfg)
    s = update_stuck(s, 1.02, 1.0, cfg)                             # jitter inside the tolerance
    assert is_stuck(s, cfg)
    s = update_stuck(s, 1.25, 1.0, cfg)                             # one step aside and back is no progress
    s = update_stuck(s, 1.0, 1.0, cfg)
    assert is_stuck(s, cfg)
    s = update_stuck(s, 1.5, 1.0, cfg)                              # two steps forward are
    assert not is_stuck(s, cfg) and s.steps_still == 0


def test_config_validation():
    with pytest.raises(ConfigError):
        ActionConfig(reach_tol_m=0.1)                                # would overshoot back and forth
    with pytest.raises(ConfigError):
        ActionConfig(stuck_steps=0)
    with pytest.raises(ConfigError, match="actions.steer_search_deg"):
        ActionConfig(steer_search_deg=-1.0)
    with pytest.raises(ConfigError, match="actions.clear_margin_m"):
        ActionConfig(clear_margin_m=0.6)


def test_a_robot_between_two_nodes_does_not_turn_back_to_the_one_behind_it():
    # robot at x=0.6 on the segment (0,0) -> (1,0), facing +x: the node behind is passed
    assert act(0.6, 0.05, 0, [[0, 0], [1, 0], [2, 0]]).action == Action.FORWARD


def test_small_zig_zags_of_the_skeleton_are_cut_straight():
    # waypoints wiggle by 0.1 m (< robot radius) around the x axis: head straight along it
    wiggle = [[0.5, 0.1], [1.0, -0.1], [1.5, 0.1], [2.0, 0.0]]
    assert act(0, 0, 0, wiggle).action == Action.FORWARD
    # a real corner (1 m off the chord) is not cut: the robot first aims at the corner
    corner = [[1.0, 0.0], [1.0, 1.0]]
    assert act(0, 0, 0, corner).action == Action.FORWARD
    assert act(0, 0, 30, corner).action == Action.TURN_RIGHT


def test_a_target_within_target_tol_is_turned_to_on_the_spot():
    # the target position 0.2 m behind the robot, its heading 20 deg to the right: turn right, do not drive back
    assert act(0, 0, 0, [[-0.2, 0.01]], -20).action == Action.TURN_RIGHT
    assert act(0, 0, -18, [[-0.2, 0.01]], -20).action == Action.STOP
    assert next_action(RobotPose2D(0.0, 0.0, 0.0), np.array([[-0.2, 0.01]]), math.radians(-20),
                       ActionConfig(target_tol_m=CFG.reach_tol_m)).action == Action.TURN_LEFT   # drives to it
    with pytest.raises(ConfigError, match="target_tol_m"):
        ActionConfig(target_tol_m=0.1)


def _window(lo_xy, n, cell, wall):
    """A clearance window of n x n cells from lower-left ``lo_xy``: exact distance to the set ``wall(x, y)``."""
    from scipy import ndimage
    xs = lo_xy[0] + (np.arange(4 * n) - 1.5 * n + 0.5) * cell         # a larger patch, cut down to the window
    ys = lo_xy[1] + (np.arange(4 * n) - 1.5 * n + 0.5) * cell
    X, Y = np.meshgrid(xs, ys)
    d = ndimage.distance_transform_edt(~wall(X, Y)) * cell - 0.5 * cell
    i0 = int(1.5 * n)
    return d[i0:i0 + n, i0:i0 + n].astype(np.float32), np.array(lo_xy, float)


def test_a_step_that_drifts_into_a_wall_beside_the_robot_is_not_clear():
    # a wall along y = 0.4 (cells above it occupied); the robot at y = 0.175, 0.225 m from it (0.045 m slack)
    clear, origin = _window((-0.6, -0.6), 24, 0.05, lambda x, y: y >= 0.4)
    pose = RobotPose2D(0.0, 0.175, 0.0)
    yaws = np.radians([-10.0, 0.0, 11.0, 30.0, 90.0])
    ok = clear_headings(clear, origin, 0.05, pose, yaws, CFG)
    assert ok.tolist() == [True, True, False, False, False]
    # with no window every step counts as clear
    assert clear_headings(np.zeros((0, 0), np.float32), origin, 0.05, pose, yaws, CFG).all()
    # a robot already nearer than radius + margin may move along the wall or away, not closer
    near = RobotPose2D(0.0, 0.21, 0.0)
    assert clear_headings(clear, origin, 0.05, near, np.radians([0.0, -45.0, 20.0]), CFG).tolist() == [True, True, False]
    # a post 0.175 m behind the robot: stepping away from it is fine, but not on toward the wall
    post, origin = _window((-0.6, -0.6), 24, 0.05, lambda x, y: (y >= 0.4) | ((x <= -0.17) & (np.abs(y - 0.175) < 0.1)))
    at = RobotPose2D(0.025, 0.175, 0.0)
    assert post[15, 12] == pytest.approx(0.175)                # the robot's cell
    assert clear_headings(post, origin, 0.05, at, np.radians([0.0, 11.0]), CFG).tolist() == [True, False]


def test_steering_clear_picks_the_nearest_heading_toward_the_waypoint_whose_step_keeps_clear():
    clear, origin = _window((-0.6, -0.6), 24, 0.05, lambda x, y: y >= 0.4)
    # the waypoint lies 7 deg toward the wall: at 11 deg the step is within forward_tol_deg but grazes
    pose = RobotPose2D(0.0, 0.175, math.radians(11.0))
    ps = next_action(pose, np.array([[3.0, 0.175 + 3.0 * math.tan(math.radians(7.0))]]), None, CFG)
    assert ps.action == Action.FORWARD and ps.aim_rad == pytest.approx(math.radians(7.0))
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG) == Action.TURN_RIGHT      # to 1 deg, 6 deg off
    after = RobotPose2D(0.0, 0.175, math.radians(1.0))
    ps = next_action(after, np.array([[3.0, 0.175 + 3.0 * math.tan(math.radians(7.0))]]), None, CFG)
    assert steer_clear(after, ps, clear, origin, 0.05, CFG) == Action.FORWARD
    # a waypoint round a corner: no heading within forward_tol_deg is clear, the nearest clear one is taken
    pose = RobotPose2D(0.0, 0.175, 0.0)
    ps = next_action(pose, np.array([[0.3, 1.0]]), None, CFG)                        # bearing 70 deg
    assert ps.action == Action.TURN_LEFT
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG) == Action.TURN_LEFT        # beyond the 45 deg search
    pose = RobotPose2D(0.0, 0.175, math.radians(40.0))
    ps = next_action(pose, np.array([[1.0, 0.175 + math.tan(math.radians(40.0))]]), None, CFG)
    assert ps.action == Action.FORWARD
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG) == Action.TURN_RIGHT       # toward the 0 deg step
    # steer_search_deg = 0 turns it off; the final turn to the target's heading is never steered
    off = ActionConfig(steer_search_deg=0.0)
    assert steer_clear(pose, next_action(pose, np.array([[1.0, 0.175 + math.tan(math.radians(40.0))]]), None, off),
                       clear, origin, 0.05, off) == Action.FORWARD
    at = next_action(pose, np.array([[0.0, 0.175]]), math.radians(40.0), CFG)
    assert at.aim_rad is None and steer_clear(pose, at, clear, origin, 0.05, CFG) == at.action == Action.STOP


def test_with_nothing_near_steering_clear_changes_no_action():
    rng = np.random.default_rng(5)
    clear = np.full((24, 24), 0.6, np.float32)
    for _ in range(300):
        x, y, yaw = rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(-math.pi, math.pi)
        pose = RobotPose2D(x, y, yaw)
        wps = rng.uniform(-3, 3, (int(rng.integers(1, 4)), 2))
        ps = next_action(pose, wps, float(rng.uniform(-math.pi, math.pi)), CFG)
        assert steer_clear(pose, ps, clear, np.array([-0.6, -0.6]), 0.05, CFG) == ps.action


def _window_at(pose, wall):
    """The 25 x 25 window of a world-aligned 5 cm grid around the robot's cell, as the selection cuts it."""
    c = np.floor(np.array([pose.x_m, pose.y_m]) / 0.05)
    return _window((c - 12) * 0.05, 25, 0.05, wall)


def test_steering_clear_takes_a_robot_through_a_narrow_passage_without_a_bump():
    # a passage 0.45 m wide (0.045 m slack each side), the robot near its left wall, the waypoint at its far end:
    # next_action alone goes forward at up to 15 deg off and grazes the wall; steering keeps it clear, and it
    # does not zig-zag (at most the one turn it starts with)
    wall = lambda x, y: (y >= 0.45) | (y <= 0.0)                                   # noqa: E731
    cfg = RobotConfig()
    for use_window in (False, True):
        pose, bumps, turns = RobotPose2D(0.0, 0.245, math.radians(10.0)), 0, 0
        for _ in range(12):
            clear, origin = _window_at(pose, wall)
            ps = next_action(pose, np.array([[3.5, 0.26]]), None, CFG)
            a = steer_clear(pose, ps, clear, origin, 0.05, CFG) if use_window else ps.action
            turns += a != Action.FORWARD
            new = apply_action(pose, a, cfg)
            if a == Action.FORWARD and not (cfg.radius_m <= new.y_m <= 0.45 - cfg.radius_m):
                bumps += 1                                         # the disc would leave the passage: it stays
            else:
                pose = new
        assert (bumps > 0) != use_window, (use_window, bumps, pose)
        assert use_window is False or (turns == 1 and pose.x_m > 2.5)


def test_a_squeezed_robot_turns_for_a_step_that_keeps_a_centimetre_farther_from_the_wall():
    wall = lambda x, y: y <= 0.0                                                   # noqa: E731
    for yaw_deg, want in ((-2.0, Action.TURN_LEFT), (-1.0, Action.FORWARD)):
        pose = RobotPose2D(0.025, 0.16, math.radians(yaw_deg))                   # 0.16 m from the wall: squeezed
        clear, origin = _window_at(pose, wall)
        ps = next_action(pose, np.array([[3.0, 0.16 - 3.0 * math.tan(math.radians(3.0))]]), None, CFG)
        assert ps.action == Action.FORWARD                                         # 1-2 deg off the bearing
        # -2 deg drifts 0.9 cm closer (within the map's noise, so clear); 8 deg keeps 1.2 cm farther: worth a turn.
        # -1 deg drifts 0.4 cm closer; 9 deg keeps 0.8 cm farther: not worth one.
        assert steer_clear(pose, ps, clear, origin, 0.05, CFG) == want


def test_a_robot_with_no_clear_heading_out_of_a_pocket_takes_the_one_its_body_fits_with_steer_tight():
    # a box up-left (corner 0.28 m behind, 0.08 m to the left of the robot) and a wall 0.35 m to its right: the
    # way out lies between them, toward a waypoint 15 deg right of straight back. No heading keeps clear_margin_m.
    box = lambda x, y: (x <= -0.28) & (y >= 0.08)                                   # noqa: E731
    wall = lambda x, y: box(x, y) | (y <= -0.35)                                     # noqa: E731

    def room(p):                    # the true distance from the robot's centre to the box and the wall
        dx, dy = max(p.x_m - -0.28, 0.0), max(0.08 - p.y_m, 0.0)
        return min(math.hypot(dx, dy), p.y_m + 0.35)

    cfg = RobotConfig()
    tight = ActionConfig(steer_tight=True)
    outcome = {}
    for acfg in (ActionConfig(steer_tight=False), tight):
        pose, actions = RobotPose2D(0.025, 0.025, math.radians(-170.0)), []
        for _ in range(4):
            clear, origin = _window_at(pose, wall)
            assert not clear_headings(clear, origin, 0.05, pose, pose.yaw_rad + np.radians(np.arange(-4, 5) * 10.0),
                                      acfg).any() or actions
            ps = next_action(pose, np.array([[-1.0, -0.25]]), None, acfg)
            a = steer_clear(pose, ps, clear, origin, 0.05, acfg)
            actions.append(a)
            pose = apply_action(pose, a, cfg)
            if a == Action.FORWARD:
                break
        outcome[acfg.steer_tight] = (actions, room(pose))
    # by the path alone it steps at -170 deg and its body would overlap the box's corner
    assert outcome[False][0] == [Action.FORWARD] and outcome[False][1] < cfg.radius_m
    # steer_tight turns twice to -150 deg, where the step keeps the body off both
    assert outcome[True][0] == [Action.TURN_LEFT, Action.TURN_LEFT, Action.FORWARD]
    assert outcome[True][1] >= cfg.radius_m
    # where no heading leaves room for the body, the action stays
    narrow = lambda x, y: box(x, y) | (y <= -0.25)                                   # noqa: E731
    pose = RobotPose2D(0.025, 0.025, math.radians(-170.0))
    clear, origin = _window_at(pose, narrow)
    ps = next_action(pose, np.array([[-1.0, -0.25]]), None, tight)
    assert steer_clear(pose, ps, clear, origin, 0.05, tight) == ps.action == Action.FORWARD


def test_a_heading_blocked_from_here_is_not_taken_with_steer_skip_blocked():
    # the wall along y = 0.4 and a waypoint 7 deg toward it: at 1 deg the step keeps clear and is within
    # forward_tol_deg, so the map alone steps forward there
    clear, origin = _window((-0.6, -0.6), 24, 0.05, lambda x, y: y >= 0.4)
    pose = RobotPose2D(0.0, 0.175, math.radians(1.0))
    ps = next_action(pose, np.array([[3.0, 0.175 + 3.0 * math.tan(math.radians(7.0))]]), None, CFG)
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG) == Action.FORWARD
    # the camera saw that step blocked: 11 deg grazes the wall, so it turns to -9 deg, the next clear heading
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG, [math.radians(1.0)]) == Action.TURN_RIGHT
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG, [math.radians(1.0), math.radians(-9.0)]) == Action.TURN_RIGHT
    # a heading only near one blocked (more than half a turn step off) stays a candidate
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG, [math.radians(7.0)]) == Action.FORWARD
    # with every heading that keeps clear barred, steer_tight takes none of the barred ones either
    every = list(pose.yaw_rad + np.radians(np.arange(-6, 6) * 10.0))
    assert steer_clear(pose, ps, clear, origin, 0.05, CFG, every) == ps.action == Action.FORWARD
