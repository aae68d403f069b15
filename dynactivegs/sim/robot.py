"""The ground robot: discrete actions (Habitat-style) and the camera it carries."""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

from dynactivegs.sim.config import RobotConfig
from dynactivegs.records import RobotPose2D


class Action(IntEnum):
    """The robot's discrete actions; step sizes come from :class:`RobotConfig`."""

    FORWARD = 0
    TURN_LEFT = 1
    TURN_RIGHT = 2
    STOP = 3


def wrap_angle(a_rad: float) -> float:
    """Angle in [-pi, pi)."""
    return (a_rad + math.pi) % (2 * math.pi) - math.pi


def apply_action(pose: RobotPose2D, action: Action, cfg: RobotConfig) -> RobotPose2D:
    """The pose the action aims for (collision is checked by the simulator)."""
    if action == Action.FORWARD:
        return RobotPose2D(pose.x_m + cfg.forward_step_m * math.cos(pose.yaw_rad),
                           pose.y_m + cfg.forward_step_m * math.sin(pose.yaw_rad), pose.yaw_rad)
    if action == Action.TURN_LEFT:
        return RobotPose2D(pose.x_m, pose.y_m, wrap_angle(pose.yaw_rad + math.radians(cfg.turn_step_deg)))
    if action == Action.TURN_RIGHT:
        return RobotPose2D(pose.x_m, pose.y_m, wrap_angle(pose.yaw_rad - math.radians(cfg.turn_step_deg)))
    return pose


def camera_pose(x_m: float, y_m: float, yaw_rad: float, height_m: float) -> np.ndarray:
    """float64 (4, 4) ``T_world_cam`` of a level camera at ``height_m`` looking along ``yaw_rad``.

    OpenCV camera axes: z forward = (cos yaw, sin yaw, 0), x right = (sin yaw, -cos yaw, 0),
    y down = (0, 0, -1).
    """
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    T = np.eye(4)
    T[:3, 0] = (s, -c, 0.0)
    T[:3, 1] = (0.0, 0.0, -1.0)
    T[:3, 2] = (c, s, 0.0)
    T[:3, 3] = (x_m, y_m, height_m)
    return T
