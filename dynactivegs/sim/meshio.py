"""Loading real scene meshes (``.glb`` / ``.gltf``, ``.ply``, ``.obj``) into a :class:`Scene`.

The result is in the simulator's world frame: Z up, metres, floor at z = 0, and shown unlit
(``lit=False``) with the file's own colours:

- vertex colours (Replica ``.ply``, coloured ``.obj``, glTF ``COLOR_0``) -> :class:`VertexColors`;
- a texture image with UVs (glTF ``baseColorTexture``, OBJ ``map_Kd``) -> :class:`UVTexture`;
- otherwise the material's main colour or the face colours -> :class:`FaceColors`
  (grey when the file has no colour at all).

Up axis. glTF is Y-up (Habitat's ``.glb`` files included), so ``up_axis="auto"`` means ``y`` for
``.glb`` / ``.gltf`` and ``z`` for ``.ply`` / ``.obj`` (Replica). An explicit axis (``x``, ``y``,
``z``, ``-x``, ``-y``, ``-z``) is rotated onto world +Z by a proper rotation (no mirroring), e.g.
``y``: file ``(x, y, z)`` -> world ``(x, -z, y)``.

Floor. Unless ``floor_z_m`` is given, the floor is the lowest height holding a large share of
the upward-facing surface area (see :func:`infer_floor_z`); the scene is shifted so that it
lies at z = 0.

Every problem with the file is a one-line :class:`~dynactivegs.errors.SceneError`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dynactivegs.errors import ConfigError, SceneError
from dynactivegs.sim.scene import FaceColors, Scene, ScenePart, UVTexture, VertexColors

SUPPORTED_SUFFIXES = (".glb", ".gltf", ".ply", ".obj")
UP_AXES = ("x", "y", "z", "-x", "-y", "-z")

# Rotations taking the named file axis onto world +Z (rows: world x, y, z in file coordinates).
# All have determinant +1, so face winding and handedness are kept.
_UP_ROTATIONS = {
    "z": ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    "y": ((1, 0, 0), (0, 0, -1), (0, 1, 0)),      # glTF: (x, y, z) -> (x, -z, y)
    "x": ((0, 1, 0), (0, 0, 1), (1, 0, 0)),       # (x, y, z) -> (y, z, x)
    "-z": ((1, 0, 0), (0, -1, 0), (0, 0, -1)),    # (x, y, z) -> (x, -y, -z)
    "-y": ((1, 0, 0), (0, 0, 1), (0, -1, 0)),     # (x, y, z) -> (x, z, -y)
    "-x": ((0, 1, 0), (0, 0, -1), (-1, 0, 0)),    # (x, y, z) -> (y, -z, -x)
}

MAX_EXTENT_M = 300.0
"""Largest plausible horizontal extent of an indoor scene; beyond it the units are wrong."""
MIN_EXTENT_M = 1.0
"""Smallest plausible horizontal extent of an indoor scene."""
FLOOR_BIN_M = 0.05
"""Height resolution of the floor histogram."""
FLOOR_MIN_SHARE = 0.2
"""A height level is a floor candidate when it holds this share of the largest level's area."""
UP_NORMAL_MIN_Z = 0.9
"""Faces whose unit normal has z above this count as upward-facing (within ~26 deg of +Z)."""
DEFAULT_GREY = (128, 128, 128)


def up_rotation(up_axis: str) -> np.ndarray:
    """float64 (3, 3) rotation R with ``world = R @ file`` taking ``up_axis`` onto world +Z."""
    if up_axis not in _UP_ROTATIONS:
        raise ConfigError(f"sim.mesh_up_axis: {up_axis!r} is not an axis; use one of auto, {', '.join(UP_AXES)}")
    return np.array(_UP_ROTATIONS[up_axis], dtype=np.float64)


def load_mesh_scene(path: str | Path, *, up_axis: str = "auto", floor_z_m: float = math.nan,
                    scale: float = 1.0) -> Scene:
    """Load a scene mesh file as a :class:`Scene` (world Z up, metres, floor at z = 0, unlit).

    Args:
        path: a ``.glb``, ``.gltf``, ``.ply`` or ``.obj`` file (an ``.obj`` may bring its
            ``.mtl`` and texture images, a ``.gltf`` its buffers, next to it).
        up_axis: ``auto`` (``y`` for glTF, ``z`` otherwise) or one of x, y, z, -x, -y, -z:
            the file axis that points up (``sim.mesh_up_axis``).
        floor_z_m: floor height in metres after the up-axis rotation and scaling; NaN infers it
            (``sim.mesh_floor_z_m``).
        scale: multiplier from file units to metres, e.g. 0.001 for millimetres (``sim.mesh_scale``).

    Raises:
        SceneError: missing, unreadable, empty or non-mesh file, implausible size, no floor.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise SceneError(f"{path}: unsupported mesh format {path.suffix or '(no extension)'!r}; "
                         f"supported: {', '.join(SUPPORTED_SUFFIXES)}")
    if not path.is_file():
        raise SceneError(f"{path}: no such mesh file; check the path (sim.scene)")
    if up_axis == "auto":
        up_axis = "y" if suffix in (".glb", ".gltf") else "z"
    import trimesh  # deferred: procedural scenes do not need the mesh loaders

    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as exc:  # trimesh raises many kinds on malformed input
        raise SceneError(f"{path}: cannot be read as a {suffix} mesh ({type(exc).__name__}: "
                         f"{_one_line(exc)}); check that the file is complete and really {suffix}") from exc
    return scene_from_trimesh(loaded, path.stem, up_axis=up_axis, floor_z_m=floor_z_m, scale=scale,
                              source=str(path))


def scene_from_trimesh(mesh_or_scene, name: str, *, up_axis: str = "z", floor_z_m: float = math.nan,
                       scale: float = 1.0, source: str | None = None) -> Scene:
    """Build a :class:`Scene` from an in-memory ``trimesh.Trimesh`` or ``trimesh.Scene``.

    Node transforms of a ``trimesh.Scene`` are applied, then the up-axis rotation
    (``up_axis`` is an explicit axis here, see :func:`up_rotation`), then ``scale``, then the
    floor shift. Each geometry becomes one appearance; geometries are grouped by kind
    (vertex colours, face colours, each texture image) so that a scene has few parts.

    Args:
        mesh_or_scene: ``trimesh.Trimesh`` or ``trimesh.Scene`` (point clouds are rejected).
        name: the scene's name.
        up_axis, floor_z_m, scale: as in :func:`load_mesh_scene`.
        source: how to name the input in error messages (defaults to ``name``).
    """
    import trimesh

    where = source if source is not None else name
    rot = up_rotation(up_axis)
    if not (math.isfinite(scale) and scale > 0.0):
        raise ConfigError(f"sim.mesh_scale: {scale!r} is not a positive finite number; use e.g. 1.0 or 0.001")
    if isinstance(mesh_or_scene, trimesh.Trimesh):
        mesh_or_scene = trimesh.Scene(mesh_or_scene)
    if not isinstance(mesh_or_scene, trimesh.Scene):
        raise SceneError(f"{where}: expected a triangle mesh, got a {type(mesh_or_scene).__name__}; "
                         "give a mesh with faces")

    geoms = _flatten(mesh_or_scene, where)
    if not geoms:
        n_points = sum(len(g.vertices) for g in mesh_or_scene.geometry.values()
                       if isinstance(g, trimesh.PointCloud))
        if n_points:
            raise SceneError(f"{where}: has {n_points} points but no faces (a point cloud, not a mesh); "
                             "give a triangle mesh, e.g. reconstruct a surface from the points first")
        raise SceneError(f"{where}: contains no triangles (empty mesh); give a file with faces")

    vertices, faces, parts = _assemble(geoms)
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise SceneError(f"{where}: {bad} vertices have NaN or infinite coordinates; repair the mesh "
                         "(e.g. remove those vertices and their faces) and load it again")

    vertices = (vertices @ rot.T) * scale
    extent = float(np.max(vertices[:, :2].max(axis=0) - vertices[:, :2].min(axis=0)))
    if extent > MAX_EXTENT_M:
        raise SceneError(f"{where}: largest horizontal extent is {extent:.4g} m after scale {scale:g}, "
                         "too large for an indoor scene; looks like millimetres or centimetres: "
                         "pass mesh_scale=0.001 / 0.01 (sim.mesh_scale)")
    if extent < MIN_EXTENT_M:
        raise SceneError(f"{where}: largest horizontal extent is {extent:.4g} m after scale {scale:g}, "
                         "too small for an indoor scene; check units, pass mesh_scale (sim.mesh_scale), "
                         "and check the up axis (sim.mesh_up_axis)")

    if math.isnan(floor_z_m):
        floor_z_m = infer_floor_z(vertices, faces, where=where)
    elif not math.isfinite(floor_z_m):
        raise ConfigError(f"sim.mesh_floor_z_m: {floor_z_m!r} is not finite; give a height in metres or NaN to infer it")
    vertices[:, 2] -= floor_z_m
    return Scene(name=name, vertices_m=vertices, faces=faces, parts=tuple(parts), lit=False)


def infer_floor_z(vertices_m: np.ndarray, faces: np.ndarray, *, where: str = "mesh") -> float:
    """Floor height (m) of a Z-up mesh: the lowest level with a large upward-facing area.

    Faces whose unit normal has z > :data:`UP_NORMAL_MIN_Z` are binned by centroid height in
    :data:`FLOOR_BIN_M` bins, weighted by area. Adjacent-bin pairs are summed (so a floor on a
    bin edge is not split), and the lowest pair holding at least :data:`FLOOR_MIN_SHARE` of the
    largest pair's area is the floor level; the answer is the area-weighted median height of the
    upward faces in it. Table tops and beds hold far less area than the floor, and stray
    fragments below the floor far less again.

    Args:
        vertices_m: float64 (V, 3), Z up.
        faces: int (F, 3).

    Raises:
        SceneError: no upward-facing area at all, or most of the surface lies well below the
            level found (inverted face winding).
    """
    assert vertices_m.ndim == 2 and vertices_m.shape[1] == 3
    assert faces.ndim == 2 and faces.shape[1] == 3
    tri = vertices_m[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    nz = np.divide(cross[:, 2], area2, out=np.zeros_like(area2), where=area2 > 0)
    up = nz > UP_NORMAL_MIN_Z
    if not up.any():
        raise SceneError(f"{where}: no upward-facing surface to infer the floor from; "
                         "pass the floor height (sim.mesh_floor_z_m) or check the up axis (sim.mesh_up_axis)")
    z = tri[up, :, 2].mean(axis=1)
    w = 0.5 * area2[up]
    lo = float(z.min())
    n_bins = int(math.floor((float(z.max()) - lo) / FLOOR_BIN_M)) + 2
    idx = np.minimum(((z - lo) / FLOOR_BIN_M).astype(np.int64), n_bins - 2)
    hist = np.bincount(idx, weights=w, minlength=n_bins)
    pair = hist[:-1] + hist[1:]                       # pair k covers bins k and k + 1
    k = int(np.nonzero(pair >= FLOOR_MIN_SHARE * pair.max())[0][0])
    sel = (idx == k) | (idx == k + 1)
    order = np.argsort(z[sel], kind="stable")
    cw = np.cumsum(w[sel][order])
    floor = float(z[sel][order][np.searchsorted(cw, 0.5 * cw[-1])])

    # A scan or model seen from inside has (almost) nothing below its floor. With inverted
    # winding the ceiling faces up and would be taken for the floor: catch that here.
    all_areas = 0.5 * area2
    below = tri[:, :, 2].mean(axis=1) < floor - 0.5
    if all_areas[below].sum() > 0.5 * all_areas.sum():
        raise SceneError(f"{where}: most of the surface lies more than 0.5 m below the inferred floor "
                         f"z = {floor:.3f} m (inverted face winding?); pass the floor height (sim.mesh_floor_z_m)")
    return floor


# ----------------------------------------------------------------------------------------------
# Internals


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text[:200] if text else "no details"


class _Geom:
    """One geometry of the file in the file's frame after its node transform."""

    __slots__ = ("vertices", "faces", "kind", "colors", "uv", "image", "image_key")

    def __init__(self, vertices, faces, kind, colors=None, uv=None, image=None, image_key=None):
        self.vertices = vertices      # float64 (v, 3)
        self.faces = faces            # int64 (f, 3), local vertex indices
        self.kind = kind              # "vertex" | "face" | "texture"
        self.colors = colors          # uint8 (v, 3) for "vertex", (f, 3) for "face"
        self.uv = uv                  # float32 (v, 2) for "texture"
        self.image = image            # uint8 (h, w, 3) for "texture"
        self.image_key = image_key    # identity of the source image, to group faces sharing it


def _flatten(tscene, where: str) -> list[_Geom]:
    """Geometries of a ``trimesh.Scene`` with node transforms applied, unused vertices dropped."""
    import trimesh

    images: dict[tuple, np.ndarray] = {}
    out = []
    for node in tscene.graph.nodes_geometry:
        transform, geom_name = tscene.graph[node]
        mesh = tscene.geometry.get(geom_name)
        if not isinstance(mesh, trimesh.Trimesh):
            continue
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
        vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        if len(faces) == 0:
            continue
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise SceneError(f"{where}: geometry {geom_name!r} has face indices outside its "
                             f"{len(vertices)} vertices; the file is corrupt, re-export it")
        transform = np.asarray(transform, dtype=np.float64)
        vertices = vertices @ transform[:3, :3].T + transform[:3, 3]
        if np.linalg.det(transform[:3, :3]) < 0:      # a mirroring node: keep faces facing outwards
            faces = faces[:, [0, 2, 1]]
        geom = _appearance(mesh, vertices, faces, images, where)
        # Drop vertices no face uses (shared glTF buffers, stray points in scans).
        used, inverse = np.unique(geom.faces, return_inverse=True)
        geom.faces = inverse.reshape(-1, 3)
        geom.vertices = geom.vertices[used]
        if geom.kind == "vertex":
            geom.colors = geom.colors[used]
        elif geom.kind == "texture":
            geom.uv = geom.uv[used]
        out.append(geom)
    return out


def _appearance(mesh, vertices: np.ndarray, faces: np.ndarray, images: dict, where: str) -> _Geom:
    """Pick the appearance of one trimesh geometry (see the module docstring for the order)."""
    import trimesh

    visual = mesh.visual
    n_v, n_f = len(vertices), len(faces)
    if isinstance(visual, trimesh.visual.ColorVisuals):
        kind = visual.kind
        if kind == "vertex":
            colors = np.asarray(visual.vertex_colors, dtype=np.uint8)[:, :3]
            if colors.shape == (n_v, 3):
                return _Geom(vertices, faces, "vertex", colors=np.ascontiguousarray(colors))
        if kind == "face":
            colors = np.asarray(visual.face_colors, dtype=np.uint8)[:, :3]
            if colors.shape == (n_f, 3):
                return _Geom(vertices, faces, "face", colors=np.ascontiguousarray(colors))
        return _Geom(vertices, faces, "face", colors=np.tile(np.uint8(DEFAULT_GREY), (n_f, 1)))

    if isinstance(visual, trimesh.visual.TextureVisuals):
        material = visual.material
        uv = None if visual.uv is None else np.asarray(visual.uv, dtype=np.float64)
        image, factor = _material_image(material)
        if image is not None and uv is not None and uv.shape == (n_v, 2) and np.isfinite(uv).all():
            key = (id(image), tuple(factor))
            if key not in images:
                images[key] = _image_rgb(image, factor, where)
            return _Geom(vertices, faces, "texture", uv=uv.astype(np.float32), image=images[key], image_key=key)
        # glTF may carry COLOR_0 next to a material without a texture.
        vcol = (getattr(visual, "vertex_attributes", None) or {}).get("color")
        if vcol is not None and np.asarray(vcol).shape[0] == n_v:
            colors = _to_uint8_rgb(np.asarray(vcol))
            return _Geom(vertices, faces, "vertex", colors=colors)
        color = _material_color(material)
        return _Geom(vertices, faces, "face", colors=np.tile(color, (n_f, 1)))

    return _Geom(vertices, faces, "face", colors=np.tile(np.uint8(DEFAULT_GREY), (n_f, 1)))


def _material_image(material) -> tuple[object | None, tuple[int, int, int]]:
    """The base-colour image of a material and the RGB factor (0-255) that multiplies it.

    glTF PBR: ``baseColorTexture`` times ``baseColorFactor`` (the glTF rule). OBJ / simple
    materials: ``map_Kd`` as it is (viewers ignore ``Kd`` under a texture in practice)."""
    if material is None:
        return None, (255, 255, 255)
    image = getattr(material, "baseColorTexture", None)
    if image is not None:
        factor = getattr(material, "baseColorFactor", None)
        if factor is None:
            return image, (255, 255, 255)
        rgb = _to_uint8_rgb(np.asarray(factor).reshape(1, -1))[0]
        return image, tuple(int(c) for c in rgb)
    image = getattr(material, "image", None)
    return image, (255, 255, 255)


def _material_color(material) -> np.ndarray:
    """uint8 (3,): the main colour of a material, grey when there is none."""
    try:
        color = np.asarray(material.main_color).reshape(1, -1)
        return _to_uint8_rgb(color)[0]
    except Exception:  # materials without a usable colour
        return np.array(DEFAULT_GREY, dtype=np.uint8)


def _to_uint8_rgb(colors: np.ndarray) -> np.ndarray:
    """uint8 (N, 3) from colours (N, 3|4) given as uint8 or as floats in [0, 1]."""
    colors = np.asarray(colors)
    if colors.ndim != 2 or colors.shape[1] < 3:
        return np.tile(np.uint8(DEFAULT_GREY), (len(colors), 1))
    rgb = colors[:, :3]
    if np.issubdtype(rgb.dtype, np.floating):
        rgb = np.round(np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255.0)
    return np.ascontiguousarray(np.clip(rgb, 0, 255).astype(np.uint8))


def _image_rgb(image, factor: tuple[int, int, int], where: str) -> np.ndarray:
    """uint8 (h, w, 3) from a PIL image (alpha dropped), times ``factor / 255`` per channel."""
    try:
        if image.mode in ("I;16", "I;16B", "I;16L", "I"):
            arr = np.asarray(image, dtype=np.float64)
            rgb = np.repeat((arr / max(float(arr.max()), 1.0) * 255.0)[..., None], 3, axis=2).astype(np.uint8)
        else:
            rgb = np.asarray(image.convert("RGB"), dtype=np.uint8)
    except Exception as exc:
        raise SceneError(f"{where}: a texture image cannot be decoded ({type(exc).__name__}: {_one_line(exc)}); "
                         "re-export the textures as PNG or JPEG") from exc
    if rgb.ndim != 3 or rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise SceneError(f"{where}: a texture image is empty; re-export the textures as PNG or JPEG")
    if tuple(factor) != (255, 255, 255):
        f = np.asarray(factor, dtype=np.float64) / 255.0
        rgb = np.round(rgb * f).astype(np.uint8)
    return np.ascontiguousarray(rgb)


def _assemble(geoms: list[_Geom]) -> tuple[np.ndarray, np.ndarray, list[ScenePart]]:
    """Concatenate geometries into one vertex / face array and contiguous parts.

    Geometries are ordered vertex-coloured, then face-coloured, then textured grouped by
    image, so that each group is one part. Vertex-indexed appearance arrays cover the whole
    scene's vertices (zeros on rows of other geometries) and are shared by all parts.

    Returns (vertices float64 (V, 3), faces int32 (F, 3), parts).
    """
    group_order: dict = {}

    def group(g: _Geom):
        key = ("texture", g.image_key) if g.kind == "texture" else (g.kind,)
        rank = {"vertex": 0, "face": 1, "texture": 2}[g.kind]
        return (rank, group_order.setdefault(key, len(group_order)))

    geoms = sorted(geoms, key=group)                  # stable: file order within a group
    n_v = sum(len(g.vertices) for g in geoms)
    n_f = sum(len(g.faces) for g in geoms)
    if n_v >= 2**31:
        raise SceneError(f"mesh has {n_v} vertices, more than this loader supports (2^31); simplify the mesh")
    vertices = np.empty((n_v, 3), dtype=np.float64)
    faces = np.empty((n_f, 3), dtype=np.int32)
    has_vertex = any(g.kind == "vertex" for g in geoms)
    has_uv = any(g.kind == "texture" for g in geoms)
    vcolors = np.zeros((n_v, 3), dtype=np.uint8) if has_vertex else None
    uv = np.zeros((n_v, 2), dtype=np.float32) if has_uv else None

    # First pass fills the shared arrays; parts are made after so that they see final data.
    spans = []
    v0 = f0 = 0
    for g in geoms:
        v1, f1 = v0 + len(g.vertices), f0 + len(g.faces)
        vertices[v0:v1] = g.vertices
        faces[f0:f1] = g.faces + v0
        if g.kind == "vertex":
            vcolors[v0:v1] = g.colors
        elif g.kind == "texture":
            uv[v0:v1] = g.uv
        spans.append((f0, f1))
        v0, f0 = v1, f1
    if vcolors is not None:
        vcolors.flags.writeable = False
    if uv is not None:
        uv.flags.writeable = False

    parts: list[ScenePart] = []
    i = 0
    while i < len(geoms):
        key = group(geoms[i])
        j = i
        while j + 1 < len(geoms) and group(geoms[j + 1]) == key:
            j += 1
        start, stop = spans[i][0], spans[j][1]
        kind = geoms[i].kind
        if kind == "vertex":
            appearance = VertexColors(colors=vcolors)
        elif kind == "texture":
            appearance = UVTexture(uv=uv, image=geoms[i].image)
        else:
            appearance = FaceColors(colors=np.concatenate([g.colors for g in geoms[i:j + 1]]))
        parts.append(ScenePart(face_start=start, face_stop=stop, appearance=appearance))
        i = j + 1
    return vertices, faces, parts
