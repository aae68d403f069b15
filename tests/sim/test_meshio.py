"""Loading scene mesh files: up axis, floor, scale, appearance, and one-line errors.

Every file is made here in ``tmp_path`` (trimesh exports, or PLY / OBJ written by hand so that
the loader is checked against the formats, not only against trimesh's own writer).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from PIL import Image

from dynactivegs.errors import ConfigError, SceneError
from dynactivegs.sim.meshio import infer_floor_z, load_mesh_scene, scene_from_trimesh, up_rotation
from dynactivegs.sim.scene import FaceColors, UVTexture, VertexColors

# Room used throughout: 6 m along x, 4 m along y, 2.7 m high, floor at z = FLOOR0 (Z up).
ROOM_XYZ_M = np.array([6.0, 4.0, 2.7])
FLOOR0 = 0.7
# glTF is Y-up: a Z-up point (x, y, z) is stored as (x, z, -y).
ZUP_TO_YUP = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)


def _room(rng: np.random.Generator) -> trimesh.Trimesh:
    """Inward-facing box room (Z up), floor at FLOOR0, walls split into several triangles."""
    room = trimesh.creation.box(extents=ROOM_XYZ_M)
    room = room.subdivide()
    room.invert()                                  # normals into the room, as a scan is seen
    room.apply_translation([0.0, 0.0, FLOOR0 + ROOM_XYZ_M[2] / 2])
    room.visual.face_colors = np.c_[rng.integers(0, 256, (len(room.faces), 3)), np.full(len(room.faces), 255)]
    return room


def _pillar() -> trimesh.Trimesh:
    """A 0.2 x 0.2 x 2.0 m pillar (Z up) standing on z = 0 at the origin."""
    pillar = trimesh.creation.box(extents=[0.2, 0.2, 2.0])
    pillar.apply_translation([0.0, 0.0, 1.0])
    return pillar


def _extent_of_faces(scene, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Size (3,) and min corner (3,) in metres of the vertices used by ``faces``."""
    pts = scene.vertices_m[np.unique(scene.faces[faces])]
    return pts.max(axis=0) - pts.min(axis=0), pts.min(axis=0)


def _ply_bytes(vertices: np.ndarray, faces: list[list[int]] | None, colors: np.ndarray | None,
               binary: bool) -> bytes:
    """A PLY file as Replica writes it: float xyz, uchar rgb, polygon faces (quads allowed)."""
    head = ["ply", "format binary_little_endian 1.0" if binary else "format ascii 1.0",
            f"element vertex {len(vertices)}", "property float x", "property float y", "property float z"]
    if colors is not None:
        head += ["property uchar red", "property uchar green", "property uchar blue"]
    if faces is not None:
        head += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
    head.append("end_header")
    out = ("\n".join(head) + "\n").encode()
    if binary:
        fields = [("xyz", "<f4", 3)] + ([("rgb", "u1", 3)] if colors is not None else [])
        rec = np.zeros(len(vertices), dtype=fields)
        rec["xyz"] = vertices
        if colors is not None:
            rec["rgb"] = colors
        out += rec.tobytes()
        for f in faces or []:
            out += np.uint8(len(f)).tobytes() + np.asarray(f, dtype="<i4").tobytes()
    else:
        for i, v in enumerate(vertices):
            row = [repr(float(c)) for c in v] + ([str(int(c)) for c in colors[i]] if colors is not None else [])
            out += (" ".join(row) + "\n").encode()
        for f in faces or []:
            out += (" ".join(str(x) for x in [len(f), *f]) + "\n").encode()
    return out


def _box_room_quads(size_m: np.ndarray, floor_z: float) -> tuple[np.ndarray, list[list[int]]]:
    """8 corners of a box room and its 6 inward-facing quads (Replica-like quad faces)."""
    sx, sy, sz = size_m
    v = np.array([[x, y, z] for z in (floor_z, floor_z + sz) for y in (0.0, sy) for x in (0.0, sx)])
    # corners: 0..3 bottom (x fastest), 4..7 top; quads wound so normals point into the room
    quads = [[0, 1, 3, 2],        # floor, normal +z
             [4, 6, 7, 5],        # ceiling, normal -z
             [0, 4, 5, 1],        # y = 0 wall, normal +y
             [2, 3, 7, 6],        # y = sy wall, normal -y
             [0, 2, 6, 4],        # x = 0 wall, normal +x
             [1, 5, 7, 3]]        # x = sx wall, normal -x
    return v, quads


def _hit_albedo(scene, face: int, u: float, v: float) -> np.ndarray:
    """Albedo at barycentric (u, v) of a face (Embree convention), float32 (3,) in [0, 1]."""
    f = np.array([face])
    bary = np.array([[u, v]])
    tri = scene.vertices_m[scene.faces[face]]
    p = ((1 - u - v) * tri[0] + u * tri[1] + v * tri[2])[None]
    return scene.albedo(f, bary, p)[0]


# ----------------------------------------------------------------------------------------------
# Up axis, node transforms, floor


def test_yup_glb_loads_z_up_with_floor_at_zero(tmp_path):
    rng = np.random.default_rng(0)
    world = trimesh.Scene()
    world.add_geometry(_room(rng), geom_name="room", transform=ZUP_TO_YUP)
    # The pillar stands at (1.5, -0.5) on the floor; its placement lives in its node transform.
    place = trimesh.transformations.translation_matrix([1.5, -0.5, FLOOR0])
    world.add_geometry(_pillar(), geom_name="pillar", transform=ZUP_TO_YUP @ place)
    path = tmp_path / "room.glb"
    world.export(path)

    scene = load_mesh_scene(path)
    assert not scene.lit and scene.name == "room"
    lo, hi = scene.bounds_m
    np.testing.assert_allclose(hi - lo, ROOM_XYZ_M, atol=1e-5)
    np.testing.assert_allclose(lo, [-3.0, -2.0, 0.0], atol=1e-5)   # x and y keep their sign

    # The pillar is the only 12-face geometry, so it is a part of its own.
    n_room = len(_room(np.random.default_rng(0)).faces)
    assert scene.n_faces == n_room + 12
    pillar = [p for p in scene.parts if p.face_stop - p.face_start == 12]
    assert len(pillar) == 1
    ext, pmin = _extent_of_faces(scene, np.arange(pillar[0].face_start, pillar[0].face_stop))
    np.testing.assert_allclose(ext, [0.2, 0.2, 2.0], atol=1e-5)     # tall and thin along z
    np.testing.assert_allclose(pmin, [1.4, -0.6, 0.0], atol=1e-5)   # stands on the floor at (1.5, -0.5)
    # Room floor faces look up, its ceiling faces look down: the rotation is proper, not a mirror.
    room = np.ones(scene.n_faces, dtype=bool)
    room[pillar[0].face_start:pillar[0].face_stop] = False
    n = scene.face_normals[room]
    z = scene.triangles_m[room, :, 2].mean(axis=1)
    assert np.all(n[z < 1e-6, 2] > 0.99)
    assert np.all(n[np.abs(z - ROOM_XYZ_M[2]) < 1e-6, 2] < -0.99)


def test_up_axis_override(tmp_path):
    rng = np.random.default_rng(1)
    room = _room(rng)
    zup = tmp_path / "zup.glb"
    room.export(zup)                        # a Z-up glb, against glTF's convention
    auto = load_mesh_scene(zup)             # read as Y-up: 2.7 m tall room lands along y
    lo, hi = auto.bounds_m
    np.testing.assert_allclose(hi - lo, [6.0, 2.7, 4.0], atol=1e-5)
    fixed = load_mesh_scene(zup, up_axis="z")
    lo, hi = fixed.bounds_m
    np.testing.assert_allclose(hi - lo, ROOM_XYZ_M, atol=1e-5)
    assert lo[2] == pytest.approx(0.0, abs=1e-6)

    # An X-up PLY: file (x, y, z) = world (z, x, y).
    xup = room.copy()
    xup.vertices = room.vertices[:, [2, 0, 1]]
    path = tmp_path / "xup.ply"
    xup.export(path)
    scene = load_mesh_scene(path, up_axis="x")
    lo, hi = scene.bounds_m
    np.testing.assert_allclose(hi - lo, ROOM_XYZ_M, atol=1e-5)
    np.testing.assert_allclose(scene.vertices_m, room.vertices - [0, 0, FLOOR0], atol=1e-5)


@pytest.mark.parametrize("axis", ["x", "y", "z", "-x", "-y", "-z"])
def test_up_rotations_are_proper_and_point_the_axis_up(axis):
    r = up_rotation(axis)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r @ r.T, np.eye(3))
    file_axis = np.zeros(3)
    file_axis["xyz".index(axis[-1])] = -1.0 if axis.startswith("-") else 1.0
    np.testing.assert_allclose(r @ file_axis, [0, 0, 1])


def test_gltf_rotation_is_the_habitat_convention():
    np.testing.assert_allclose(up_rotation("y") @ [1.0, 2.0, 3.0], [1.0, -3.0, 2.0])


def test_bad_up_axis_is_a_config_error():
    with pytest.raises(ConfigError, match="mesh_up_axis"):
        scene_from_trimesh(_pillar(), "p", up_axis="up")


def test_floor_override_and_inference_ignore_furniture_and_debris():
    rng = np.random.default_rng(2)
    room = _room(rng)
    table = trimesh.creation.box(extents=[1.2, 0.8, 0.05])
    table.apply_translation([0.5, 0.5, FLOOR0 + 0.75])
    debris = trimesh.creation.box(extents=[0.1, 0.1, 0.01])      # a small fragment below the floor
    debris.apply_translation([0.0, 0.0, FLOOR0 - 0.4])
    mesh = trimesh.util.concatenate([room, table, debris])

    scene = scene_from_trimesh(mesh, "r", up_axis="z")
    assert scene.vertices_m[:, 2].max() == pytest.approx(ROOM_XYZ_M[2], abs=1e-6)
    assert infer_floor_z(mesh.vertices, mesh.faces) == pytest.approx(FLOOR0, abs=1e-9)

    given = scene_from_trimesh(mesh, "r", up_axis="z", floor_z_m=0.5)
    np.testing.assert_allclose(given.vertices_m, scene.vertices_m + [0, 0, FLOOR0 - 0.5], atol=1e-9)


def test_floor_on_a_histogram_bin_edge_is_found():
    # Bins start at the lowest upward face: a 1 cm^2 fragment at z = -0.10 puts a 5 cm bin edge
    # at z = 0.05, where the noisy floor lies; the floor's area must not be split by it.
    rng = np.random.default_rng(3)
    room = _room(rng).subdivide().subdivide()
    up = room.face_normals[:, 2] > 0.9
    v = room.vertices.copy()
    floor_v = np.unique(room.faces[up])
    v[floor_v, 2] = 0.05 + rng.uniform(-0.004, 0.004, len(floor_v))
    v[room.vertices[:, 2] > 1.0, 2] -= FLOOR0 - 0.05
    frag = np.array([[0.0, 0.0, -0.1], [0.01, 0.0, -0.1], [0.0, 0.01, -0.1]])
    faces = np.vstack([room.faces, [[0, 1, 2]] + np.int64(len(v))])
    z = infer_floor_z(np.vstack([v, frag]), faces)
    assert z == pytest.approx(0.05, abs=0.004)


def test_no_upward_area_asks_for_floor_height():
    wall = trimesh.Trimesh([[0, 0, 0], [5, 0, 0], [5, 0, 2.5], [0, 0, 2.5]], [[0, 1, 2], [0, 2, 3]], process=False)
    with pytest.raises(SceneError) as err:
        scene_from_trimesh(wall, "wall", up_axis="z")
    assert "\n" not in str(err.value) and "mesh_floor_z_m" in str(err.value)
    scene = scene_from_trimesh(wall, "wall", up_axis="z", floor_z_m=0.0)
    assert scene.n_faces == 2


def test_inverted_winding_is_caught_not_silently_misplaced():
    room = _room(np.random.default_rng(4))
    room.invert()                    # outward normals: the ceiling now faces up
    with pytest.raises(SceneError) as err:
        scene_from_trimesh(room, "inv", up_axis="z")
    assert "\n" not in str(err.value) and "winding" in str(err.value) and "mesh_floor_z_m" in str(err.value)


# ----------------------------------------------------------------------------------------------
# Appearance


@pytest.mark.parametrize("binary", [True, False])
def test_replica_like_ply_vertex_colours_interpolate(tmp_path, binary):
    rng = np.random.default_rng(5)
    verts, quads = _box_room_quads(np.array([5.0, 3.0, 2.6]), floor_z=-1.2)
    colors = rng.integers(0, 256, (len(verts), 3), dtype=np.uint8)
    path = tmp_path / "mesh.ply"
    path.write_bytes(_ply_bytes(verts, quads, colors, binary=binary))

    scene = load_mesh_scene(path)
    assert len(scene.parts) == 1 and isinstance(scene.parts[0].appearance, VertexColors)
    assert scene.n_faces == 12                                  # quads split into triangles
    assert scene.bounds_m[0, 2] == pytest.approx(0.0, abs=1e-6)
    # Find each scene vertex's source vertex by position (floor moved from -1.2 to 0).
    src = verts + [0.0, 0.0, 1.2]
    d = np.linalg.norm(scene.vertices_m[:, None] - src[None], axis=2)
    source_of = np.argmin(d, axis=1)
    assert d.min(axis=1).max() < 1e-5
    for face in range(scene.n_faces):
        c0, c1, c2 = (colors[source_of[scene.faces[face, k]]].astype(np.float32) / 255 for k in range(3))
        np.testing.assert_allclose(_hit_albedo(scene, face, 0.0, 0.0), c0, atol=1e-6)
        np.testing.assert_allclose(_hit_albedo(scene, face, 1.0, 0.0), c1, atol=1e-6)
        np.testing.assert_allclose(_hit_albedo(scene, face, 0.2, 0.5), 0.3 * c0 + 0.2 * c1 + 0.5 * c2, atol=1e-6)


def _texture(rng: np.random.Generator) -> np.ndarray:
    return rng.integers(0, 256, (4, 8, 4), dtype=np.uint8)       # RGBA, 4 rows x 8 columns


def _texel_uv(row: int, col: int, h: int = 4, w: int = 8) -> tuple[float, float]:
    """UV (v up, OBJ/glTF-in-trimesh convention) of the centre of texel (row from the top, col)."""
    return (col + 0.5) / w, 1.0 - (row + 0.5) / h


def test_textured_obj_gives_uv_texture_with_texel_colours(tmp_path):
    rng = np.random.default_rng(6)
    rgba = _texture(rng)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "wall.png")
    (tmp_path / "room.mtl").write_text("newmtl wall\nKd 0.8 0.8 0.8\nmap_Kd wall.png\n")
    verts, quads = _box_room_quads(np.array([4.0, 3.0, 2.5]), floor_z=0.0)
    texels = [(0, 0), (1, 7), (3, 2), (2, 5)]                     # per quad corner
    lines = ["mtllib room.mtl"] + [f"v {x} {y} {z}" for x, y, z in verts]
    lines += ["vt {} {}".format(*_texel_uv(r, c)) for r, c in texels]
    lines.append("usemtl wall")
    for q in quads:
        lines.append("f " + " ".join(f"{vi + 1}/{k + 1}" for k, vi in enumerate(q)))
    path = tmp_path / "room.obj"
    path.write_text("\n".join(lines) + "\n")

    scene = load_mesh_scene(path)
    assert len(scene.parts) == 1
    app = scene.parts[0].appearance
    assert isinstance(app, UVTexture) and app.image.shape == (4, 8, 3) and app.image.dtype == np.uint8
    np.testing.assert_array_equal(app.image, rgba[:, :, :3])     # alpha dropped, no multiply by Kd
    for face in range(scene.n_faces):
        for k, (u, v) in enumerate([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)]):
            uv = app.uv[scene.faces[face, k]]
            row, col = int(round((1.0 - uv[1]) * 4 - 0.5)), int(round(uv[0] * 8 - 0.5))
            assert (row, col) in texels
            np.testing.assert_allclose(_hit_albedo(scene, face, u, v), rgba[row, col, :3] / 255.0, atol=1e-6)


def test_textured_glb_pbr_texture_and_base_colour_factor(tmp_path):
    rng = np.random.default_rng(7)
    rgba = _texture(rng)
    uvs = np.array([_texel_uv(0, 0), _texel_uv(0, 7), _texel_uv(3, 7), _texel_uv(3, 0)])
    quad = np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]], dtype=np.float64)
    world = trimesh.Scene()
    # Two floor tiles with the same texture: at y in [0, 3] plain, at y in [5, 8] times a factor.
    factors = {0.0: np.array([255, 255, 255]), 5.0: np.array([128, 255, 64])}
    for y0, factor in factors.items():
        mesh = trimesh.Trimesh(quad + [0, y0, 0], [[0, 1, 2], [0, 2, 3]], process=False)
        mesh.visual = trimesh.visual.TextureVisuals(
            uv=uvs, material=trimesh.visual.material.PBRMaterial(
                baseColorTexture=Image.fromarray(rgba, "RGBA"), baseColorFactor=[*factor, 255]))
        world.add_geometry(mesh, geom_name=f"tile{y0:g}", transform=ZUP_TO_YUP)
    path = tmp_path / "textured.glb"
    world.export(path)

    scene = load_mesh_scene(path, floor_z_m=0.0)
    assert len(scene.parts) == 2 and all(isinstance(p.appearance, UVTexture) for p in scene.parts)
    for part in scene.parts:
        app = part.appearance
        y0 = 0.0 if scene.vertices_m[scene.faces[part.face_start, 0], 1] < 4.0 else 5.0
        want_image = np.round(rgba[:, :, :3] * (factors[y0] / 255.0))
        np.testing.assert_array_equal(app.image, want_image)
        for face in range(part.face_start, part.face_stop):
            for k, (u, v) in enumerate([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)]):
                # The corner's position says which texel it carries.
                xy = scene.vertices_m[scene.faces[face, k], :2] - [0.0, y0]
                corner = int(np.argmin(np.linalg.norm(quad[:, :2] - xy, axis=1)))
                row, col = [(0, 0), (0, 7), (3, 7), (3, 0)][corner]
                np.testing.assert_allclose(_hit_albedo(scene, face, u, v) * 255.0,
                                           np.round(rgba[row, col, :3] * factors[y0] / 255.0), atol=1e-3)


def test_plain_material_and_vertex_coloured_obj(tmp_path):
    (tmp_path / "m.mtl").write_text("newmtl red\nKd 0.8 0.1 0.1\n")
    verts, quads = _box_room_quads(np.array([3.0, 3.0, 2.5]), floor_z=0.0)
    plain = ["mtllib m.mtl"] + [f"v {x} {y} {z}" for x, y, z in verts] + ["usemtl red"]
    plain += ["f " + " ".join(str(i + 1) for i in q) for q in quads]
    (tmp_path / "plain.obj").write_text("\n".join(plain) + "\n")
    scene = load_mesh_scene(tmp_path / "plain.obj")
    assert isinstance(scene.parts[0].appearance, FaceColors)
    np.testing.assert_allclose(_hit_albedo(scene, 3, 0.3, 0.3), np.round(np.array([0.8, 0.1, 0.1]) * 255) / 255, atol=1e-6)

    colored = [f"v {x} {y} {z} {x / 3:.6f} {y / 3:.6f} {z / 2.5:.6f}" for x, y, z in verts]
    colored += ["f " + " ".join(str(i + 1) for i in q) for q in quads]
    (tmp_path / "vc.obj").write_text("\n".join(colored) + "\n")
    scene = load_mesh_scene(tmp_path / "vc.obj")
    assert isinstance(scene.parts[0].appearance, VertexColors)
    for face in range(scene.n_faces):
        p = scene.vertices_m[scene.faces[face, 0]]
        np.testing.assert_allclose(_hit_albedo(scene, face, 0.0, 0.0), p / [3.0, 3.0, 2.5], atol=1 / 255)


def test_mixed_geometries_share_whole_scene_vertex_arrays():
    rng = np.random.default_rng(8)
    room = _room(rng)                                           # face colours
    colored = _pillar()
    colored.visual.vertex_colors = rng.integers(0, 256, (len(colored.vertices), 4), dtype=np.uint8)
    textured = _pillar()
    textured.apply_translation([1.0, 0.0, 0.0])
    textured.visual = trimesh.visual.TextureVisuals(
        uv=rng.random((len(textured.vertices), 2)),
        image=Image.fromarray(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)))
    grey = _pillar()
    grey.apply_translation([-1.0, 0.0, 0.0])
    world = trimesh.Scene([textured, room, grey, colored])
    scene = scene_from_trimesh(world, "mix", up_axis="z")

    kinds = [type(p.appearance) for p in scene.parts]
    assert kinds == [VertexColors, FaceColors, UVTexture]       # face colours of room and grey merged
    n_v = len(scene.vertices_m)
    vc, fc, tx = (p.appearance for p in scene.parts)
    assert vc.colors.shape == (n_v, 3) and tx.uv.shape == (n_v, 2)
    assert fc.colors.shape == (scene.parts[1].face_stop - scene.parts[1].face_start, 3)
    # Rows of vertices outside a part are zero.
    vc_rows = np.unique(scene.faces[scene.parts[0].face_start:scene.parts[0].face_stop])
    tx_rows = np.unique(scene.faces[scene.parts[2].face_start:scene.parts[2].face_stop])
    assert not np.delete(vc.colors, vc_rows, axis=0).any()
    assert not np.delete(tx.uv, tx_rows, axis=0).any()
    # The untextured, uncoloured pillar is grey; the room keeps its face colours.
    greys = (fc.colors == 128).all(axis=1)
    assert greys.sum() == 12
    # Albedo at every face through Scene.albedo agrees with each part's own data.
    faces = np.arange(scene.n_faces)
    bary = np.tile([[0.25, 0.25]], (scene.n_faces, 1))
    pts = scene.triangles_m.mean(axis=1)
    alb = scene.albedo(faces, bary, pts)
    assert alb.shape == (scene.n_faces, 3) and np.isfinite(alb).all()
    np.testing.assert_allclose(alb[scene.parts[1].face_start:scene.parts[1].face_stop], fc.colors / 255.0, atol=1e-6)


# ----------------------------------------------------------------------------------------------
# Scale


def test_millimetre_file_needs_scale(tmp_path):
    verts, quads = _box_room_quads(np.array([6000.0, 4000.0, 2700.0]), floor_z=0.0)
    path = tmp_path / "mm.ply"
    path.write_bytes(_ply_bytes(verts, quads, None, binary=True))
    with pytest.raises(SceneError) as err:
        load_mesh_scene(path)
    msg = str(err.value)
    assert "\n" not in msg and "millimetres" in msg and "mesh_scale=0.001" in msg and str(path) in msg
    scene = load_mesh_scene(path, scale=0.001)
    lo, hi = scene.bounds_m
    np.testing.assert_allclose(hi - lo, [6.0, 4.0, 2.7], atol=1e-6)
    assert isinstance(scene.parts[0].appearance, FaceColors)


def test_too_small_scene_says_check_units():
    tiny = trimesh.creation.box(extents=[0.06, 0.04, 0.027])
    tiny.invert()
    with pytest.raises(SceneError) as err:
        scene_from_trimesh(tiny, "tiny", up_axis="z")
    assert "\n" not in str(err.value) and "too small" in str(err.value) and "mesh_scale" in str(err.value)
    assert scene_from_trimesh(tiny, "tiny", up_axis="z", scale=100.0).bounds_m[1, 0] == pytest.approx(3.0)


# ----------------------------------------------------------------------------------------------
# Errors


def _scene_error(path, **kwargs) -> str:
    with pytest.raises(SceneError) as err:
        load_mesh_scene(path, **kwargs)
    msg = str(err.value)
    assert "\n" not in msg and "Traceback" not in msg
    return msg


def test_missing_file(tmp_path):
    msg = _scene_error(tmp_path / "nope.glb")
    assert "no such mesh file" in msg and "nope.glb" in msg


def test_unknown_extension(tmp_path):
    path = tmp_path / "room.fbx"
    path.write_bytes(b"x")
    msg = _scene_error(path)
    assert "unsupported" in msg and ".glb" in msg and ".ply" in msg and ".obj" in msg


@pytest.mark.parametrize("name", ["junk.glb", "junk.ply", "junk.gltf"])
def test_garbage_bytes(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(9).integers(0, 256, 2000, dtype=np.uint8).tobytes())
    msg = _scene_error(path)
    assert "cannot be read" in msg or "no triangles" in msg


def test_garbage_obj_has_no_triangles(tmp_path):
    path = tmp_path / "junk.obj"
    path.write_bytes(b"\x00\xff not an obj \x00" * 50)
    assert "no triangles" in _scene_error(path)


def test_point_cloud_ply(tmp_path):
    path = tmp_path / "cloud.ply"
    pts = np.random.default_rng(10).random((50, 3)) * 5
    path.write_bytes(_ply_bytes(pts, None, np.zeros((50, 3), np.uint8), binary=False))
    msg = _scene_error(path)
    assert "50 points but no faces" in msg


def test_empty_ply(tmp_path):
    path = tmp_path / "empty.ply"
    path.write_bytes(_ply_bytes(np.zeros((0, 3)), [], None, binary=False))
    assert "no triangles" in _scene_error(path)


def test_non_finite_vertices(tmp_path):
    verts, quads = _box_room_quads(np.array([4.0, 3.0, 2.5]), floor_z=0.0)
    verts[5, 1] = math.nan
    path = tmp_path / "nan.ply"
    path.write_bytes(_ply_bytes(verts, quads, None, binary=False))
    assert "NaN or infinite" in _scene_error(path)


def test_bad_scale_is_a_config_error():
    with pytest.raises(ConfigError, match="mesh_scale"):
        scene_from_trimesh(_room(np.random.default_rng(11)), "r", up_axis="z", scale=-1.0)
