"""Analytic RGB-D views of box rooms, and hand-made occupancy maps, for the selection tests."""

from __future__ import annotations

import math

import numpy as np

from dynactivegs.sim.robot import camera_pose


def intrinsics(w: int, h: int, hfov_deg: float = 90.0, vfov_deg: float = 60.0) -> np.ndarray:
    """float64 (3, 3) pinhole intrinsics with pixel centres at +0.5."""
    fx = 0.5 * w / math.tan(math.radians(hfov_deg) / 2)
    fy = 0.5 * h / math.tan(math.radians(vfov_deg) / 2)
    return np.array([[fx, 0.0, w / 2], [0.0, fy, h / 2], [0.0, 0.0, 1.0]])


def render_depth(T_world_cam: np.ndarray, K: np.ndarray, w: int, h: int, room_xy: tuple[float, float],
                 boxes: list[tuple[float, float, float, float, float]] = (), ceiling_m: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """z-depth (H, W) float32 of a room [0, Lx] x [0, Ly] x [0, ceiling] seen from inside, and the box id per pixel.

    ``boxes``: (x0, y0, x1, y1, height) axis-aligned boxes standing on the floor. The second
    output is int (H, W): -1 where the room (floor, walls, ceiling) is seen, else the box index.
    """
    v, u = np.mgrid[0:h, 0:w] + 0.5
    d_cam = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    d = d_cam @ T_world_cam[:3, :3].T                       # world direction with unit camera z
    c = T_world_cam[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = []
        for axis, lim in ((0, room_xy[0]), (1, room_xy[1]), (2, ceiling_m)):
            for plane in (0.0, lim):
                t = (plane - c[axis]) / d[..., axis]
                ts.append(np.where(t > 1e-9, t, np.inf))
        t_room = np.min(np.stack(ts), axis=0)
        t_best = t_room
        which = np.full((h, w), -1)
        for b, (x0, y0, x1, y1, hz) in enumerate(boxes):
            lo = np.array([x0, y0, 0.0])
            hi = np.array([x1, y1, hz])
            ta = (lo - c) / d
            tb = (hi - c) / d
            tn = np.nanmax(np.minimum(ta, tb), axis=-1)
            tf = np.nanmin(np.maximum(ta, tb), axis=-1)
            hit = (tn <= tf) & (tn > 1e-9) & (tn < t_best)
            t_best = np.where(hit, tn, t_best)
            which = np.where(hit, b, which)
    return t_best.astype(np.float32), which


def view(x: float, y: float, yaw: float, height: float = 1.25) -> np.ndarray:
    return camera_pose(x, y, yaw, height)


def grid_from_ascii(rows: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(free, unknown) bool maps from text: '.' free, '#' occupied, '?' unknown; the first text row is the top (max y)."""
    a = np.array([list(r) for r in rows[::-1]])
    return a == ".", a == "?"
