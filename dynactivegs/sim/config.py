"""Configuration of the embedded simulator: camera, robot body, crowd, scene and clock.

A leaf module (it imports nothing else of the package but errors), so that every part of the
package can import it; :mod:`dynactivegs.config` re-exports these classes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from dynactivegs.errors import check_config


@dataclass(frozen=True, slots=True)
class CameraConfig:
    """The robot's RGB-D camera."""

    width_px: int = 160
    """Image width in pixels."""
    height_px: int = 92
    """Image height in pixels."""
    hfov_deg: float = 90.0
    """Horizontal field of view in degrees (the paper: 90)."""
    vfov_deg: float = 60.0
    """Vertical field of view in degrees (the paper: 60)."""
    height_m: float = 1.25
    """Height of the optical centre above the floor in metres."""
    min_depth_m: float = 0.1
    """Returns nearer than this are reported as 0 (no return)."""
    max_depth_m: float = 10.0
    """Returns farther than this are reported as 0 (no return)."""
    depth_noise_std_m: float = 0.0
    """Standard deviation of additive depth noise, scaled by depth^2 / 1 m (Kinect-like); 0 turns it off."""

    def __post_init__(self) -> None:
        check_config(8 <= self.width_px <= 4096, "camera.width_px", self.width_px, "in [8, 4096]")
        check_config(8 <= self.height_px <= 4096, "camera.height_px", self.height_px, "in [8, 4096]")
        check_config(1.0 < self.hfov_deg < 179.0, "camera.hfov_deg", self.hfov_deg, "in (1, 179)")
        check_config(1.0 < self.vfov_deg < 179.0, "camera.vfov_deg", self.vfov_deg, "in (1, 179)")
        check_config(0.2 <= self.height_m <= 2.2, "camera.height_m", self.height_m, "in [0.2, 2.2] m")
        check_config(0.0 < self.min_depth_m < self.max_depth_m, "camera.min_depth_m", self.min_depth_m,
                 "positive and below camera.max_depth_m")
        check_config(self.depth_noise_std_m >= 0.0, "camera.depth_noise_std_m", self.depth_noise_std_m, ">= 0")

    @property
    def fx(self) -> float:
        return 0.5 * self.width_px / math.tan(math.radians(self.hfov_deg) / 2)

    @property
    def fy(self) -> float:
        return 0.5 * self.height_px / math.tan(math.radians(self.vfov_deg) / 2)


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """The ground robot's body and discrete action set (Habitat-style)."""

    forward_step_m: float = 0.25
    """Distance of one forward action in metres."""
    turn_step_deg: float = 10.0
    """Angle of one turn action in degrees."""
    radius_m: float = 0.18
    """Collision radius of the robot's body in metres."""
    body_height_m: float = 1.5
    """Anything between 0.1 m above the floor and this height is an obstacle for the robot."""

    def __post_init__(self) -> None:
        check_config(0.01 <= self.forward_step_m <= 2.0, "robot.forward_step_m", self.forward_step_m, "in [0.01, 2] m")
        check_config(0.5 <= self.turn_step_deg <= 90.0, "robot.turn_step_deg", self.turn_step_deg, "in [0.5, 90] deg")
        check_config(0.05 <= self.radius_m <= 1.0, "robot.radius_m", self.radius_m, "in [0.05, 1] m")
        check_config(0.3 <= self.body_height_m <= 2.5, "robot.body_height_m", self.body_height_m, "in [0.3, 2.5] m")


@dataclass(frozen=True, slots=True)
class CrowdConfig:
    """Walking people and their ORCA collision avoidance."""

    count: int = -1
    """Number of people; -1 means max(1, floor(free floor area / area_per_person_m2))."""
    area_per_person_m2: float = 8.0
    """Floor area per person when count is -1 (the paper: 8 m^2)."""
    speed_mps: float = 0.5
    """Nominal walking speed; each person's is this times U(0.8, 1.2)."""
    radius_m: float = 0.3
    """Collision radius of a person in metres."""
    min_goal_dist_m: float = 3.0
    """A new goal is at least this far (straight line) from the person."""
    neighbor_dist_m: float = 5.0
    """ORCA: other agents farther than this are ignored."""
    time_horizon_s: float = 2.0
    """ORCA: time horizon for other agents."""
    obstacle_time_horizon_s: float = 2.0
    """ORCA: time horizon for static obstacles."""
    substep_s: float = 0.1
    """Crowd integration step; a simulator step is split into substeps of at most this length."""
    stuck_timeout_s: float = 3.0
    """A person whose remaining path stops shrinking (see ``stuck_speed_frac``) for this long picks a new goal
    (breaks door jams)."""
    stuck_speed_frac: float = 0.25
    """Progress counts only at this fraction of the person's own speed or more: the remaining path must shrink
    by ``stuck_speed_frac * speed * stuck_timeout_s`` within ``stuck_timeout_s``, else the person picks a new goal
    (someone inching into a jam at a few cm/s gives up like someone standing still)."""

    def __post_init__(self) -> None:
        check_config(self.count >= -1, "crowd.count", self.count, ">= 0, or -1 for the area rule")
        check_config(self.area_per_person_m2 > 0, "crowd.area_per_person_m2", self.area_per_person_m2, "> 0")
        check_config(0.0 < self.speed_mps <= 3.0, "crowd.speed_mps", self.speed_mps, "in (0, 3] m/s")
        check_config(0.1 <= self.radius_m <= 0.6, "crowd.radius_m", self.radius_m, "in [0.1, 0.6] m")
        check_config(self.min_goal_dist_m >= 0, "crowd.min_goal_dist_m", self.min_goal_dist_m, ">= 0")
        check_config(self.neighbor_dist_m > 0, "crowd.neighbor_dist_m", self.neighbor_dist_m, "> 0")
        check_config(self.time_horizon_s > 0, "crowd.time_horizon_s", self.time_horizon_s, "> 0")
        check_config(self.obstacle_time_horizon_s > 0, "crowd.obstacle_time_horizon_s",
                 self.obstacle_time_horizon_s, "> 0")
        check_config(0.0 < self.substep_s <= 1.0, "crowd.substep_s", self.substep_s, "in (0, 1] s")
        check_config(self.stuck_timeout_s > 0, "crowd.stuck_timeout_s", self.stuck_timeout_s, "> 0")
        check_config(0.0 <= self.stuck_speed_frac < 1.0, "crowd.stuck_speed_frac", self.stuck_speed_frac, "in [0, 1)")


@dataclass(frozen=True, slots=True)
class SimConfig:
    """The embedded simulator: scene, camera, robot, people, clock."""

    scene: str = "apartment-00"
    """A procedural scene name (tiny-NN, apartment-NN, house-NN, loop-NN) or a mesh file (.glb/.gltf/.ply/.obj)."""
    mesh_up_axis: str = "auto"
    """Up axis of a mesh file: auto (Y for .glb/.gltf, Z otherwise), or one of x, y, z, -x, -y, -z."""
    mesh_floor_z_m: float = math.nan
    """Floor height of a mesh file after up-axis conversion; NaN infers it from upward-facing area."""
    mesh_scale: float = 1.0
    """Multiplier applied to a mesh file's coordinates (0.001 for a file in millimetres)."""
    grid_res_m: float = 0.05
    """Cell size of the free-space grid in metres."""
    dt_s: float = 0.5
    """Simulated time per robot action in seconds."""
    camera: CameraConfig = field(default_factory=CameraConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    crowd: CrowdConfig = field(default_factory=CrowdConfig)

    def __post_init__(self) -> None:
        check_config(bool(self.scene), "sim.scene", self.scene, "a scene name or a mesh path")
        check_config(self.mesh_up_axis in ("auto", "x", "y", "z", "-x", "-y", "-z"), "sim.mesh_up_axis",
                 self.mesh_up_axis, "one of auto, x, y, z, -x, -y, -z")
        check_config(0.0 < self.mesh_scale < 1e6, "sim.mesh_scale", self.mesh_scale, "positive")
        check_config(0.01 <= self.grid_res_m <= 0.5, "sim.grid_res_m", self.grid_res_m, "in [0.01, 0.5] m")
        check_config(0.01 <= self.dt_s <= 10.0, "sim.dt_s", self.dt_s, "in [0.01, 10] s")
