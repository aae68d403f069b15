"""The simulator as a whole: determinism, collisions, people vs. ground truth, free space."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import trimesh

from dynactivegs.config import CameraConfig, CrowdConfig, SimConfig
from dynactivegs.records import RobotPose2D
from dynactivegs.rng import derive_rng
from dynactivegs.sim.freespace import freespace_from_mesh
from dynactivegs.sim.render import Renderer
from dynactivegs.sim.robot import Action
from dynactivegs.sim.scripted import ScriptedDriver
from dynactivegs.sim.world import Simulator

SMALL_CAM = CameraConfig(width_px=64, height_px=37)


def run(cfg: SimConfig, seed: int, steps: int):
    sim = Simulator(cfg, seed)
    driver = ScriptedDriver(sim.freespace, cfg.robot.radius_m, derive_rng(seed, "test-driver"))
    frames, truths = [sim.observation()[0]], [sim.observation()[1]]
    for _ in range(steps):
        t = truths[-1]
        f, t = sim.step(driver.act(t.robot.x_m, t.robot.y_m, t.robot.yaw_rad, t.collided))
        frames.append(f)
        truths.append(t)
    return sim, frames, truths


def test_same_seed_bit_identical_frames_and_tracks_different_seed_differs():
    cfg = SimConfig(scene="apartment-00", camera=dataclasses.replace(SMALL_CAM, depth_noise_std_m=0.01))
    _, fa, ta = run(cfg, 5, 40)
    _, fb, tb = run(cfg, 5, 40)
    _, fc, tc = run(cfg, 6, 40)
    for a, b in zip(fa, fb):
        assert a.rgb.tobytes() == b.rgb.tobytes() and a.depth_m.tobytes() == b.depth_m.tobytes()
        assert a.T_world_cam.tobytes() == b.T_world_cam.tobytes() and a.stamp_ns == b.stamp_ns
    for a, b in zip(ta, tb):
        assert a.people_xy_m.tobytes() == b.people_xy_m.tobytes() and a.robot == b.robot
    assert any(a.people_xy_m.shape != c.people_xy_m.shape or not np.array_equal(a.people_xy_m, c.people_xy_m)
               for a, c in zip(ta, tc))
    assert any(a.rgb.tobytes() != c.rgb.tobytes() for a, c in zip(fa, fc))


def test_robot_cannot_pass_through_a_wall():
    cfg = SimConfig(scene="tiny-00", camera=SMALL_CAM, crowd=CrowdConfig(count=0))
    sim = Simulator(cfg, 0)
    room = sim.scene.rooms[0]
    clear = np.where(sim.freespace.navigable(cfg.robot.radius_m), sim.freespace.clearance_m, 0.0)
    start = sim.freespace.cell_to_world(np.array(np.unravel_index(np.argmax(clear), clear.shape)))
    for yaw in (0.0, math.pi / 2, math.pi, -math.pi / 2):
        sim.robot = RobotPose2D(float(start[0]), float(start[1]), yaw)
        blocked = 0
        for _ in range(60):
            _, truth = sim.step(Action.FORWARD)
            blocked += truth.collided
            xy = np.array([truth.robot.x_m, truth.robot.y_m])
            assert sim.freespace.is_navigable(xy, cfg.robot.radius_m), f"robot in an obstacle at {xy}"
            inner = room.inner()
            r = cfg.robot.radius_m
            assert inner[0] + r - 1e-6 <= xy[0] <= inner[2] - r + 1e-6 and inner[1] + r - 1e-6 <= xy[1] <= inner[3] - r + 1e-6
        assert blocked > 30, f"heading {yaw:.2f}: only {blocked} of 60 forward moves blocked"


def test_robot_cannot_pass_through_a_person():
    cfg = SimConfig(scene="tiny-00", camera=SMALL_CAM, crowd=CrowdConfig(count=1, speed_mps=0.01))
    sim = Simulator(cfg, 0)
    person = sim.crowd.positions_xy_m[0]
    # stand 0.9 m from the person, facing them, with free space in between
    approaches = [a for a in np.linspace(0, 2 * np.pi, 24, endpoint=False)
                  if sim.freespace.segment_navigable(person - 0.9 * np.array([math.cos(a), math.sin(a)]), person,
                                                     cfg.robot.radius_m)]
    assert approaches, "the fixed layout must leave a free approach to the person"
    ang = approaches[0]
    start = person - 0.9 * np.array([math.cos(ang), math.sin(ang)])
    sim.robot = RobotPose2D(float(start[0]), float(start[1]), float(ang))
    gaps = []
    for _ in range(8):
        _, truth = sim.step(Action.FORWARD)
        p = truth.people_xy_m[0]
        gaps.append(np.hypot(truth.robot.x_m - p[0], truth.robot.y_m - p[1]) - cfg.robot.radius_m - cfg.crowd.radius_m)
    assert min(gaps) > -0.02, f"robot overlapped the person by {-min(gaps):.3f} m"
    assert truth.collided, "the robot should end up blocked by the person"


def test_robot_and_people_never_overlap_on_a_tour():
    cfg = SimConfig(scene="apartment-01", camera=SMALL_CAM)
    sim, _, truths = run(cfg, 3, 150)
    worst = 0.0
    for t in truths:
        d = np.hypot(t.people_xy_m[:, 0] - t.robot.x_m, t.people_xy_m[:, 1] - t.robot.y_m)
        worst = max(worst, float((cfg.robot.radius_m + cfg.crowd.radius_m - d).max()))
    assert worst < 0.02, f"robot and a person overlapped by {worst:.3f} m"


def test_people_are_in_frames_but_never_in_static_renders():
    cfg = SimConfig(scene="apartment-00", camera=SMALL_CAM)
    sim, frames, truths = run(cfg, 0, 60)
    seen = 0
    for f, t in zip(frames, truths):
        static = sim.render_static(f.T_world_cam)
        m = t.people_mask
        # outside the people mask the frame is exactly the static render
        assert np.array_equal(f.rgb[~m], static.rgb[~m]) and np.array_equal(f.depth_m[~m], static.depth_m[~m])
        if m.any():
            seen += 1
            valid = (static.depth_m[m] > 0) & (f.depth_m[m] > 0)
            assert np.all(f.depth_m[m][valid] < static.depth_m[m][valid]), "a person must be in front"
            assert not np.array_equal(f.rgb[m], static.rgb[m])
        assert not static.people_mask.any()
    assert seen >= 5, f"people visible in only {seen} of {len(frames)} frames"


def test_surface_samples_lie_on_the_static_mesh_only():
    cfg = SimConfig(scene="tiny-01", camera=SMALL_CAM)
    sim = Simulator(cfg, 0)
    n_faces = sim.scene.n_faces
    for _ in range(5):
        sim.step(Action.TURN_LEFT)
    pts = sim.surface_samples(2000, np.random.default_rng(0))
    assert sim.scene.n_faces == n_faces
    mesh = trimesh.Trimesh(sim.scene.vertices_m, sim.scene.faces, process=False)
    _, dist, _ = trimesh.proximity.closest_point(mesh, pts[:500])
    assert dist.max() < 1e-6, f"a sample is {dist.max():.2e} m off the static mesh"


def test_freespace_of_a_box_room_is_the_inset_rectangle():
    box = trimesh.creation.box(extents=(6.0, 4.0, 2.6))
    box.apply_translation((0, 0, 1.3))
    box.invert()
    tri = box.vertices[box.faces]
    from dynactivegs.sim.scene import FaceColors, Scene, ScenePart

    f = box.faces.astype(np.int32)
    scene = Scene("box", box.vertices, f, (ScenePart(0, len(f), FaceColors(np.zeros((len(f), 3), np.uint8))),))
    r = Renderer(scene)

    def down(o):
        d = np.zeros_like(o)
        d[:, 2] = -1
        return r.cast(o, d)[0]

    fs = freespace_from_mesh(tri, down, res_m=0.05)
    for radius in (0.0, 0.18, 0.3):
        area = fs.navigable(radius).sum() * 0.05 ** 2
        expected = (6.0 - 2 * radius) * (4.0 - 2 * radius)
        assert abs(area - expected) < 0.1 * (6 + 4), f"radius {radius}: {area:.2f} m^2 vs {expected:.2f}"
    assert not fs.is_navigable(np.array([3.5, 0.0]), 0.0), "outside the room is not free"


def test_grid_graph_connects_8_neighbours_without_cutting_corners():
    from scipy.sparse.csgraph import dijkstra

    from dynactivegs.sim.freespace import grid_graph

    g, cells = grid_graph(np.ones((3, 4), bool), 1.0)
    assert g.nnz == 2 * (9 + 8 + 12)            # horizontal, vertical, diagonal pairs
    mask = np.array([[1, 0], [0, 1]], bool)     # two cells touching only at a corner
    g, cells = grid_graph(mask, 0.5)
    assert g.nnz == 0
    mask = np.ones((5, 5), bool)
    mask[1:4, 2] = False                        # a wall with gaps at both ends
    g, cells = grid_graph(mask, 1.0)
    node = {tuple(c): k for k, c in enumerate(cells)}
    d = dijkstra(g, indices=node[(2, 0)])[node[(2, 4)]]
    # up past the wall's end and down again; diagonals next to the wall's end are not allowed
    assert abs(d - (4 + 2 * 2 ** 0.5)) < 1e-9, f"around the wall: {d}"


def test_people_never_enter_walls_furniture_or_each_other_in_an_apartment_over_500_steps():
    """Checked against the mesh itself (points sampled on obstacle surfaces in the body's
    height band), not only against the grid the crowd plans on."""
    from scipy.spatial import cKDTree

    cfg = SimConfig(scene="apartment-02", camera=SMALL_CAM)
    sim = Simulator(cfg, 11)
    tree = cKDTree(sim.freespace.obstacle_xy_m)
    r = cfg.crowd.radius_m
    robot = np.array([sim.robot.x_m, sim.robot.y_m])
    worst_wall, worst_pair = 0.0, 0.0
    start = sim.crowd.positions_xy_m.copy()
    for _ in range(500):
        sim.crowd.step(cfg.dt_s, robot, np.zeros(2), cfg.robot.radius_m)
        p = sim.crowd.positions_xy_m
        d_wall, _ = tree.query(p)
        worst_wall = max(worst_wall, float((r - d_wall).max()))
        if len(p) > 1:
            dd = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p)) * 1e9
            worst_pair = max(worst_pair, float((2 * r - dd).max()))
    assert worst_wall < 0.03, f"a person came {worst_wall:.3f} m into a wall or furniture"
    assert worst_pair < 0.02, f"two people overlapped by {worst_pair:.3f} m"
    walked = np.linalg.norm(sim.crowd.positions_xy_m - start, axis=1)
    assert sim.crowd.goals_reached.sum() >= len(walked), f"only {sim.crowd.goals_reached.sum()} goals reached"


def test_simulator_runs_in_a_yup_glb_scene(tmp_path):
    """A Habitat-style (Y-up) .glb room with a pillar: loaded Z-up, free space found, people walk."""
    room = trimesh.creation.box(extents=(6.0, 5.0, 2.6))
    room.apply_translation((0, 0, 1.3))
    room.invert()
    pillar = trimesh.creation.box(extents=(0.4, 0.4, 2.6))
    pillar.apply_translation((1.0, 0.5, 1.3))
    zup = trimesh.util.concatenate([room, pillar])
    zup.visual.face_colors = np.tile([180, 120, 90, 255], (len(zup.faces), 1))
    yup = zup.copy()
    yup.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))  # Z-up -> Y-up
    path = tmp_path / "room.glb"
    yup.export(path)
    sim = Simulator(SimConfig(scene=str(path), camera=SMALL_CAM, crowd=CrowdConfig(count=2)), 0)
    lo, hi = sim.scene.bounds_m
    assert abs(lo[2]) < 1e-6 and abs(hi[2] - 2.6) < 1e-6, f"z range {lo[2]:.3f}..{hi[2]:.3f}"
    assert not sim.freespace.is_navigable(np.array([1.0, 0.5]), 0.0), "the pillar is an obstacle"
    assert 20.0 < sim.freespace.free_area_m2() < 30.0
    for _ in range(10):
        frame, truth = sim.step(Action.TURN_LEFT)
    assert (frame.depth_m > 0).mean() > 0.95 and len(truth.people_xy_m) == 2
