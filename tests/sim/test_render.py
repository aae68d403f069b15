"""Renderer: analytic depth on a box room, intrinsics/poses consistent with the geometry."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from dynactivegs.config import SimConfig
from dynactivegs.sim.render import Renderer, camera_rays, intrinsics
from dynactivegs.sim.robot import camera_pose
from dynactivegs.sim.scene import FaceColors, Scene, ScenePart
from dynactivegs.sim.scenes import load_scene
from dynactivegs.sim.scenes import scene_renderer

HALF = np.array([3.0, 2.0])   # room is [-3, 3] x [-2, 2] x [0, 2.6]
HEIGHT = 2.6


def box_room() -> Scene:
    box = trimesh.creation.box(extents=(2 * HALF[0], 2 * HALF[1], HEIGHT))
    box.apply_translation((0, 0, HEIGHT / 2))
    box.invert()  # faces point into the room
    f = box.faces.astype(np.int32)
    colors = np.full((len(f), 3), 128, np.uint8)
    return Scene("box", box.vertices.astype(np.float64), f, (ScenePart(0, len(f), FaceColors(colors)),), lit=False)


def analytic_depth(T: np.ndarray, K: np.ndarray, w: int, h: int) -> np.ndarray:
    d = camera_rays(K, w, h) @ T[:3, :3].T
    o = T[:3, 3]
    t = np.full(len(d), np.inf)
    bounds = [(-HALF[0], HALF[0]), (-HALF[1], HALF[1]), (0.0, HEIGHT)]
    for axis, (lo, hi) in enumerate(bounds):
        for plane in (lo, hi):
            with np.errstate(divide="ignore", invalid="ignore"):
                s = (plane - o[axis]) / d[:, axis]
            s[~np.isfinite(s) | (s <= 0)] = np.inf
            t = np.minimum(t, s)
    return t.reshape(h, w)


def test_depth_matches_analytic_box_room_to_1mm():
    r = Renderer(box_room())
    w, h = 64, 37
    K = intrinsics(w, h, 32.0, 32.0)
    for x, y, yaw in [(0.0, 0.0, 0.0), (1.3, -0.7, 2.1), (-2.5, 1.5, -0.6)]:
        T = camera_pose(x, y, yaw, 1.25)
        out = r.render(T, K, w, h, min_depth_m=0.01, max_depth_m=100.0)
        expected = analytic_depth(T, K, w, h)
        err = np.abs(out.depth_m - expected).max()
        assert err < 1e-3, f"max depth error {err * 1000:.3f} mm at pose {(x, y, yaw)}"


def test_depth_range_clips_to_zero():
    r = Renderer(box_room())
    K = intrinsics(32, 18, 16.0, 16.0)
    T = camera_pose(-2.9, 0.0, 0.0, 1.25)
    out = r.render(T, K, 32, 18, min_depth_m=0.1, max_depth_m=3.0)
    far = analytic_depth(T, K, 32, 18) > 3.0
    assert far.any() and np.all(out.depth_m[far] == 0) and np.all(out.depth_m[~far] > 0)


def test_backprojected_depth_lands_on_the_mesh():
    """K and T_world_cam agree with the rendered geometry: pixels back-projected with them
    lie on the scene surface (distance to the nearest triangle below 2 mm)."""
    cfg = SimConfig(scene="apartment-00")
    scene = load_scene(cfg)
    r = scene_renderer(scene)
    cam = cfg.camera
    K = intrinsics(cam.width_px, cam.height_px, cam.fx, cam.fy)
    room = scene.rooms[0]
    T = camera_pose((room.x0 + room.x1) / 2, (room.y0 + room.y1) / 2, 0.7, cam.height_m)
    out = r.render(T, K, cam.width_px, cam.height_px)
    v, u = np.nonzero(out.depth_m > 0)
    pick = np.random.default_rng(0).choice(len(v), 400, replace=False)
    v, u = v[pick], u[pick]
    z = out.depth_m[v, u].astype(np.float64)
    pc = np.stack([(u + 0.5 - K[0, 2]) / K[0, 0] * z, (v + 0.5 - K[1, 2]) / K[1, 1] * z, z], axis=1)
    pw = pc @ T[:3, :3].T + T[:3, 3]
    mesh = trimesh.Trimesh(scene.vertices_m, scene.faces, process=False)
    _, dist, _ = trimesh.proximity.closest_point(mesh, pw)
    assert np.percentile(dist, 99) < 2e-3, f"99th percentile distance {np.percentile(dist, 99) * 1000:.2f} mm"


def test_camera_pose_is_level_and_faces_yaw():
    T = camera_pose(1.0, 2.0, math.pi / 2, 1.25)
    assert np.allclose(T[:3, 2], [0, 1, 0]) and np.allclose(T[:3, 1], [0, 0, -1])
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(T[:3, :3]), 1.0)


def _people_boxes(centres: list[tuple[float, float]]):
    from dynactivegs.sim.render import PeopleMesh

    vs, fs, offs = [], [], [0]
    for cx, cy in centres:
        b = trimesh.creation.box(extents=(0.4, 0.3, 1.7))
        b.apply_translation((cx, cy, 0.85))
        fs.append(b.faces + sum(len(v) for v in vs))
        vs.append(b.vertices)
        offs.append(offs[-1] + len(b.vertices))
    f = np.concatenate(fs).astype(np.int32)
    return PeopleMesh(np.concatenate(vs).astype(np.float32), f, np.full((len(f), 3), 200, np.uint8),
                      np.array(offs))


def test_people_render_matches_brute_force_merge_and_mask():
    """People are cast only inside their projected boxes; the result must equal casting every ray
    against the people and merging by depth (including a person right next to the camera)."""
    from dynactivegs.sim.render import _cast, _embree_scene

    r = Renderer(box_room())
    w, h = 80, 46
    K = intrinsics(w, h, 40.0, 40.0)
    T = camera_pose(-2.0, 0.0, 0.0, 1.25)
    people = _people_boxes([(0.5, 0.3), (1.5, -1.0), (-1.8, 0.05), (-2.5, 1.0)])  # last: behind the camera
    out = r.render(T, K, w, h, people=people, min_depth_m=0.01, max_depth_m=100.0)
    dirs = camera_rays(K, w, h) @ T[:3, :3].T
    ts, _, _ = _cast(r._bvh, T[:3, 3], dirs)
    tp, _, _ = _cast(_embree_scene(people.vertices_m[people.faces]), T[:3, 3], dirs)
    expected_mask = (tp < ts).reshape(h, w)
    expected_depth = np.minimum(ts, tp).reshape(h, w)
    assert expected_mask.sum() > 50
    assert np.array_equal(out.people_mask, expected_mask)
    assert np.allclose(out.depth_m, expected_depth, atol=1e-5)
    assert np.all(out.face_idx[out.people_mask] == -1)
