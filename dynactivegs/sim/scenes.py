"""Scene lookup: a procedural name or a mesh file, with per-process caching.

Scenes and their free-space maps are immutable and depend only on their inputs, so they are
cached by those inputs: creating many simulators of the same scene (tests, benchmarks)
builds each scene once.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from dynactivegs.sim.config import SimConfig
from dynactivegs.errors import SceneError
from dynactivegs.sim.freespace import FreeSpace, freespace_from_mesh
from dynactivegs.sim.procedural import is_procedural_name, make_scene
from dynactivegs.sim.render import Renderer
from dynactivegs.sim.scene import Scene

MESH_SUFFIXES = (".glb", ".gltf", ".ply", ".obj")


@functools.lru_cache(maxsize=16)
def _procedural(name: str) -> Scene:
    return make_scene(name)


@functools.lru_cache(maxsize=4)
def _mesh(path: str, mtime_ns: int, up_axis: str, floor_key: str, scale: float) -> Scene:
    from dynactivegs.sim.meshio import load_mesh_scene

    floor = math.nan if floor_key == "nan" else float(floor_key)
    return load_mesh_scene(path, up_axis=up_axis, floor_z_m=floor, scale=scale)


def load_scene(cfg: SimConfig) -> Scene:
    """The scene named by ``cfg.scene``: a procedural name (``apartment-03``) or a mesh path."""
    name = cfg.scene
    if is_procedural_name(name):
        return _procedural(name)
    if Path(name).suffix.lower() in MESH_SUFFIXES:
        p = Path(name)
        if not p.is_file():
            raise SceneError(f"scene file not found: {name}; check the path (formats: .glb .gltf .ply .obj)")
        return _mesh(str(p.resolve()), p.stat().st_mtime_ns, cfg.mesh_up_axis,
                     "nan" if math.isnan(cfg.mesh_floor_z_m) else repr(cfg.mesh_floor_z_m), cfg.mesh_scale)
    return make_scene(name)  # raises the "unknown scene" error that lists the valid forms


def scene_renderer(scene: Scene) -> Renderer:
    """The renderer of ``scene`` (its BVH is built once and cached on the scene)."""
    if "renderer" not in scene._cache:
        scene._cache["renderer"] = Renderer(scene)
    return scene._cache["renderer"]


def scene_freespace(scene: Scene, renderer: Renderer, res_m: float, body_height_m: float) -> FreeSpace:
    """The free-space map of ``scene`` (cached on the scene)."""
    key = ("freespace", res_m, body_height_m)
    if key not in scene._cache:
        def cast_down(origins):
            d = np.zeros_like(origins)
            d[:, 2] = -1.0
            return renderer.cast(origins, d)[0]

        scene._cache[key] = freespace_from_mesh(scene.triangles_m, cast_down, res_m=res_m, band_hi_m=body_height_m)
    return scene._cache[key]
