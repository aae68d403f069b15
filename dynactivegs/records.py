"""Typed records passed between the simulator and the pipeline stages.

Conventions, used everywhere in the package:

- World frame: Z up, metres. The floor of a scene is at ``z = 0``.
- Camera frame: OpenCV (x right, y down, z forward).
- ``T_a_b`` is a 4x4 homogeneous transform mapping points in frame ``b`` to frame ``a``;
  ``T_world_cam`` maps camera points to world points.
- Pixels: ``K`` maps camera points to continuous image coordinates in which pixel
  ``(row v, col u)`` covers ``[u, u+1) x [v, v+1)`` and has its centre at
  ``(u + 0.5, v + 0.5)``. This is the convention of 3DGS rasterizers (gsplat).
- Depth is z-depth along the optical axis in metres; 0 means "no return".
- Times are integer nanoseconds (``stamp_ns``), the same value that is used as the MCAP
  log time.

Records are frozen dataclasses; their array fields are made read-only on construction so
that a stage cannot change what an earlier stage produced.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np


def _freeze_arrays(record: object) -> None:
    for f in fields(record):  # type: ignore[arg-type]
        value = getattr(record, f.name)
        if isinstance(value, np.ndarray):
            value.flags.writeable = False


def _check(cond: bool, what: str) -> None:
    if not cond:
        raise ValueError(what)


@dataclass(frozen=True, slots=True)
class Frame:
    """One sensor tick: what is recorded, replayed and fed to perception.

    This is everything a stage may read about the world. Ground truth that only the
    evaluation may see (people masks, people poses) is in :class:`SimTruth`.
    """

    step: int
    stamp_ns: int                 # sensor clock, integer ns (= MCAP log_time)
    rgb: np.ndarray               # uint8 (H, W, 3)
    depth_m: np.ndarray           # float32 (H, W), z-depth in metres, 0 where no return
    K: np.ndarray                 # float64 (3, 3) intrinsics, pixel centres at +0.5
    T_world_cam: np.ndarray       # float64 (4, 4) camera points -> world points

    def __post_init__(self) -> None:
        h, w = self.depth_m.shape if self.depth_m.ndim == 2 else (-1, -1)
        _check(self.rgb.dtype == np.uint8 and self.rgb.shape == (h, w, 3),
               f"Frame.rgb must be uint8 (H, W, 3) matching depth; got {self.rgb.dtype} {self.rgb.shape}")
        _check(self.depth_m.dtype == np.float32, f"Frame.depth_m must be float32; got {self.depth_m.dtype}")
        _check(self.K.shape == (3, 3) and self.K.dtype == np.float64, "Frame.K must be float64 (3, 3)")
        _check(self.T_world_cam.shape == (4, 4) and self.T_world_cam.dtype == np.float64,
               "Frame.T_world_cam must be float64 (4, 4)")
        _freeze_arrays(self)

    @property
    def height(self) -> int:
        return int(self.depth_m.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth_m.shape[1])


@dataclass(frozen=True, slots=True)
class RobotPose2D:
    """Planar pose of the ground robot: position on the floor and heading."""

    x_m: float
    y_m: float
    yaw_rad: float                # heading, counter-clockwise from +x


@dataclass(frozen=True, slots=True)
class SimTruth:
    """Simulator ground truth for one tick. For evaluation and viewers only: no stage reads it."""

    step: int
    stamp_ns: int
    people_mask: np.ndarray       # bool (H, W), True where a person is the nearest surface
    robot: RobotPose2D
    people_xy_m: np.ndarray       # float64 (P, 2) people positions on the floor
    people_heading_rad: np.ndarray  # float64 (P,)
    people_height_m: np.ndarray   # float64 (P,)
    collided: bool                # the last action was blocked (wall, furniture or person)

    def __post_init__(self) -> None:
        p = self.people_xy_m.shape[0]
        _check(self.people_mask.dtype == np.bool_ and self.people_mask.ndim == 2,
               "SimTruth.people_mask must be bool (H, W)")
        _check(self.people_xy_m.shape == (p, 2), "SimTruth.people_xy_m must be (P, 2)")
        _check(self.people_heading_rad.shape == (p,) and self.people_height_m.shape == (p,),
               "SimTruth.people_heading_rad and people_height_m must be (P,)")
        _freeze_arrays(self)


# --------------------------------------------------------------------------------------------
# Stage outputs (DESIGN.md §3). Every stage is
#     step(cfg, rec: StepRecord, state, rng) -> (state, Out)
# and reads only ``rec.frame``, the outputs of the stages before it in ``rec`` and
# ``rec.prev_mapping`` (the mapping output of the previous step, see below). Everything a
# stage keeps between steps is in its explicit state. These records are what the MCAP log
# stores per step, so they are kept small: images at the camera resolution, voxel sets as
# integer indices, no Gaussian parameters (those go into occasional map snapshots).
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class PerceptionOut:
    """Per-pixel uncertainty of the current frame.

    ``beta`` is predicted for frame t by the MLP as trained up to the previous frame
    (predict-then-train: at step t the predictor first trains on frame t-1 against the
    map's render of frame t-1 carried by ``rec.prev_mapping``, then predicts frame t).
    """

    beta: np.ndarray              # float32 (H, W), >= beta_min + 1e-3
    loss: float                   # uncertainty loss at the last training iteration; nan if none ran
    trained: bool                 # whether the MLP was trained at this step

    def __post_init__(self) -> None:
        _check(self.beta.dtype == np.float32 and self.beta.ndim == 2, "PerceptionOut.beta must be float32 (H, W)")
        _freeze_arrays(self)


@dataclass(frozen=True, slots=True)
class MappingOut:
    """What the mapping stage tells later stages (and the next step's perception).

    ``render_*`` is the map *before* this step's update (G_{t-1}) rendered at frame t's pose:
    perception trains on it at step t+1, fields aggregates its residual, and it is the
    frame the densification decision was made on.

    ``surface_ijk`` is a compact proxy of the map's geometry for visibility tests: the
    voxels (edge ``surface_voxel_m``, world-aligned, voxel (i, j, k) spans
    ``[i, i+1) * surface_voxel_m`` in x, etc.) holding the centre of at least one opaque
    Gaussian, sorted lexicographically.
    """

    render_rgb: np.ndarray        # uint8 (H, W, 3)
    render_depth_m: np.ndarray    # float32 (H, W), expected depth, 0 where alpha is ~0
    render_alpha: np.ndarray      # float32 (H, W), accumulated opacity in [0, 1]
    surface_ijk: np.ndarray       # int32 (M, 3)
    surface_voxel_m: float
    n_gaussians: int
    n_added: int
    n_pruned: int
    loss: float                   # mapping loss at the last iteration of this step; nan if none ran
    keyframe: bool                # frame t was added to the keyframe set

    def __post_init__(self) -> None:
        h, w = self.render_depth_m.shape if self.render_depth_m.ndim == 2 else (-1, -1)
        _check(self.render_rgb.dtype == np.uint8 and self.render_rgb.shape == (h, w, 3),
               "MappingOut.render_rgb must be uint8 (H, W, 3)")
        _check(self.render_depth_m.dtype == np.float32, "MappingOut.render_depth_m must be float32")
        _check(self.render_alpha.dtype == np.float32 and self.render_alpha.shape == (h, w),
               "MappingOut.render_alpha must be float32 (H, W)")
        _check(self.surface_ijk.dtype == np.int32 and self.surface_ijk.ndim == 2 and self.surface_ijk.shape[1] == 3,
               "MappingOut.surface_ijk must be int32 (M, 3)")
        _freeze_arrays(self)


@dataclass(frozen=True, slots=True)
class FieldsOut:
    """Structural and motion uncertainty on the voxel query set Omega (a dense box grid).

    Voxel (i, j, k) has its centre at ``origin_m + (i + 0.5, j + 0.5, k + 0.5) * voxel_m``.
    """

    origin_m: np.ndarray          # float64 (3,), the grid's min corner
    voxel_m: float
    u_s: np.ndarray               # float32 (X, Y, Z), eq. 4
    u_m: np.ndarray               # float32 (X, Y, Z), eq. 5
    n_obs: np.ndarray             # float32 (X, Y, Z), effective observation count n_t
    visible: np.ndarray           # bool (X, Y, Z), 1_t(x): observed in this frame

    def __post_init__(self) -> None:
        s = self.u_s.shape
        _check(self.origin_m.shape == (3,) and self.origin_m.dtype == np.float64, "FieldsOut.origin_m must be float64 (3,)")
        _check(len(s) == 3 and all(a.shape == s for a in (self.u_m, self.n_obs, self.visible)),
               "FieldsOut grids must share one (X, Y, Z) shape")
        _check(self.u_s.dtype == self.u_m.dtype == self.n_obs.dtype == np.float32 and self.visible.dtype == np.bool_,
               "FieldsOut: u_s, u_m, n_obs float32; visible bool")
        _freeze_arrays(self)


@dataclass(frozen=True, slots=True)
class SelectionOut:
    """The next target view, the graph it was chosen on, and every candidate's score (for viewers).

    The graph's node ids are 0..N-1; ``edges`` lists (u, v) with u < v, sorted.
    ``mode`` is how the target was chosen: ``local``, ``global``, ``random``, ``frontier``,
    ``keep`` (the previous target still stands) or ``none`` (nothing left to explore).
    ``target_reason`` is what became of the previous target at this step: ``keep``, ``reached``,
    ``unreachable`` (no way to it in the graph), ``stuck`` (no progress, or too many bumps),
    ``timeout``, ``reopened`` (a better view beyond a disc that was let go), or ``none`` (there was none);
    ``""`` in logs older than schema version 6.
    ``local_clear_m`` is the known free space around the robot for the planner's last metre: each
    cell's distance to the nearest occupied cell of the occupancy grid or kept bump disc (the
    measure of ``node_leg_clear``), or with ``selection.local_people_steps`` of a cell holding one of the
    last frames' people returns, capped where obstacles farther out were not looked for.
    """

    target_xy_m: np.ndarray       # float64 (2,)
    target_yaw_rad: float
    target_node: int              # -1 when mode is none
    mode: str
    node_xy_m: np.ndarray         # float64 (N, 2)
    edges: np.ndarray             # int32 (E, 2)
    edge_length_m: np.ndarray     # float64 (E,)
    node_region: np.ndarray       # int32 (N,), subregion label per node
    frontier: np.ndarray          # bool (N,), node next to unknown space
    node_leg_clear: np.ndarray    # bool (N,), the straight way from the robot to the node keeps clear of obstacles
    cand_node: np.ndarray         # int32 (C,), candidate views: node and yaw
    cand_yaw_rad: np.ndarray      # float64 (C,)
    cand_gain: np.ndarray         # float64 (C,), I_s (eq. 8)
    cand_risk: np.ndarray         # float64 (C,), R_m (eq. 9)
    cand_cost: np.ndarray         # float64 (C,), travel cost C(n)
    cand_score: np.ndarray        # float64 (C,), S_local (eq. 7)
    local_clear_m: np.ndarray     # float32 (L, L), distance to the nearest known obstacle around the robot; (0, 0): none
    local_origin_xy_m: np.ndarray  # float64 (2,), world xy of local_clear_m's lower-left corner
    local_cell_m: float           # cell size of local_clear_m: cell [i, j] is centred at origin + ((j, i) + 0.5) * cell
    target_reason: str = ""       # what became of the previous target: keep, reached, unreachable, stuck, ...

    def __post_init__(self) -> None:
        n = self.node_xy_m.shape[0]
        c = self.cand_node.shape[0]
        _check(self.target_xy_m.shape == (2,), "SelectionOut.target_xy_m must be (2,)")
        _check(self.node_xy_m.shape == (n, 2) and self.node_region.shape == (n,) and self.frontier.shape == (n,)
               and self.node_leg_clear.shape == (n,), "SelectionOut node arrays must be (N, ...)")
        _check(self.edges.ndim == 2 and self.edges.shape[1] == 2 and self.edge_length_m.shape == (self.edges.shape[0],),
               "SelectionOut.edges must be (E, 2) with edge_length_m (E,)")
        _check(all(a.shape == (c,) for a in (self.cand_yaw_rad, self.cand_gain, self.cand_risk, self.cand_cost,
                                             self.cand_score)), "SelectionOut candidate arrays must be (C,)")
        _check(self.local_clear_m.ndim == 2 and self.local_clear_m.shape[0] == self.local_clear_m.shape[1]
               and self.local_origin_xy_m.shape == (2,), "SelectionOut.local_clear_m must be (L, L), origin (2,)")
        _freeze_arrays(self)


@dataclass(frozen=True, slots=True)
class PlanningOut:
    """The planned path and the one discrete action the robot takes now."""

    action: int                   # a sim.robot.Action value
    path_xy_m: np.ndarray         # float64 (P, 2), waypoints from the robot to the target
    path_cost: float              # eq. 11 summed along the path; nan when there is no path
    replanned: bool               # the path was recomputed at this step
    blocked: bool                 # the local collision check stopped a forward move
    stuck: bool                   # the robot was stuck and asked for a new target

    def __post_init__(self) -> None:
        _check(self.path_xy_m.ndim == 2 and self.path_xy_m.shape[1] == 2, "PlanningOut.path_xy_m must be (P, 2)")
        _freeze_arrays(self)


@dataclass(frozen=True, slots=True)
class StepRecord:
    """Everything of one step that stages read: the frame and the outputs so far.

    A stage's output field is None until that stage has run. ``prev_mapping`` is the
    previous step's :class:`MappingOut` (None at step 0); only perception reads it.
    """

    frame: Frame
    prev_mapping: MappingOut | None = None
    perception: PerceptionOut | None = None
    mapping: MappingOut | None = None
    fields: FieldsOut | None = None
    selection: SelectionOut | None = None
    planning: PlanningOut | None = None


def robot_pose_of(frame: Frame) -> RobotPose2D:
    """The robot's planar pose from the camera pose (the camera looks along the robot's heading)."""
    T = frame.T_world_cam
    z_axis = T[:3, 2]                                # the optical axis in world coordinates
    return RobotPose2D(float(T[0, 3]), float(T[1, 3]), float(np.arctan2(z_axis[1], z_axis[0])))
