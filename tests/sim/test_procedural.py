"""Procedural scenes: determinism, suite sizes, textures, doors kept clear."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from dynactivegs.errors import SceneError
from dynactivegs.sim.procedural import STANDARD_INSTANCES, make_scene
from dynactivegs.sim.scenes import load_scene, scene_freespace
from dynactivegs.config import SimConfig
from dynactivegs.sim.scenes import scene_renderer


def test_same_name_same_mesh_and_different_names_differ():
    a, b, c = make_scene("apartment-02"), make_scene("apartment-02"), make_scene("apartment-03")
    assert np.array_equal(a.vertices_m, b.vertices_m) and np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.parts[0].appearance.textures, b.parts[0].appearance.textures)
    assert a.vertices_m.shape != c.vertices_m.shape or not np.array_equal(a.vertices_m, c.vertices_m)


@pytest.mark.parametrize("suite,rooms,area", [("tiny", (1, 1), (14, 28)), ("apartment", (4, 6), (60, 100)),
                                               ("house", (8, 12), (150, 250)), ("loop", (4, 6), (60, 100))])
def test_suites_have_their_sizes(suite, rooms, area):
    for name in STANDARD_INSTANCES[suite][:3]:
        s = load_scene(SimConfig(scene=name))
        real = [r for r in s.rooms if r.kind != "corridor"]
        total = sum(r.area_m2 for r in s.rooms)
        assert rooms[0] <= len(real) <= rooms[1], f"{name}: {len(real)} rooms"
        assert area[0] <= total <= area[1], f"{name}: {total:.1f} m^2"
        assert 2.5 <= s.wall_height_m <= 2.8, f"{name}: walls {s.wall_height_m:.2f} m"
        if suite != "tiny":
            assert len(s.doors) >= len(s.rooms) - 1, f"{name}: {len(s.doors)} doors for {len(s.rooms)} rooms"


def test_every_room_and_door_is_reachable_in_the_mesh_free_space():
    """Furniture never blocks a door: from the mesh itself, every door centre and every room is
    in the single navigable component, for the robot and for a person."""
    for name in ("apartment-00", "apartment-01", "house-00", "loop-00"):
        s = load_scene(SimConfig(scene=name))
        fs = scene_freespace(s, scene_renderer(s), 0.05, 1.5)
        for radius in (0.18, 0.3):
            nav = fs.navigable(radius)
            for d in s.doors:
                c = np.array([d.line_m, d.center_m]) if d.vertical else np.array([d.center_m, d.line_m])
                assert fs.is_navigable(c, radius), f"{name}: door at {c} blocked for radius {radius}"
            for r in s.rooms:
                i0, j0 = fs.world_to_cell(np.array([r.x0, r.y0]))
                i1, j1 = fs.world_to_cell(np.array([r.x1, r.y1]))
                assert nav[i0:i1, j0:j1].sum() * 0.0025 > 0.5, f"{name}: room {r.name} unreachable at r={radius}"


def _door_loops(doors, n_rooms: int) -> int:
    """Independent cycles of the rooms-and-doors graph (doors - rooms + components)."""
    g = nx.MultiGraph()
    g.add_nodes_from(range(n_rooms))
    g.add_edges_from(d.rooms for d in doors)
    return g.number_of_edges() - n_rooms + nx.number_connected_components(g)


def test_loop_scenes_are_the_apartments_with_ways_round():
    """loop-NN has apartment-NN's rooms, a superset of its room pairs joined by doors, and at least one loop
    through the doors, in every standard instance; apartments keep their own doors."""
    loops = []
    for i in range(8):
        a, b = make_scene(f"apartment-{i:02d}"), make_scene(f"loop-{i:02d}")
        rooms_a, rooms_b = ([(r.kind, r.x0, r.y0, r.x1, r.y1) for r in s.rooms] for s in (a, b))
        assert rooms_a == rooms_b
        assert {d.rooms for d in a.doors} <= {d.rooms for d in b.doors}
        loops.append((_door_loops(a.doors, len(a.rooms)), _door_loops(b.doors, len(b.rooms))))
    assert all(lb >= 1 for _, lb in loops), loops
    assert sum(lb for _, lb in loops) >= 2 * sum(la for la, _ in loops) + 8, loops


def test_room_contains_and_door_sides():
    """Room.contains tests the rectangle, edges included; Room.door_sides names the walls its doors are in, on
    constructed rooms (a vertical door between two rooms side by side, a horizontal one to a room north of the
    first) and on every room of the standard apartments (each has a door, as many sides as it has doors at most)."""
    from dynactivegs.sim.procedural import Door, Room

    rooms = (Room("a", "living", 0.0, 0.0, 4.0, 3.0), Room("b", "kitchen", 4.0, 0.0, 7.0, 3.0),
             Room("c", "bedroom", 0.0, 3.0, 4.0, 6.0))
    doors = (Door((0, 1), True, 4.0, 1.5, 0.9), Door((0, 2), False, 3.0, 2.0, 0.9))
    assert rooms[0].door_sides(doors, rooms) == {1, 3}                  # north and east
    assert rooms[1].door_sides(doors, rooms) == {2} and rooms[2].door_sides(doors, rooms) == {0}
    assert rooms[1].door_sides(doors[1:], rooms) == frozenset()
    xy = np.array([[0.0, 0.0], [4.0, 3.0], [2.0, 1.5], [4.01, 1.0], [1.0, -0.01]])
    assert rooms[0].contains(xy).tolist() == [True, True, True, False, False]
    for i in range(4):
        scene = make_scene(f"apartment-{i:02d}")
        for k, r in enumerate(scene.rooms):
            sides = r.door_sides(scene.doors, scene.rooms)
            assert 1 <= len(sides) <= sum(k in d.rooms for d in scene.doors)


def test_surfaces_are_textured_not_flat():
    s = make_scene("apartment-00")
    tex = s.parts[0].appearance.textures
    stds = tex.reshape(len(tex), -1, 3).std(axis=1).mean(axis=1)
    assert (stds > 3.0).mean() > 0.95, f"flat textures: {np.sort(stds)[:5]}"
    assert len(tex) > 40, f"only {len(tex)} materials"


def test_unknown_scene_names_fail_clearly():
    for bad in ("apartment-1", "mansion-00", "apartment-000", "loop-7"):
        with pytest.raises(SceneError) as e:
            make_scene(bad)
        assert "\n" not in str(e.value) and "tiny-NN" in str(e.value)
