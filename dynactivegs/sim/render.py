"""RGB-D rendering by ray casting with Embree (through ``embreex``).

The static scene's BVH is built once per scene. People are articulated meshes that change
every frame: they are put in a small BVH of their own each frame, cast separately, and
merged with the static hits by depth, which also gives the per-pixel people mask.

Shading is view-independent: albedo, and for lit scenes a fixed world light
``albedo * (AMBIENT + DIFFUSE * max(0, n . l))``. The same surface point has the same
colour from every viewpoint, as a 3DGS map with view-independent colour assumes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from dynactivegs.sim.scene import Scene

LIGHT_DIR = np.array([0.35, 0.55, 0.76]) / np.linalg.norm([0.35, 0.55, 0.76])
AMBIENT = 0.62
DIFFUSE = 0.38


@dataclass(frozen=True)
class PeopleMesh:
    """Triangles of all people at one instant, world frame."""

    vertices_m: np.ndarray        # float32 (V, 3)
    faces: np.ndarray             # int32 (F, 3)
    face_colors: np.ndarray       # uint8 (F, 3)
    vertex_offsets: np.ndarray | None = None
    """int64 (P + 1,): person p owns vertices [offsets[p], offsets[p+1]); None: one group."""

    @staticmethod
    def empty() -> "PeopleMesh":
        return PeopleMesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 3), np.uint8))

    def pixel_boxes(self, T_world_cam: np.ndarray, K: np.ndarray, width: int, height: int,
                    near_m: float = 0.05) -> dict[int, tuple[int, int, int, int]]:
        """Image-space boxes (u0, v0, u1, v1), end-exclusive, containing the projection of each person
        that can appear in the image, keyed by person index.

        A person with a vertex closer than ``near_m`` in front of (or behind) the camera gets the
        whole image, since its projection is unbounded.
        """
        offsets = np.array([0, len(self.vertices_m)]) if self.vertex_offsets is None else self.vertex_offsets
        T_cam_world = np.linalg.inv(T_world_cam)
        pc = self.vertices_m.astype(np.float64) @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
        # Frustum side planes through the camera centre: x >= x_lo z, x <= x_hi z, same for y.
        x_lo, x_hi = -K[0, 2] / K[0, 0], (width - K[0, 2]) / K[0, 0]
        y_lo, y_hi = -K[1, 2] / K[1, 1], (height - K[1, 2]) / K[1, 1]
        boxes = {}
        for p, (a, b) in enumerate(zip(offsets[:-1], offsets[1:])):
            q = pc[a:b]
            if len(q) == 0 or q[:, 2].max() < near_m:
                continue
            x, y, z = q[:, 0], q[:, 1], q[:, 2]
            if (x < x_lo * z).all() or (x > x_hi * z).all() or (y < y_lo * z).all() or (y > y_hi * z).all():
                continue  # entirely outside one side plane of the view frustum
            if z.min() < near_m:
                boxes[p] = (0, 0, width, height)
                continue
            u = K[0, 0] * q[:, 0] / q[:, 2] + K[0, 2]
            v = K[1, 1] * q[:, 1] / q[:, 2] + K[1, 2]
            u0, u1 = int(np.floor(u.min())), int(np.ceil(u.max())) + 1
            v0, v1 = int(np.floor(v.min())), int(np.ceil(v.max())) + 1
            u0, v0, u1, v1 = max(u0, 0), max(v0, 0), min(u1, width), min(v1, height)
            if u0 < u1 and v0 < v1:
                boxes[p] = (u0, v0, u1, v1)
        return boxes

    def faces_of(self, persons: list[int]) -> np.ndarray:
        """int64 indices of the faces that belong to the given persons."""
        if self.vertex_offsets is None:
            return np.arange(len(self.faces))
        owner = np.searchsorted(self.vertex_offsets, self.faces[:, 0], side="right") - 1
        return np.flatnonzero(np.isin(owner, persons))


@dataclass(frozen=True)
class RenderResult:
    rgb: np.ndarray               # uint8 (H, W, 3)
    depth_m: np.ndarray           # float32 (H, W), z-depth, 0 where no return within range
    people_mask: np.ndarray       # bool (H, W), a person is the nearest surface
    face_idx: np.ndarray          # int32 (H, W), static face hit (-1: none, or a person in front)


def intrinsics(width: int, height: int, fx: float, fy: float) -> np.ndarray:
    """float64 (3, 3) pinhole K with the principal point at the image centre (pixel centres at +0.5)."""
    return np.array([[fx, 0.0, width / 2.0], [0.0, fy, height / 2.0], [0.0, 0.0, 1.0]])


def camera_rays(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """float64 (H*W, 3) camera-frame ray directions with z = 1, row-major over pixels.

    With z = 1 the ray parameter at a hit equals the hit's z-depth.
    """
    u = (np.arange(width) + 0.5 - K[0, 2]) / K[0, 0]
    v = (np.arange(height) + 0.5 - K[1, 2]) / K[1, 1]
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel(), np.ones(width * height)], axis=1)


def _embree_scene(triangles: np.ndarray) -> rtcs.EmbreeScene:
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, np.ascontiguousarray(triangles, dtype=np.float32))
    return scene


def _cast(scene: rtcs.EmbreeScene, origin: np.ndarray, dirs: np.ndarray):
    """Closest hits of rays from ``origin`` (3,) or per-ray origins (N, 3) along ``dirs`` (N, 3):
    (t (N,) float64 with inf on miss, face (N,) int64 with -1 on miss, bary (N, 2))."""
    n = len(dirs)
    origins = np.broadcast_to(np.asarray(origin, dtype=np.float32), (n, 3))
    res = scene.run(np.ascontiguousarray(origins), np.ascontiguousarray(dirs, dtype=np.float32), output=1)
    face = res["primID"].astype(np.int64)
    hit = face >= 0
    t = np.where(hit, res["tfar"].astype(np.float64), np.inf)
    bary = np.stack([res["u"], res["v"]], axis=1).astype(np.float64)
    return t, np.where(hit, face, -1), bary


class Renderer:
    """Ray-casting RGB-D renderer of one static scene (plus people passed per call)."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self._bvh = _embree_scene(scene.triangles_m)
        self._rays_cache: dict[tuple, np.ndarray] = {}

    def _rays(self, K: np.ndarray, width: int, height: int) -> np.ndarray:
        key = (width, height, *np.round(K.ravel(), 9))
        if key not in self._rays_cache:
            self._rays_cache[key] = camera_rays(K, width, height)
        return self._rays_cache[key]

    def cast(self, origins_m: np.ndarray, dirs: np.ndarray):
        """Closest static hits of arbitrary rays; returns (t, face, bary) as in a render. ``origins_m`` (N, 3) or (3,)."""
        return _cast(self._bvh, origins_m, dirs)

    def render(self, T_world_cam: np.ndarray, K: np.ndarray, width: int, height: int, *,
               people: PeopleMesh | None = None, min_depth_m: float = 0.1, max_depth_m: float = 10.0) -> RenderResult:
        """Render RGB, z-depth and the people mask from camera pose ``T_world_cam`` (4, 4)."""
        assert T_world_cam.shape == (4, 4) and K.shape == (3, 3)
        rays_cam = self._rays(K, width, height)
        R = T_world_cam[:3, :3]
        origin = T_world_cam[:3, 3]
        dirs = rays_cam @ R.T
        t, face, bary = _cast(self._bvh, origin, dirs)
        person = np.zeros(len(t), dtype=bool)
        fp = np.full(len(t), -1, dtype=np.int64)
        if people is not None and len(people.faces):
            # Only rays inside the people's projected boxes can hit them.
            # and only the people whose projection is in the image are put in the BVH.
            boxes = people.pixel_boxes(T_world_cam, K, width, height)
            near = np.zeros((height, width), dtype=bool)
            for u0, v0, u1, v1 in boxes.values():
                near[v0:v1, u0:u1] = True
            cand = np.flatnonzero(near)
            if len(cand):
                faces = people.faces_of(list(boxes))
                tp, fpc, _ = _cast(_embree_scene(people.vertices_m[people.faces[faces]]), origin, dirs[cand])
                closer = tp < t[cand]
                hit_idx = cand[closer]
                person[hit_idx] = True
                t[hit_idx] = tp[closer]
                fp[hit_idx] = faces[fpc[closer]]
        hit = np.isfinite(t)
        rgb = np.zeros((len(t), 3), dtype=np.float32)
        static_hit = hit & ~person
        idx = np.nonzero(static_hit)[0]
        if len(idx):
            pts = origin + dirs[idx] * t[idx, None]
            f = face[idx]
            albedo = self.scene.albedo(f, bary[idx], pts)
            rgb[idx] = albedo * self._shade(self.scene.face_normals[f]) if self.scene.lit else albedo
        pidx = np.nonzero(person)[0]
        if len(pidx):
            pf = fp[pidx]
            tri = people.vertices_m[people.faces[pf]].astype(np.float64)
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            rgb[pidx] = people.face_colors[pf].astype(np.float32) / 255.0 * self._shade(n)
        depth = np.where(hit & (t >= min_depth_m) & (t <= max_depth_m), t, 0.0)
        shape = (height, width)
        return RenderResult(
            rgb=(np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8).reshape(height, width, 3),
            depth_m=depth.astype(np.float32).reshape(shape),
            people_mask=person.reshape(shape),
            face_idx=np.where(static_hit, face, -1).astype(np.int32).reshape(shape),
        )

    @staticmethod
    def _shade(normals: np.ndarray) -> np.ndarray:
        return (AMBIENT + DIFFUSE * np.maximum(normals @ LIGHT_DIR, 0.0))[:, None].astype(np.float32)
