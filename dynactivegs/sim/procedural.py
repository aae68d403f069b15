"""Seeded procedural indoor scenes: rooms joined by doors and corridors, textured walls,
floors and ceilings, and furniture that never blocks a door.

Named suites (DESIGN.md §4):

- ``tiny-NN``: one room, for tests.
- ``apartment-NN``: 4-6 rooms, about 60-100 m^2 (like the paper's Gibson scenes).
- ``house-NN``: 8-12 rooms, about 150-250 m^2 (like its Matterport3D scenes).
- ``loop-NN``: the floor plan of ``apartment-NN`` (the same rooms and corridor) with a door in
  every wall that two rooms share over at least 1.4 m (bathrooms included), so the free
  space has ways round: two routes between rooms, where a planner that avoids busy edges
  has a choice (the apartments' rooms mostly hang off one corridor by one door each).

``NN`` is a two-digit instance number; ``-00`` .. ``-07`` are the standard instances used by
benchmarks. A scene depends only on its name: the same name always gives the same mesh.
"""

from __future__ import annotations

import re
import zlib
from dataclasses import dataclass

import numpy as np

from dynactivegs.errors import SceneError
from dynactivegs.rng import derive_rng
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.scene import Scene, ScenePart, TriplanarMaterials
from dynactivegs.sim.textures import Material, make_material

SUITES = {
    "tiny": dict(rooms=(1, 1), area_m2=(16.0, 26.0), corridor_prob=0.0, extra_door_prob=0.2, bath_extra=False),
    "apartment": dict(rooms=(4, 6), area_m2=(62.0, 96.0), corridor_prob=0.5, extra_door_prob=0.2, bath_extra=False),
    "house": dict(rooms=(8, 12), area_m2=(160.0, 240.0), corridor_prob=1.0, extra_door_prob=0.2, bath_extra=False),
    "loop": dict(rooms=(4, 6), area_m2=(62.0, 96.0), corridor_prob=0.5, extra_door_prob=1.0, bath_extra=True),
}
"""Per suite: the room count and floor area ranges, the chance of a corridor, the chance of each further door in
a shared wall (beyond the doors that connect the rooms), and whether bathrooms get such further doors."""
STANDARD_INSTANCES = {suite: tuple(f"{suite}-{i:02d}" for i in range(8)) for suite in SUITES}

WALL_T_M = 0.10            # interior wall thickness (each room contributes half)
DOOR_H_M = 2.10            # door opening height
MIN_ROOM_SIDE_M = 2.4      # no room narrower than this
DOOR_KEEPOUT_M = 1.0       # furniture stays this far from a door, on both sides
CHECK_RADIUS_M = 0.3       # every room must stay reachable for a body of this radius (a person)
_NAME_RE = re.compile(r"^(tiny|apartment|house|loop)-(\d{2})$")


@dataclass(frozen=True)
class Room:
    """An axis-aligned room; its walls are on the rectangle's edges."""

    name: str
    kind: str                     # living, kitchen, bedroom, office, bathroom, corridor
    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def area_m2(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    def inner(self, margin: float = WALL_T_M / 2) -> tuple[float, float, float, float]:
        return self.x0 + margin, self.y0 + margin, self.x1 - margin, self.y1 - margin

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """bool (N,): the points (N, 2) inside the rectangle, its edges included."""
        return (xy[:, 0] >= self.x0) & (xy[:, 0] <= self.x1) & (xy[:, 1] >= self.y0) & (xy[:, 1] <= self.y1)

    def door_sides(self, doors, rooms) -> frozenset[int]:
        """The walls of this room that hold one of ``doors`` (``Door`` s indexing ``rooms``): 0 south, 1 north,
        2 west, 3 east."""
        sides = set()
        for d in doors:
            if self not in (rooms[d.rooms[0]], rooms[d.rooms[1]]):
                continue
            lo, hi = (self.x0, self.x1) if d.vertical else (self.y0, self.y1)
            near_hi = abs(d.line_m - hi) < abs(d.line_m - lo)
            sides.add((2 if d.vertical else 0) + int(near_hi))
        return frozenset(sides)


@dataclass(frozen=True)
class Door:
    """An opening in the wall line between two rooms."""

    rooms: tuple[int, int]
    vertical: bool                # True: the wall line is x = line_m; False: y = line_m
    line_m: float
    center_m: float               # position along the wall line
    width_m: float


def is_procedural_name(name: str) -> bool:
    return _NAME_RE.match(name) is not None


def make_scene(name: str) -> Scene:
    """The procedural scene called ``name`` (e.g. ``apartment-03``)."""
    m = _NAME_RE.match(name)
    if m is None:
        raise SceneError(f"unknown scene {name!r}: use tiny-NN, apartment-NN, house-NN or loop-NN (NN = 00..99), "
                         "or a path to a .glb/.gltf/.ply/.obj mesh")
    suite = m.group(1)
    plan = f"apartment-{m.group(2)}" if suite == "loop" else name   # loop-NN: apartment-NN's rooms, more doors
    rng = derive_rng(zlib.crc32(plan.encode()), "procedural-scene")
    return _Generator(name, suite, rng).build()


# ---------------------------------------------------------------------------------------------
# Mesh assembly
# ---------------------------------------------------------------------------------------------
_BOX_FACES = np.array([
    [0, 2, 1], [0, 3, 2],   # z-
    [4, 5, 6], [4, 6, 7],   # z+
    [0, 1, 5], [0, 5, 4],   # y-
    [2, 3, 7], [2, 7, 6],   # y+
    [1, 2, 6], [1, 6, 5],   # x+
    [3, 0, 4], [3, 4, 7],   # x-
], dtype=np.int32)


def _unit_cylinder(sections: int = 12) -> tuple[np.ndarray, np.ndarray]:
    a = 2 * np.pi * np.arange(sections) / sections
    ring = np.stack([np.cos(a), np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.zeros(sections)], np.c_[ring, np.ones(sections)],
                        [[0, 0, 0], [0, 0, 1]]])
    f = []
    for i in range(sections):
        j = (i + 1) % sections
        f += [[i, j, sections + j], [i, sections + j, sections + i]]
        f += [[2 * sections, j, i], [2 * sections + 1, sections + i, sections + j]]
    return v, np.array(f, dtype=np.int32)


def _unit_sphere() -> tuple[np.ndarray, np.ndarray]:
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
         [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
         [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    faces = np.array(f, dtype=np.int32)
    # one loop subdivision step, projected to the sphere
    verts = list(v)
    cache: dict[tuple[int, int], int] = {}

    def mid(a: int, b: int) -> int:
        key = (min(a, b), max(a, b))
        if key not in cache:
            p = verts[a] + verts[b]
            verts.append(p / np.linalg.norm(p))
            cache[key] = len(verts) - 1
        return cache[key]

    out = []
    for a, b, c in faces:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
    return np.array(verts), np.array(out, dtype=np.int32)


_CYL = _unit_cylinder()
_SPH = _unit_sphere()


class _MeshBuilder:
    """Collects primitives with a material index per face."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.verts: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.face_mat: list[np.ndarray] = []
        self.materials: list[Material] = []
        self.n_verts = 0

    def material(self, category: str) -> int:
        self.materials.append(make_material(category, self.rng))
        return len(self.materials) - 1

    def _add(self, v: np.ndarray, f: np.ndarray, mat: int) -> None:
        self.verts.append(v)
        self.faces.append(f + self.n_verts)
        self.face_mat.append(np.full(len(f), mat, dtype=np.int32))
        self.n_verts += len(v)

    def box(self, lo, hi, mat: int) -> None:
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        if np.any(hi - lo <= 1e-6):
            return
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                      [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]])
        self._add(v, _BOX_FACES, mat)

    def cylinder(self, cx: float, cy: float, z0: float, z1: float, r: float, mat: int) -> None:
        v, f = _CYL
        self._add(np.c_[v[:, 0] * r + cx, v[:, 1] * r + cy, v[:, 2] * (z1 - z0) + z0], f, mat)

    def sphere(self, c, r: float, mat: int) -> None:
        v, f = _SPH
        self._add(v * r + np.asarray(c), f, mat)

    def mesh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return np.concatenate(self.verts), np.concatenate(self.faces), np.concatenate(self.face_mat)


# ---------------------------------------------------------------------------------------------
# Furniture: pieces are described in a local frame (x along the wall, y from the wall into the
# room, z up) and placed with a rotation by a multiple of 90 degrees.
# ---------------------------------------------------------------------------------------------
@dataclass
class _Prim:
    kind: str                     # box | cyl | sphere
    a: np.ndarray                 # box: lo corner; cyl: (cx, cy, z0); sphere: centre
    b: np.ndarray                 # box: hi corner; cyl: (z1, r, 0); sphere: (r, 0, 0)
    mat: int


@dataclass
class _Piece:
    name: str
    width_m: float                # along the wall (local x), centred on 0
    depth_m: float                # from the wall (local y from 0)
    prims: list[_Prim]
    obstacle: bool = True         # rugs and wall art are not obstacles for placement


class _Furnisher:
    def __init__(self, mb: _MeshBuilder, rng: np.random.Generator) -> None:
        self.mb = mb
        self.rng = rng

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    @staticmethod
    def box(prims: list[_Prim], lo, hi, mat: int) -> None:
        prims.append(_Prim("box", np.asarray(lo, float), np.asarray(hi, float), mat))

    def legs(self, prims: list[_Prim], w: float, y0: float, y1: float, h: float, t: float, mat: int) -> None:
        for x in (-w / 2, w / 2 - t):
            for y in (y0, y1 - t):
                self.box(prims, (x, y, 0), (x + t, y + t, h), mat)

    def table(self, w: float, d: float, h: float, wood: int | None = None) -> _Piece:
        wood = self.mb.material("wood") if wood is None else wood
        p: list[_Prim] = []
        self.box(p, (-w / 2, 0, h - 0.04), (w / 2, d, h), wood)
        self.legs(p, w - 0.08, 0.04, d - 0.04, h - 0.04, 0.05, wood)
        return _Piece("table", w, d, p)

    def chair(self) -> _Piece:
        wood = self.mb.material(self.rng.choice(["wood", "paint"]))
        seat = self.mb.material("fabric")
        w = self.u(0.42, 0.5)
        p: list[_Prim] = []
        self.box(p, (-w / 2, 0, 0.42), (w / 2, w, 0.47), seat)
        self.legs(p, w, 0, w, 0.42, 0.04, wood)
        self.box(p, (-w / 2, 0, 0.47), (w / 2, 0.05, self.u(0.85, 1.0)), wood)
        return _Piece("chair", w, w, p)

    def bed(self) -> _Piece:
        w = self.u(1.4, 1.8)
        d = self.u(1.95, 2.1)
        frame, sheet, blanket, pillow = (self.mb.material("wood"), self.mb.material("paint"),
                                         self.mb.material("fabric"), self.mb.material("fabric"))
        p: list[_Prim] = []
        self.box(p, (-w / 2, 0, 0), (w / 2, d, 0.3), frame)
        self.box(p, (-w / 2 + 0.03, 0.05, 0.3), (w / 2 - 0.03, d - 0.03, 0.52), sheet)
        self.box(p, (-w / 2, 0, 0), (w / 2, 0.08, self.u(0.9, 1.15)), frame)
        self.box(p, (-w / 2 + 0.01, d * 0.4, 0.52), (w / 2 - 0.01, d - 0.01, 0.58), blanket)
        for s in (-1, 1):
            cx = s * w / 4
            self.box(p, (cx - w / 5, 0.12, 0.52), (cx + w / 5, 0.5, 0.66), pillow)
        return _Piece("bed", w, d, p)

    def sofa(self) -> _Piece:
        w = self.u(1.7, 2.3)
        d = self.u(0.85, 0.95)
        cover, cushion = self.mb.material("fabric"), self.mb.material("fabric")
        p: list[_Prim] = []
        self.box(p, (-w / 2, 0, 0.05), (w / 2, d, 0.42), cover)
        self.box(p, (-w / 2, 0, 0.42), (w / 2, 0.22, self.u(0.8, 0.9)), cover)
        for s in (-1, 1):
            x0 = s * w / 2 - (0.18 if s > 0 else 0)
            self.box(p, (x0, 0, 0.42), (x0 + 0.18, d, 0.62), cover)
        n = int(self.rng.integers(2, 4))
        cw = (w - 0.36) / n
        for i in range(n):
            x0 = -w / 2 + 0.18 + i * cw
            self.box(p, (x0 + 0.01, 0.22, 0.42), (x0 + cw - 0.01, d - 0.02, 0.52), cushion)
        self.legs(p, w - 0.1, 0.05, d - 0.05, 0.05, 0.05, self.mb.material("wood"))
        return _Piece("sofa", w, d, p)

    def shelf(self) -> _Piece:
        w = self.u(0.8, 1.3)
        d = self.u(0.3, 0.4)
        h = self.u(1.6, 2.1)
        wood = self.mb.material("wood")
        p: list[_Prim] = []
        for x in (-w / 2, w / 2 - 0.03):
            self.box(p, (x, 0, 0), (x + 0.03, d, h), wood)
        self.box(p, (-w / 2, 0, 0), (w / 2, 0.02, h), wood)
        n = int(self.rng.integers(4, 6))
        book_mats = [self.mb.material(self.rng.choice(["paint", "fabric"])) for _ in range(3)]
        for k in range(n + 1):
            z = k * (h - 0.03) / n
            self.box(p, (-w / 2, 0, z), (w / 2, d, z + 0.03), wood)
            if k == n:
                break
            x = -w / 2 + 0.04
            while x < w / 2 - 0.1 and self.rng.random() < 0.93:
                bw = self.u(0.02, 0.06)
                bh = self.u(0.15, min(0.3, (h - 0.03) / n - 0.05))
                self.box(p, (x, 0.03, z + 0.03), (x + bw, d * self.u(0.6, 0.95), z + 0.03 + bh),
                         book_mats[int(self.rng.integers(3))])
                x += bw + 0.005
        return _Piece("shelf", w, d, p)

    def cabinet(self, name: str, w: float, d: float, h: float) -> _Piece:
        body, front = self.mb.material(self.rng.choice(["wood", "paint"])), self.mb.material("paint")
        p: list[_Prim] = []
        self.box(p, (-w / 2, 0, 0), (w / 2, d - 0.02, h), body)
        n = max(1, int(round(w / 0.5)))
        for i in range(n):
            x0 = -w / 2 + i * w / n
            self.box(p, (x0 + 0.01, d - 0.02, 0.05), (x0 + w / n - 0.01, d, h - 0.02), front)
        return _Piece(name, w, d, p)

    def counter(self, length: float) -> _Piece:
        piece = self.cabinet("counter", length, 0.6, 0.88)
        top = self.mb.material(self.rng.choice(["metal", "paint"]))
        self.box(piece.prims, (-length / 2, 0, 0.88), (length / 2, 0.62, 0.92), top)
        upper = self.mb.material("paint")
        self.box(piece.prims, (-length / 2, 0, 1.55), (length / 2, 0.35, 2.2), upper)
        return piece

    def plant(self) -> _Piece:
        pot, leaf = self.mb.material("paint"), self.mb.material("plant")
        r = self.u(0.15, 0.22)
        h = self.u(0.3, 0.45)
        p: list[_Prim] = [_Prim("cyl", np.array([0, r + 0.02, 0.0]), np.array([h, r, 0]), pot)]
        p.append(_Prim("sphere", np.array([0, r + 0.02, h + r * 1.3]), np.array([r * 1.6, 0, 0]), leaf))
        return _Piece("plant", 2 * r + 0.1, 2 * r + 0.1, p)

    def lamp(self) -> _Piece:
        base, shade = self.mb.material("metal"), self.mb.material("fabric")
        h = self.u(1.3, 1.7)
        p = [_Prim("cyl", np.array([0, 0.2, 0.0]), np.array([0.03, 0.15, 0]), base),
             _Prim("cyl", np.array([0, 0.2, 0.03]), np.array([h, 0.015, 0]), base),
             _Prim("cyl", np.array([0, 0.2, h - 0.05]), np.array([h + 0.22, 0.18, 0]), shade)]
        return _Piece("lamp", 0.4, 0.4, p)

    def rug(self, w: float, d: float) -> _Piece:
        p = [_Prim("box", np.array([-w / 2, 0, 0]), np.array([w / 2, d, 0.012]), self.mb.material("fabric"))]
        return _Piece("rug", w, d, p, obstacle=False)

    def art(self) -> _Piece:
        w = self.u(0.4, 1.1)
        h = self.u(0.35, 0.8)
        z0 = self.u(1.15, 1.5)
        frame = self.mb.material(self.rng.choice(["wood", "metal"]))
        p = [_Prim("box", np.array([-w / 2, 0, z0]), np.array([w / 2, 0.025, z0 + h]), frame),
             _Prim("box", np.array([-w / 2 + 0.04, 0.025, z0 + 0.04]), np.array([w / 2 - 0.04, 0.03, z0 + h - 0.04]),
                   self.mb.material("paint"))]
        return _Piece("art", w, 0.03, p, obstacle=False)

    def toilet(self) -> _Piece:
        white = self.mb.material("paint")
        p = [_Prim("box", np.array([-0.2, 0, 0]), np.array([0.2, 0.2, 0.8]), white),
             _Prim("cyl", np.array([0, 0.42, 0.0]), np.array([0.42, 0.2, 0]), white)]
        return _Piece("toilet", 0.42, 0.64, p)

    def tv(self) -> _Piece:
        piece = self.cabinet("tv_stand", self.u(1.2, 1.8), 0.42, 0.5)
        screen = self.mb.material("metal")
        self.box(piece.prims, (-0.55, 0.12, 0.55), (0.55, 0.17, 1.2), screen)
        return piece


_ROOM_PLAN = {
    # kind -> list of (piece, placement) in the order they are tried; "wall" pieces stand
    # against a wall, "center" pieces in the middle, "corner" against a wall near a corner.
    "living": [("sofa", "wall"), ("tv", "wall"), ("coffee_table", "center"), ("shelf", "wall"),
               ("armchair", "wall"), ("plant", "corner"), ("lamp", "corner"), ("rug", "center"),
               ("art", "wall"), ("art", "wall")],
    "kitchen": [("counter", "wall"), ("fridge", "corner"), ("dining", "center"), ("shelf", "wall"),
                ("plant", "corner"), ("art", "wall")],
    "bedroom": [("bed", "wall"), ("wardrobe", "wall"), ("nightstand", "wall"), ("desk", "wall"),
                ("plant", "corner"), ("rug", "center"), ("art", "wall"), ("lamp", "corner")],
    "office": [("desk", "wall"), ("shelf", "wall"), ("shelf", "wall"), ("armchair", "wall"),
               ("plant", "corner"), ("art", "wall"), ("lamp", "corner")],
    "bathroom": [("bathtub", "wall"), ("sink", "wall"), ("toilet", "wall"), ("art", "wall")],
    "corridor": [("art", "wall"), ("art", "wall"), ("art", "wall")],
}


# ---------------------------------------------------------------------------------------------
# Generator
# ---------------------------------------------------------------------------------------------
class _Generator:
    def __init__(self, name: str, suite: str, rng: np.random.Generator) -> None:
        self.name = name
        self.suite = suite
        self.rng = rng
        self.params = SUITES[suite]
        self.wall_h = float(rng.uniform(2.5, 2.8))
        self.mb = _MeshBuilder(rng)
        self.furn = _Furnisher(self.mb, rng)

    # ---------------- layout
    def _split(self, rect: tuple[float, float, float, float], k: int) -> list[tuple[float, float, float, float]]:
        if k <= 1:
            return [rect]
        x0, y0, x1, y1 = rect
        w, h = x1 - x0, y1 - y0
        k1 = int(self.rng.integers(1, k))
        frac = k1 / k
        options = []
        if w >= 2 * MIN_ROOM_SIDE_M:
            options.append("x")
        if h >= 2 * MIN_ROOM_SIDE_M:
            options.append("y")
        if not options:
            return [rect]
        axis = "x" if (w >= h and "x" in options) or options == ["x"] else "y"
        if len(options) == 2 and self.rng.random() < 0.2:
            axis = "y" if axis == "x" else "x"
        lo, length = (x0, w) if axis == "x" else (y0, h)
        cut = lo + length * float(np.clip(frac * self.rng.uniform(0.85, 1.15), MIN_ROOM_SIDE_M / length,
                                          1 - MIN_ROOM_SIDE_M / length))
        cut = round(cut * 20) / 20  # walls on a 5 cm grid
        if axis == "x":
            return self._split((x0, y0, cut, y1), k1) + self._split((cut, y0, x1, y1), k - k1)
        return self._split((x0, y0, x1, cut), k1) + self._split((x0, cut, x1, y1), k - k1)

    def layout(self) -> tuple[list[Room], list[Door]]:
        rng = self.rng
        n = int(rng.integers(self.params["rooms"][0], self.params["rooms"][1] + 1))
        area = float(rng.uniform(*self.params["area_m2"]))
        aspect = float(rng.uniform(1.0, 1.6)) if n > 1 else float(rng.uniform(1.0, 1.4))
        width = round(np.sqrt(area * aspect) * 20) / 20
        depth = round(area / width * 20) / 20
        rects: list[tuple[float, float, float, float]] = []
        corridor = None
        if rng.random() < self.params["corridor_prob"]:
            cw = round(float(rng.uniform(1.2, 1.6)) * 20) / 20
            yc = round(float(depth * rng.uniform(0.4, 0.6) - cw / 2) * 20) / 20
            corridor = (0.0, yc, width, yc + cw)
            below = (0.0, 0.0, width, yc)
            above = (0.0, yc + cw, width, depth)
            n_below = max(1, int(round(n * yc / (depth - cw))))
            n_above = max(1, n - n_below)
            rects = self._split(below, n_below) + self._split(above, n_above)
        else:
            rects = self._split((0.0, 0.0, width, depth), n)
        kinds = self._room_kinds(rects)
        rooms = [Room(f"{k}-{i}", k, *r) for i, (k, r) in enumerate(zip(kinds, rects))]
        if corridor is not None:
            rooms.append(Room(f"corridor-{len(rooms)}", "corridor", *corridor))
        return rooms, self._doors(rooms)

    def _room_kinds(self, rects: list[tuple[float, float, float, float]]) -> list[str]:
        n = len(rects)
        if n == 1:
            return [str(self.rng.choice(["living", "bedroom", "office", "kitchen"]))]
        order = np.argsort([-(r[2] - r[0]) * (r[3] - r[1]) for r in rects], kind="stable")
        kinds = [""] * n
        n_bath = 1 if n <= 6 else 2
        for rank, idx in enumerate(order):
            if rank == 0:
                kinds[idx] = "living"
            elif rank == 1:
                kinds[idx] = "kitchen"
            elif rank >= n - n_bath:
                kinds[idx] = "bathroom"
            else:
                kinds[idx] = "bedroom" if rank % 3 != 0 else "office"
        return kinds

    def _doors(self, rooms: list[Room]) -> list[Door]:
        rng = self.rng
        adj: list[tuple[int, int, bool, float, float, float]] = []
        for i, a in enumerate(rooms):
            for j in range(i + 1, len(rooms)):
                b = rooms[j]
                for vertical, line, lo, hi in self._shared_edge(a, b):
                    if hi - lo >= 1.4:
                        adj.append((i, j, vertical, line, lo, hi))
        corridor = [i for i, r in enumerate(rooms) if r.kind == "corridor"]
        chosen: list[int] = []
        parent = list(range(len(rooms)))

        def find(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        def take(k: int) -> None:
            i, j = adj[k][:2]
            parent[find(i)] = find(j)
            chosen.append(k)

        for k, (i, j, *_r) in enumerate(adj):
            if corridor and (i in corridor or j in corridor) and find(i) != find(j):
                take(k)
        for k in rng.permutation(len(adj)):
            i, j = adj[k][:2]
            if find(i) != find(j):
                take(int(k))
        for k in range(len(adj)):
            i, j = adj[k][:2]
            if (k not in chosen and rng.random() < self.params["extra_door_prob"]
                    and (self.params["bath_extra"] or "bathroom" not in (rooms[i].kind, rooms[j].kind))):
                chosen.append(k)
        doors = []
        for k in sorted(chosen):
            i, j, vertical, line, lo, hi = adj[k]
            w = round(float(rng.uniform(0.9, 1.0)) * 100) / 100
            margin = 0.25 + w / 2
            c = float(rng.uniform(lo + margin, hi - margin))
            doors.append(Door((i, j), vertical, line, c, w))
        return doors

    @staticmethod
    def _shared_edge(a: Room, b: Room):
        eps = 1e-6
        for xa in (a.x0, a.x1):
            for xb in (b.x0, b.x1):
                if abs(xa - xb) < eps and ((xa == a.x1) != (xb == b.x1)):
                    yield True, xa, max(a.y0, b.y0), min(a.y1, b.y1)
        for ya in (a.y0, a.y1):
            for yb in (b.y0, b.y1):
                if abs(ya - yb) < eps and ((ya == a.y1) != (yb == b.y1)):
                    yield False, ya, max(a.x0, b.x0), min(a.x1, b.x1)

    # ---------------- architecture
    def walls_floors(self, rooms: list[Room], doors: list[Door]) -> list[np.ndarray]:
        """Adds floors, ceilings and walls; returns the obstacle footprints of the walls (x0, y0, x1, y1)."""
        mb = self.mb
        t = WALL_T_M / 2
        h = self.wall_h
        ceiling = mb.material("ceiling")
        footprints = []
        for ri, room in enumerate(rooms):
            floor = mb.material("floor")
            wall = mb.material("wall")
            mb.box((room.x0, room.y0, -0.05), (room.x1, room.y1, 0.0), floor)
            mb.box((room.x0, room.y0, h), (room.x1, room.y1, h + 0.05), ceiling)
            # each edge: (vertical, line, lo, hi, inner side sign)
            edges = [(False, room.y0, room.x0, room.x1, +1), (False, room.y1, room.x0, room.x1, -1),
                     (True, room.x0, room.y0, room.y1, +1), (True, room.x1, room.y0, room.y1, -1)]
            for vertical, line, lo, hi, side in edges:
                gaps = sorted((d.center_m - d.width_m / 2, d.center_m + d.width_m / 2) for d in doors
                              if ri in d.rooms and d.vertical == vertical and abs(d.line_m - line) < 1e-6)
                a0 = line if side > 0 else line - t
                a1 = line + t if side > 0 else line
                pieces: list[tuple[float, float, float, float]] = []  # (lo, hi, z0, z1)
                cur = lo
                for g0, g1 in gaps:
                    pieces.append((cur, g0, 0.0, h))
                    pieces.append((g0, g1, DOOR_H_M, h))
                    cur = g1
                pieces.append((cur, hi, 0.0, h))
                for s0, s1, z0, z1 in pieces:
                    if vertical:
                        lo3, hi3 = (a0, s0, z0), (a1, s1, z1)
                    else:
                        lo3, hi3 = (s0, a0, z0), (s1, a1, z1)
                    mb.box(lo3, hi3, wall)
                    if z0 == 0.0:
                        footprints.append(np.array([lo3[0], lo3[1], hi3[0], hi3[1]]))
        return footprints

    # ---------------- furniture
    def furnish(self, rooms: list[Room], doors: list[Door], wall_fps: list[np.ndarray]) -> None:
        placed: list[tuple[int, np.ndarray, list[_Prim]]] = []   # (room, footprint, world prims)
        keepouts = self._door_keepouts(rooms, doors)
        for ri, room in enumerate(rooms):
            plan = list(_ROOM_PLAN[room.kind])
            if self.suite == "tiny":
                plan = plan[:6]
            for piece_name, where in plan:
                for _attempt in range(12):
                    pieces = self._make_piece(piece_name)
                    if pieces is None:
                        break
                    result = self._place(room, pieces[0], where, keepouts, [p[1] for p in placed if p[1] is not None])
                    if result is None:
                        continue
                    fp, prims = result
                    placed.append((ri, fp if pieces[0].obstacle else None, prims))
                    for extra in pieces[1:]:   # chairs around a table
                        r2 = self._place_beside(room, fp, extra, keepouts,
                                                [p[1] for p in placed if p[1] is not None])
                        if r2 is not None:
                            placed.append((ri, r2[0], r2[1]))
                    break
        placed = self._keep_rooms_connected(rooms, doors, wall_fps, placed)
        for _ri, _fp, prims in placed:
            for pr in prims:
                if pr.kind == "box":
                    self.mb.box(pr.a, pr.b, pr.mat)
                elif pr.kind == "cyl":
                    self.mb.cylinder(pr.a[0], pr.a[1], pr.a[2], pr.b[0], pr.b[1], pr.mat)
                else:
                    self.mb.sphere(pr.a, pr.b[0], pr.mat)

    def _make_piece(self, name: str) -> list[_Piece] | None:
        f = self.furn
        if name == "sofa":
            return [f.sofa()]
        if name == "armchair":
            piece = f.sofa()
            return [_scale_piece_x(piece, f.u(0.8, 1.0))]
        if name == "tv":
            return [f.tv()]
        if name == "coffee_table":
            return [f.table(f.u(0.9, 1.2), f.u(0.5, 0.7), f.u(0.4, 0.48))]
        if name == "dining":
            w, d = f.u(1.2, 1.7), f.u(0.75, 0.95)
            table = f.table(w, d, 0.75)
            return [table] + [f.chair() for _ in range(int(self.rng.integers(2, 5)))]
        if name == "desk":
            desk = f.table(f.u(1.1, 1.5), f.u(0.55, 0.7), 0.75)
            f.box(desk.prims, (-0.3, 0.05, 0.75), (0.3, 0.09, 1.15), self.mb.material("metal"))
            return [desk, f.chair()]
        if name == "shelf":
            return [f.shelf()]
        if name == "plant":
            return [f.plant()]
        if name == "lamp":
            return [f.lamp()]
        if name == "rug":
            return [f.rug(f.u(1.4, 2.2), f.u(1.0, 1.6))]
        if name == "art":
            return [f.art()]
        if name == "bed":
            return [f.bed()]
        if name == "wardrobe":
            return [f.cabinet("wardrobe", f.u(1.0, 1.6), 0.6, f.u(1.9, 2.2))]
        if name == "nightstand":
            return [f.cabinet("nightstand", 0.45, 0.4, 0.55)]
        if name == "counter":
            return [f.counter(f.u(1.6, 2.8))]
        if name == "fridge":
            return [f.cabinet("fridge", 0.7, 0.7, 1.85)]
        if name == "bathtub":
            tub = f.cabinet("bathtub", f.u(1.5, 1.7), 0.75, 0.55)
            return [tub]
        if name == "sink":
            sink = f.cabinet("sink", f.u(0.6, 0.9), 0.5, 0.85)
            f.box(sink.prims, (-0.25, 0.0, 1.2), (0.25, 0.03, 1.8), self.mb.material("metal"))
            return [sink]
        if name == "toilet":
            return [f.toilet()]
        raise AssertionError(name)

    def _door_keepouts(self, rooms: list[Room], doors: list[Door]) -> list[np.ndarray]:
        out = []
        for d in doors:
            half = d.width_m / 2 + 0.2
            if d.vertical:
                out.append(np.array([d.line_m - DOOR_KEEPOUT_M, d.center_m - half, d.line_m + DOOR_KEEPOUT_M,
                                     d.center_m + half]))
            else:
                out.append(np.array([d.center_m - half, d.line_m - DOOR_KEEPOUT_M, d.center_m + half,
                                     d.line_m + DOOR_KEEPOUT_M]))
        return out

    def _place(self, room: Room, piece: _Piece, where: str, keepouts, others):
        ix0, iy0, ix1, iy1 = room.inner()
        w, d = piece.width_m, piece.depth_m
        rng = self.rng
        if where == "center":
            rot = int(rng.integers(0, 2))
            ext = (w, d) if rot == 0 else (d, w)
            if ix1 - ix0 < ext[0] + 1.4 or iy1 - iy0 < ext[1] + 1.4:
                return None
            cx = float(rng.uniform(ix0 + 0.7 + ext[0] / 2, ix1 - 0.7 - ext[0] / 2))
            cy = float(rng.uniform(iy0 + 0.7 + ext[1] / 2, iy1 - 0.7 - ext[1] / 2))
            # local origin is the middle of the back edge: move so the footprint is centred
            return self._commit(piece, rot * 2, cx, cy, centered=True, keepouts=keepouts, others=others,
                                check_keepouts=piece.obstacle)
        wall = int(rng.integers(0, 4))  # 0: y0 wall, facing +y; 1: x1 wall, facing -x; 2: y1; 3: x0
        length = (ix1 - ix0) if wall in (0, 2) else (iy1 - iy0)
        if length < w + 0.02:
            return None
        if where == "corner":
            s = float(rng.choice([w / 2 + 0.01, length - w / 2 - 0.01]))
        else:
            s = float(rng.uniform(w / 2 + 0.01, length - w / 2 - 0.01))
        if wall == 0:
            ox, oy = ix0 + s, iy0
        elif wall == 1:
            ox, oy = ix1, iy0 + s
        elif wall == 2:
            ox, oy = ix1 - s, iy1
        else:
            ox, oy = ix0, iy1 - s
        return self._commit(piece, wall, ox, oy, centered=False, keepouts=keepouts, others=others,
                            check_keepouts=True)

    def _place_beside(self, room: Room, table_fp: np.ndarray, chair: _Piece, keepouts, others):
        x0, y0, x1, y1 = table_fp
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        # candidate chair spots: middle of each side, chair back away from the table
        spots = [(cx, y0 - 0.05, 0), (cx, y1 + 0.05, 2), (x0 - 0.05, cy, 3), (x1 + 0.05, cy, 1)]
        for k in self.rng.permutation(4):
            sx, sy, side = spots[k]
            # the chair's local +y (its front) must point at the table: rotation faces into the room
            rot = side
            back = {0: (0, -chair.depth_m), 2: (0, chair.depth_m), 3: (-chair.depth_m, 0), 1: (chair.depth_m, 0)}[side]
            r = self._commit(chair, rot, sx + back[0], sy + back[1], centered=False, keepouts=keepouts,
                             others=others, check_keepouts=True)
            if r is not None and _inside(r[0], room.inner()):
                return r
        return None

    def _commit(self, piece: _Piece, rot: int, ox: float, oy: float, *, centered: bool, keepouts, others,
                check_keepouts: bool):
        prims = [_transform_prim(p, rot, ox, oy, piece.depth_m if centered else 0.0) for p in piece.prims]
        fp = _footprint(prims)
        if check_keepouts and any(_overlap(fp, k, 0.0) for k in keepouts):
            return None
        if piece.obstacle and any(_overlap(fp, o, 0.05) for o in others):
            return None
        return fp, prims

    def _keep_rooms_connected(self, rooms, doors, wall_fps, placed):
        """Drops furniture (last placed first) until every room and door is reachable for a person."""
        res = 0.05
        while True:
            fs = _raster_freespace(rooms, wall_fps + [fp for _r, fp, _p in placed if fp is not None], res)
            nav = fs.navigable(CHECK_RADIUS_M)
            bad_rooms = set()
            for ri, room in enumerate(rooms):
                x0, y0, x1, y1 = room.inner()
                ij0 = fs.world_to_cell(np.array([x0, y0]))
                ij1 = fs.world_to_cell(np.array([x1, y1]))
                if not nav[ij0[0]:ij1[0] + 1, ij0[1]:ij1[1] + 1].any():
                    bad_rooms.add(ri)
            for d in doors:
                c = np.array([d.line_m, d.center_m]) if d.vertical else np.array([d.center_m, d.line_m])
                if not fs.is_navigable(c, CHECK_RADIUS_M):
                    bad_rooms.update(d.rooms)
            if not bad_rooms:
                return placed
            removable = [k for k, (ri, fp, _p) in enumerate(placed) if ri in bad_rooms and fp is not None]
            if not removable:
                raise SceneError(f"scene {self.name}: generated layout is not connected; this is a bug, "
                                 "please report the scene name")
            placed = placed[:removable[-1]] + placed[removable[-1] + 1:]

    # ---------------- assembly
    def build(self) -> Scene:
        rooms, doors = self.layout()
        wall_fps = self.walls_floors(rooms, doors)
        self.furnish(rooms, doors, wall_fps)
        v, f, fm = self.mb.mesh()
        mats = self.mb.materials
        appearance = TriplanarMaterials(face_material=fm, textures=np.stack([m.texture for m in mats]),
                                        tile_m=np.array([m.tile_m for m in mats], dtype=np.float32))
        return Scene(name=self.name, vertices_m=v, faces=f, parts=(ScenePart(0, len(f), appearance),), lit=True,
                     rooms=tuple(rooms), doors=tuple(doors), wall_height_m=self.wall_h)


def _scale_piece_x(piece: _Piece, s: float) -> _Piece:
    prims = []
    for p in piece.prims:
        a, b = p.a.copy(), p.b.copy()
        if p.kind == "box":
            a[0] *= s
            b[0] *= s
        else:
            a[0] *= s
        prims.append(_Prim(p.kind, a, b, p.mat))
    return _Piece("armchair", piece.width_m * s, piece.depth_m, prims, piece.obstacle)


def _rot_xy(x, y, rot: int):
    """Rotate local (x along wall, y into room) by rot * 90 degrees counter-clockwise."""
    if rot == 0:
        return x, y
    if rot == 1:
        return -y, x
    if rot == 2:
        return -x, -y
    return y, -x


def _transform_prim(p: _Prim, rot: int, ox: float, oy: float, center_shift: float) -> _Prim:
    """Local -> world. ``center_shift`` moves a piece so its footprint is centred on the origin."""
    # The wall index maps to a rotation: wall 0 faces +y (rot 0), wall 1 faces -x (rot 1), ...
    if p.kind == "box":
        xs = [p.a[0], p.b[0]]
        ys = [p.a[1] - center_shift / 2, p.b[1] - center_shift / 2]
        pts = [_rot_xy(x, y, rot) for x in xs for y in ys]
        px = [q[0] + ox for q in pts]
        py = [q[1] + oy for q in pts]
        return _Prim("box", np.array([min(px), min(py), p.a[2]]), np.array([max(px), max(py), p.b[2]]), p.mat)
    x, y = _rot_xy(p.a[0], p.a[1] - center_shift / 2, rot)
    return _Prim(p.kind, np.array([x + ox, y + oy, p.a[2]]), p.b.copy(), p.mat)


def _footprint(prims: list[_Prim]) -> np.ndarray:
    lo = np.array([np.inf, np.inf])
    hi = -lo
    for p in prims:
        if p.kind == "box":
            plo, phi = p.a[:2], p.b[:2]
        else:
            r = p.b[1] if p.kind == "cyl" else p.b[0]
            plo, phi = p.a[:2] - r, p.a[:2] + r
        lo = np.minimum(lo, plo)
        hi = np.maximum(hi, phi)
    return np.array([lo[0], lo[1], hi[0], hi[1]])


def _overlap(a: np.ndarray, b: np.ndarray, margin: float) -> bool:
    return bool(a[0] < b[2] + margin and b[0] < a[2] + margin and a[1] < b[3] + margin and b[1] < a[3] + margin)


def _inside(fp: np.ndarray, rect: tuple[float, float, float, float]) -> bool:
    return fp[0] >= rect[0] - 1e-6 and fp[1] >= rect[1] - 1e-6 and fp[2] <= rect[2] + 1e-6 and fp[3] <= rect[3] + 1e-6


def _raster_freespace(rooms: list[Room], footprints: list[np.ndarray], res: float) -> FreeSpace:
    """A quick 2D free-space map from room rectangles (floor) and obstacle footprints."""
    x1 = max(r.x1 for r in rooms)
    y1 = max(r.y1 for r in rooms)
    origin = np.array([-2 * res, -2 * res])
    h = int(np.ceil((y1 - origin[1]) / res)) + 2
    w = int(np.ceil((x1 - origin[0]) / res)) + 2
    floor = np.zeros((h, w), bool)
    occ = np.zeros((h, w), bool)

    def cells(x0, y0, xa, ya):
        j0 = int(np.floor((x0 - origin[0]) / res))
        j1 = int(np.ceil((xa - origin[0]) / res))
        i0 = int(np.floor((y0 - origin[1]) / res))
        i1 = int(np.ceil((ya - origin[1]) / res))
        return slice(max(i0, 0), i1), slice(max(j0, 0), j1)

    for r in rooms:
        floor[cells(r.x0, r.y0, r.x1, r.y1)] = True
    for fp in footprints:
        occ[cells(*fp)] = True
    return FreeSpace(origin, res, floor, occ)
