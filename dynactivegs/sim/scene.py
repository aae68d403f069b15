"""The static scene: one triangle mesh in world coordinates (Z up, metres, floor at z = 0) and
its appearance.

A scene is made of *parts*, contiguous face ranges that share one way of giving albedo:

- :class:`TriplanarMaterials` (procedural scenes): each face has a material; the material's
  texture tile is sampled at world coordinates projected on the plane orthogonal to the
  face normal's dominant axis, so every surface has a pattern at a fixed metric scale.
- :class:`VertexColors` (Replica ``.ply``, coloured ``.obj``): barycentric interpolation.
- :class:`UVTexture` (``.glb`` / textured ``.obj``): texture image looked up at interpolated UVs.
- :class:`FaceColors`: one colour per face (plain materials of mesh files).

Shading is view-independent. Procedural scenes are lit by a fixed world light
(``lit=True``); mesh files are shown with their captured colours as they are.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba
import numpy as np


def _bary_interp(values: np.ndarray, faces: np.ndarray, face_idx: np.ndarray, bary_uv: np.ndarray) -> np.ndarray:
    """Interpolate per-vertex ``values (V, C)`` at hits given face indices ``(N,)`` and barycentric
    ``(u, v)`` ``(N, 2)`` w.r.t. vertices 1 and 2 of the face (Embree's convention)."""
    tri = faces[face_idx]
    u = bary_uv[:, 0:1]
    v = bary_uv[:, 1:2]
    return (1.0 - u - v) * values[tri[:, 0]] + u * values[tri[:, 1]] + v * values[tri[:, 2]]


@dataclass(frozen=True)
class TriplanarMaterials:
    """Per-face materials sampled by world-space planar projection."""

    face_material: np.ndarray     # int32 (F_part,), index into textures
    textures: np.ndarray          # uint8 (M, T, T, 3), tileable texture images
    tile_m: np.ndarray            # float32 (M,), world size of one texture tile in metres

    def albedo(self, scene: "Scene", local_face: np.ndarray, global_face: np.ndarray,
               bary_uv: np.ndarray, points_m: np.ndarray) -> np.ndarray:
        mat = self.face_material[local_face].astype(np.int64)
        axis = scene.face_dominant_axis[global_face]
        return _triplanar_lookup(np.ascontiguousarray(points_m, dtype=np.float64), axis, mat, self.textures,
                                 self.tile_m.astype(np.float64))


@numba.njit(cache=True, nogil=True)
def _triplanar_lookup(points_m, axis, mat, textures, tile_m):  # pragma: no cover - compiled
    """Texel of each hit: the tile coordinates are the two world coordinates orthogonal to the
    face normal's dominant axis (x -> (y, z), y -> (x, z), z -> (x, y)), nearest texel, wrapping."""
    n = points_m.shape[0]
    t = textures.shape[1]
    out = np.empty((n, 3), dtype=np.float32)
    for k in range(n):
        ax = axis[k]
        a = points_m[k, 1] if ax == 0 else points_m[k, 0]
        b = points_m[k, 1] if ax == 2 else points_m[k, 2]
        m = mat[k]
        scale = t / tile_m[m]
        ti = int(np.floor(b * scale)) % t
        tj = int(np.floor(a * scale)) % t
        for c in range(3):
            out[k, c] = textures[m, ti, tj, c] / np.float32(255.0)
    return out


@dataclass(frozen=True)
class VertexColors:
    """Per-vertex colours interpolated with barycentric coordinates."""

    colors: np.ndarray            # uint8 (V, 3) over the whole scene's vertices

    def albedo(self, scene: "Scene", local_face, global_face, bary_uv, points_m) -> np.ndarray:
        return _bary_interp(self.colors.astype(np.float32) / 255.0, scene.faces, global_face, bary_uv)


@dataclass(frozen=True)
class UVTexture:
    """A texture image sampled (nearest texel, wrapping) at interpolated per-vertex UVs."""

    uv: np.ndarray                # float32 (V, 2) over the whole scene's vertices, glTF/OBJ convention (v up)
    image: np.ndarray             # uint8 (h, w, 3)

    def albedo(self, scene: "Scene", local_face, global_face, bary_uv, points_m) -> np.ndarray:
        uv = _bary_interp(self.uv, scene.faces, global_face, bary_uv)
        h, w = self.image.shape[:2]
        col = np.floor(uv[:, 0] * w).astype(np.int64) % w
        row = np.floor((1.0 - uv[:, 1]) * h).astype(np.int64) % h
        return self.image[row, col].astype(np.float32) / 255.0


@dataclass(frozen=True)
class FaceColors:
    """One colour per face."""

    colors: np.ndarray            # uint8 (F_part, 3)

    def albedo(self, scene: "Scene", local_face, global_face, bary_uv, points_m) -> np.ndarray:
        return self.colors[local_face].astype(np.float32) / 255.0


Appearance = TriplanarMaterials | VertexColors | UVTexture | FaceColors


@dataclass(frozen=True)
class ScenePart:
    """Faces ``[face_start, face_stop)`` of the scene share ``appearance``."""

    face_start: int
    face_stop: int
    appearance: Appearance


@dataclass(frozen=True)
class Scene:
    """A static scene: the mesh the robot moves in, without people."""

    name: str
    vertices_m: np.ndarray        # float64 (V, 3), world frame, Z up, floor at z = 0
    faces: np.ndarray             # int32 (F, 3)
    parts: tuple[ScenePart, ...]
    lit: bool = True
    """Apply the fixed world light (procedural scenes) or show captured colours as they are."""
    rooms: tuple = ()
    """Procedural scenes: the rooms (``procedural.Room``), for plots and per-room statistics."""
    doors: tuple = ()
    """Procedural scenes: the doors (``procedural.Door``)."""
    wall_height_m: float = float("nan")
    """Procedural scenes: height of walls and ceiling."""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        assert self.vertices_m.ndim == 2 and self.vertices_m.shape[1] == 3
        assert self.faces.ndim == 2 and self.faces.shape[1] == 3
        starts = [p.face_start for p in self.parts]
        stops = [p.face_stop for p in self.parts]
        assert starts and starts[0] == 0 and stops[-1] == len(self.faces), "parts must cover all faces"
        assert all(a == b for a, b in zip(stops[:-1], starts[1:])), "parts must be contiguous"
        self.vertices_m.flags.writeable = False
        self.faces.flags.writeable = False

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def bounds_m(self) -> np.ndarray:
        """float64 (2, 3): min and max corner."""
        return np.stack([self.vertices_m.min(axis=0), self.vertices_m.max(axis=0)])

    @property
    def triangles_m(self) -> np.ndarray:
        """float64 (F, 3, 3)."""
        if "tri" not in self._cache:
            self._cache["tri"] = self.vertices_m[self.faces]
        return self._cache["tri"]

    @property
    def face_normals(self) -> np.ndarray:
        """float64 (F, 3) unit normals (zero for degenerate faces)."""
        if "normals" not in self._cache:
            tri = self.triangles_m
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            norm = np.linalg.norm(n, axis=1, keepdims=True)
            self._cache["normals"] = np.where(norm > 0, n / np.maximum(norm, 1e-300), 0.0)
        return self._cache["normals"]

    @property
    def face_dominant_axis(self) -> np.ndarray:
        """int8 (F,): index (0, 1, 2) of the largest absolute component of each face normal."""
        if "axis" not in self._cache:
            self._cache["axis"] = np.argmax(np.abs(self.face_normals), axis=1).astype(np.int8)
        return self._cache["axis"]

    @property
    def face_areas_m2(self) -> np.ndarray:
        if "areas" not in self._cache:
            tri = self.triangles_m
            self._cache["areas"] = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        return self._cache["areas"]

    def albedo(self, face_idx: np.ndarray, bary_uv: np.ndarray, points_m: np.ndarray) -> np.ndarray:
        """float32 (N, 3) albedo in [0, 1] at hits on faces ``(N,)`` with Embree barycentrics ``(N, 2)``."""
        if len(self.parts) == 1:
            return self.parts[0].appearance.albedo(self, face_idx, face_idx, bary_uv, points_m).astype(np.float32)
        out = np.empty((len(face_idx), 3), dtype=np.float32)
        if len(face_idx) == 0:
            return out
        stops = np.array([p.face_stop for p in self.parts])
        part_of = np.searchsorted(stops, face_idx, side="right")
        for k, part in enumerate(self.parts):
            sel = np.nonzero(part_of == k)[0]
            if len(sel):
                f = face_idx[sel]
                out[sel] = part.appearance.albedo(self, f - part.face_start, f, bary_uv[sel], points_m[sel])
        return out

    def sample_surface(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """``n`` points uniformly distributed over the surface area, and their face indices.

        Returns (points float64 (n, 3), face_idx int64 (n,)). People are never part of a scene.
        """
        areas = self.face_areas_m2
        cdf = np.cumsum(areas)
        face = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right").clip(0, len(areas) - 1)
        r1 = np.sqrt(rng.random(n))
        r2 = rng.random(n)
        tri = self.triangles_m[face]
        pts = (1 - r1)[:, None] * tri[:, 0] + (r1 * (1 - r2))[:, None] * tri[:, 1] + (r1 * r2)[:, None] * tri[:, 2]
        return pts, face
