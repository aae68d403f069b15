"""Articulated human meshes: size, grounding, gait, heading, colours, closed outward-wound parts."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from dynactivegs.sim.humans import (SHOES, TRIANGLES_PER_PERSON, VERTICES_PER_PERSON, HumanLook, people_mesh,
                                    sample_look)
from dynactivegs.sim import humans


def _looks(n: int, seed: int = 0) -> list[HumanLook]:
    rng = np.random.default_rng(seed)
    return [sample_look(rng) for _ in range(n)]


def _one(look: HumanLook, phase: float, speed: float, heading: float = 0.0, xy=(0.0, 0.0)):
    return people_mesh([look], np.array([xy], float), np.array([heading]), np.array([phase]), np.array([speed]))


def test_shapes_dtypes_and_triangle_budget():
    looks = _looks(7)
    rng = np.random.default_rng(1)
    v, f, c = people_mesh(looks, rng.uniform(0, 5, (7, 2)), rng.uniform(-3, 3, 7), rng.uniform(0, 6, 7),
                          np.full(7, 0.5))
    assert 300 <= TRIANGLES_PER_PERSON <= 600, f"{TRIANGLES_PER_PERSON} triangles per person"
    assert v.dtype == np.float32 and v.shape == (7 * VERTICES_PER_PERSON, 3), (v.dtype, v.shape)
    assert f.dtype == np.int32 and f.shape == (7 * TRIANGLES_PER_PERSON, 3), (f.dtype, f.shape)
    assert c.dtype == np.uint8 and c.shape == f.shape, (c.dtype, c.shape)
    assert f.min() == 0 and f.max() == len(v) - 1
    v0, f0, c0 = people_mesh([], np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0))
    assert v0.shape == (0, 3) and f0.shape == (0, 3) and c0.shape == (0, 3)


def test_every_part_is_closed_and_wound_outward():
    look = _looks(1)[0]
    for phase, speed in ((0.0, 0.0), (1.3, 0.6), (4.0, 1.0)):
        v, f, _ = _one(look, phase, speed, heading=0.7, xy=(2.0, -1.0))
        parts = trimesh.Trimesh(v.astype(np.float64), f, process=False).split(only_watertight=False)
        assert len(parts) == 15, f"{len(parts)} connected parts, expected 15 body segments"
        for part in parts:
            assert part.is_watertight, "a body segment is not closed"
            assert part.volume > 0, f"a segment has signed volume {part.volume:.3g} m^3: faces wound inward"


@pytest.mark.parametrize("height", [1.6, 1.75, 1.9])
def test_height_and_feet_on_the_floor(height):
    look = HumanLook(height, (200, 160, 130), (10, 20, 200), (30, 30, 30), (0, 0, 0), (40, 20, 10))
    v, _, _ = _one(look, 0.0, 0.0)
    assert abs(v[:, 2].max() - height) < 1e-4, f"standing top at {v[:, 2].max():.5f} m, height {height} m"
    assert abs(v[:, 2].min()) < 1e-5, f"standing lowest point at {v[:, 2].min():.6f} m, expected 0"
    for phase in np.linspace(0, 2 * np.pi, 9):
        v, _, _ = _one(look, phase, 0.7)
        assert abs(v[:, 2].min()) < 1e-5, f"walking (phase {phase:.2f}) lowest point at {v[:, 2].min():.6f} m"
        assert 0.95 * height < v[:, 2].max() <= height + 1e-4, \
            f"walking (phase {phase:.2f}) top at {v[:, 2].max():.4f} m for height {height} m"


def test_vertices_stay_near_the_person():
    looks = _looks(10, seed=3)
    rng = np.random.default_rng(4)
    xy = rng.uniform(-10, 10, (10, 2))
    # crowd speeds are at most 0.6 m/s; a long stride reaches farther than the 0.3 m collision disc
    for speed, limit in ((0.0, 0.32), (0.6, 0.5), (1.0, 0.7)):
        v, _, _ = people_mesh(looks, xy, rng.uniform(-3, 3, 10), rng.uniform(0, 6.3, 10), np.full(10, speed))
        d = np.hypot(*(v[:, :2].reshape(10, -1, 2) - xy[:, None]).transpose(2, 0, 1))
        assert d.max() < limit, f"at {speed} m/s a vertex lies {d.max():.3f} m from its person (limit {limit} m)"


def test_limbs_swing_with_phase_and_speed_and_stand_straight():
    look = _looks(1)[0]
    a, _, _ = _one(look, 0.5 * np.pi, 0.6)
    b, _, _ = _one(look, 1.5 * np.pi, 0.6)
    swing = np.abs(a - b).max()
    assert swing > 0.15, f"half a gait cycle moves limbs by only {swing:.3f} m"
    slow, _, _ = _one(look, 0.5 * np.pi, 0.2)
    fast, _, _ = _one(look, 0.5 * np.pi, 0.9)
    rest, _, _ = _one(look, 0.5 * np.pi, 0.0)
    s_slow, s_fast = np.abs(slow - rest).max(), np.abs(fast - rest).max()
    assert 0 < s_slow < s_fast, f"limb excursion from rest: {s_slow:.3f} m at 0.2 m/s, {s_fast:.3f} m at 0.9 m/s"
    # standing: the phase is irrelevant and the left and right sides mirror each other
    r1, _, _ = _one(look, 0.3, 0.0)
    r2, _, _ = _one(look, 2.9, 0.0)
    assert np.array_equal(r1, r2), "a standing person's pose depends on the gait phase"
    def rows_sorted(a):
        a = np.round(a.astype(np.float64), 4) + 0.0
        return a[np.lexsort(a.T[::-1])]
    err = np.abs(rows_sorted(r1 * [1, -1, 1]) - rows_sorted(r1)).max()
    assert err < 2e-4, f"a standing person is not left-right symmetric (max mismatch {err:.2e} m)"


def test_faces_its_heading():
    look = _looks(1)[0]
    v0, f, c = _one(look, 1.0, 0.0, heading=0.0)
    shoe_verts = np.unique(f[(c == look.palette()[SHOES]).all(axis=1)])
    x = v0[shoe_verts, 0]
    assert x.max() > 2 * abs(x.min()), f"toes reach x={x.max():.3f}, heels x={x.min():.3f}: not facing +x"
    v0, _, _ = _one(look, 1.0, 0.6, heading=0.0)
    h = 2.1
    v1, _, _ = _one(look, 1.0, 0.6, heading=h)
    rot = np.array([[np.cos(h), -np.sin(h)], [np.sin(h), np.cos(h)]])
    err = np.abs(v0[:, :2].astype(np.float64) @ rot.T - v1[:, :2]).max()
    assert err < 1e-5, f"heading {h} rad is not a rotation of heading 0 (max error {err:.2e} m)"


def test_colours_vary_between_people():
    looks = _looks(40, seed=11)
    shirts = {lk.shirt_rgb for lk in looks}
    assert len(shirts) >= 30, f"only {len(shirts)} distinct shirt colours among 40 people"
    lum = np.array([np.dot(lk.skin_rgb, [0.299, 0.587, 0.114]) for lk in looks])
    assert lum.max() - lum.min() > 100, f"skin luminance spans only {lum.min():.0f}..{lum.max():.0f}"
    heights = np.array([lk.height_m for lk in looks])
    assert heights.min() >= 1.6 and heights.max() <= 1.9 and heights.std() > 0.05, heights
    _, _, c = people_mesh(looks[:2], np.zeros((2, 2)), np.zeros(2), np.zeros(2), np.zeros(2))
    a, b = c[:TRIANGLES_PER_PERSON], c[TRIANGLES_PER_PERSON:]
    assert (a != b).any(axis=1).mean() > 0.5, "two people's face colours are mostly identical"
    assert len(np.unique(a, axis=0)) == 5, "a person should show skin, shirt, trousers, shoes and hair"


def test_look_validation():
    with pytest.raises(ValueError, match="height_m"):
        HumanLook(2.3, (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="shirt_rgb"):
        HumanLook(1.7, (0, 0, 0), (0, 0, 300), (0, 0, 0), (0, 0, 0), (0, 0, 0))


def test_template_is_read_only():
    assert not humans._TEMPLATE_V.flags.writeable and not humans._TEMPLATE_F.flags.writeable
