"""The simulator: a static scene, walking people and an RGB-D robot, stepped by discrete actions.

One :meth:`Simulator.step` is one robot action: the robot moves (unless a wall, furniture or
a person is in the way), the crowd walks for ``dt_s`` seconds (avoiding the robot), and the
camera renders a :class:`Frame` (what stages see) and a :class:`SimTruth` (ground truth
for evaluation: people mask, people and robot poses).

Everything random derives from ``(seed, name)`` streams: the same config and seed give
bit-identical frames and tracks.
"""

from __future__ import annotations

import math

import numpy as np

from dynactivegs.sim.config import SimConfig
from dynactivegs.records import Frame, RobotPose2D, SimTruth
from dynactivegs.rng import derive_rng
from dynactivegs.sim.crowd import Crowd
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.render import PeopleMesh, RenderResult, intrinsics
from dynactivegs.sim.robot import Action, apply_action, camera_pose
from dynactivegs.sim.scenes import load_scene, scene_freespace, scene_renderer

NS_PER_S = 1_000_000_000


class Simulator:
    """A scene with people and one robot. Not thread-safe; one instance per run."""

    def __init__(self, cfg: SimConfig, seed: int) -> None:
        self.cfg = cfg
        self.seed = seed
        self.scene = load_scene(cfg)
        self.renderer = scene_renderer(self.scene)
        self.freespace: FreeSpace = scene_freespace(self.scene, self.renderer, cfg.grid_res_m,
                                                    cfg.robot.body_height_m)
        cam = cfg.camera
        self.K = intrinsics(cam.width_px, cam.height_px, cam.fx, cam.fy)
        self.robot = self._spawn_robot(derive_rng(seed, "robot-spawn"))
        self.crowd = Crowd(cfg.crowd, self.freespace, derive_rng(seed, "crowd"),
                           np.array([self.robot.x_m, self.robot.y_m]), cfg.robot.radius_m)
        self.step_index = 0
        self.collided = False
        self._frame, self._truth = self._observe()

    # ------------------------------------------------------------------ public API
    @property
    def stamp_ns(self) -> int:
        return self.step_index * int(round(self.cfg.dt_s * NS_PER_S))

    def observation(self) -> tuple[Frame, SimTruth]:
        """The current frame and ground truth (step 0 right after construction)."""
        return self._frame, self._truth

    def step(self, action: Action | int) -> tuple[Frame, SimTruth]:
        """Apply one action, advance the crowd by ``dt_s`` and render the new observation."""
        action = Action(int(action))
        rcfg = self.cfg.robot
        target = apply_action(self.robot, action, rcfg)
        start = np.array([self.robot.x_m, self.robot.y_m])
        end = np.array([target.x_m, target.y_m])
        self.collided = False
        if action == Action.FORWARD:
            blocked = (not self.freespace.segment_navigable(start, end, rcfg.radius_m)
                       or self.crowd.overlaps_disc(end, rcfg.radius_m))
            if blocked:
                self.collided = True
                target = self.robot
        self.robot = target
        xy = np.array([self.robot.x_m, self.robot.y_m])
        self.crowd.step(self.cfg.dt_s, xy, (xy - start) / self.cfg.dt_s, rcfg.radius_m)
        self.step_index += 1
        self._frame, self._truth = self._observe()
        return self._frame, self._truth

    def camera_pose(self, pose: RobotPose2D | None = None) -> np.ndarray:
        """``T_world_cam`` (4, 4) of the robot's camera at ``pose`` (default: the current pose)."""
        p = self.robot if pose is None else pose
        return camera_pose(p.x_m, p.y_m, p.yaw_rad, self.cfg.camera.height_m)

    def render_static(self, T_world_cam: np.ndarray, *, width: int | None = None,
                      height: int | None = None) -> RenderResult:
        """Render the scene without people from any pose: the ground truth for novel views.

        ``width``/``height`` default to the camera's; the field of view stays the camera's.
        """
        cam = self.cfg.camera
        w = cam.width_px if width is None else width
        h = cam.height_px if height is None else height
        K = intrinsics(w, h, cam.fx * w / cam.width_px, cam.fy * h / cam.height_px)
        return self.renderer.render(T_world_cam, K, w, h, min_depth_m=cam.min_depth_m, max_depth_m=cam.max_depth_m)

    def surface_samples(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """float64 (n, 3): points uniform on the static mesh (never on people): ground truth for geometry."""
        return self.scene.sample_surface(n, rng)[0]

    def people_mesh(self) -> PeopleMesh:
        v, f, c = self.crowd.mesh()
        n = len(self.crowd)
        per_person = len(v) // max(n, 1)
        assert per_person * n == len(v), "every person has the same template vertex count"
        return PeopleMesh(v, f, c, np.arange(n + 1, dtype=np.int64) * per_person)

    # ------------------------------------------------------------------ internals
    def _spawn_robot(self, rng: np.random.Generator) -> RobotPose2D:
        r = self.cfg.robot.radius_m
        nav = self.freespace.navigable(r)
        roomy = nav & (self.freespace.clearance_m >= max(0.5, r))
        cells = np.argwhere(roomy if roomy.any() else nav)
        if len(cells) == 0:
            from dynactivegs.errors import SceneError

            raise SceneError(f"scene {self.scene.name}: no free floor for a robot of radius {r} m; "
                             "check the floor height (sim.mesh_floor_z_m) and units (sim.mesh_scale)")
        xy = self.freespace.cell_to_world(cells[rng.integers(len(cells))])
        return RobotPose2D(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))

    def _observe(self) -> tuple[Frame, SimTruth]:
        cam = self.cfg.camera
        T = self.camera_pose()
        out = self.renderer.render(T, self.K, cam.width_px, cam.height_px, people=self.people_mesh(),
                                   min_depth_m=cam.min_depth_m, max_depth_m=cam.max_depth_m)
        depth = out.depth_m
        if cam.depth_noise_std_m > 0:
            rng = derive_rng(self.seed, "depth-noise", self.step_index)
            noisy = depth + (cam.depth_noise_std_m * depth.astype(np.float64) ** 2
                             * rng.standard_normal(depth.shape)).astype(np.float32)
            valid = (depth > 0) & (noisy >= cam.min_depth_m) & (noisy <= cam.max_depth_m)
            depth = np.where(valid, noisy, np.float32(0.0)).astype(np.float32)
        stamp = self.stamp_ns
        frame = Frame(step=self.step_index, stamp_ns=stamp, rgb=out.rgb, depth_m=depth, K=self.K.copy(),
                      T_world_cam=T)
        truth = SimTruth(step=self.step_index, stamp_ns=stamp, people_mask=out.people_mask, robot=self.robot,
                         people_xy_m=self.crowd.positions_xy_m.copy(),
                         people_heading_rad=self.crowd.headings_rad.copy(),
                         people_height_m=self.crowd.heights_m.copy(), collided=self.collided)
        return frame, truth
