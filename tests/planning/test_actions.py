"""Path following to discrete actions, the local collision check, the stuck rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.config import RobotConfig
from dynactivegs.errors import ConfigError
from dynactivegs.planning.actions import (
    ActionConfig, StuckState, forward_blocked, is_stuck, next_action, side_clearance, update_stuck,
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
    s = update_stuck(s, 1.25, 1.0, cfg)                             # a real step forward
    assert not is_stuck(s, cfg) and s.steps_still == 0


def test_config_validation():
    with pytest.raises(ConfigError):
        ActionConfig(reach_tol_m=0.1)                                # would overshoot back and forth
    with pytest.raises(ConfigError):
        ActionConfig(stuck_steps=0)


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
