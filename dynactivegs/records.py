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
