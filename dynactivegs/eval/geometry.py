"""Geometric accuracy of a reconstruction: ground-truth points, Acc, Comp and C.R. (DESIGN.md §6).

Ground truth is a set of points sampled uniformly over the part of the static mesh that the
robot's camera can see from somewhere in free space. Visibility is tested exactly, per
sample, by ray casting (Embree) from a lattice of viewpoints:

- viewpoints: camera centres at camera height above every navigable lattice cell
  (``FreeSpace.navigable(robot radius)``, spacing ``EvalConfig.viewpoint_spacing_m``);
- a sample ``p`` is visible from viewpoint ``v`` when the camera, turned to face it (the yaw is
  free, the camera stays level), has it inside the vertical field of view
  (``|p_z - v_z| <= tan(vfov / 2) * |p_xy - v_xy|``), within the depth range (horizontal
  distance in ``[min_depth, max_depth]``), and the first static hit of the ray ``v -> p`` is
  not nearer than ``|p - v| - visibility_tol_m``;
- a sample is kept when it is visible from at least one viewpoint. Samples are drawn (seeded)
  in batches until ``n_gt_points`` visible ones are collected, so they stay uniform over the
  visible area.

People are never part of the static mesh, so no ground-truth point lies on a person.
The points are computed once per scene and parameter set and cached on disk (``.npz``);
the file name holds a digest of the mesh, the parameters and :data:`GT_VERSION`.

Metrics, in centimetres, with KD-trees (scipy):

- Acc: mean distance from each reconstruction point to the visible surface: the nearest of
  the mesh triangles that carry its ``ACC_NEIGHBOURS`` nearest ground-truth points (exact
  point-to-triangle distance, ``trimesh.triangles.closest_point``);
- Comp: mean distance from each ground-truth point to its nearest reconstruction point;
- C.R.: percentage of ground-truth points with a reconstruction point within the threshold.

Measured to the nearest sample instead, Acc would be bounded below by the spacing of the
samples: a reconstruction lying exactly on the surface is on average about
``0.5 / sqrt(points per m^2)`` from the nearest sample (apartment-00, 200k points over
~420 m^2 of visible surface: 2.3 cm). Against the triangles it is 0 for points on the
surface. Comp and C.R. go from the samples to the (1 cm voxel) reconstruction points and need
no such correction.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from dynactivegs.config import SimConfig
from dynactivegs.errors import DagsError
from dynactivegs.eval.config import EvalConfig
from dynactivegs.eval.views import free_space_lattice
from dynactivegs.rng import derive_rng
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.render import Renderer
from dynactivegs.sim.scene import Scene
from dynactivegs.sim.scenes import load_scene, scene_freespace, scene_renderer

GT_VERSION = 2
"""Bump when the ground-truth sampling changes, so that stale cache files are not reused."""
MAX_SAMPLE_ROUNDS = 50
ACC_NEIGHBOURS = 8
"""Acc measures to the triangles of this many nearest ground-truth samples of each reconstruction point."""
ACC_CHUNK = 500_000


@dataclass(frozen=True)
class GroundTruthPoints:
    """Ground-truth points of one scene and how they were obtained."""

    points_m: np.ndarray          # float64 (N, 3), world frame (values are float32-exact: the cache stores float32)
    face_idx: np.ndarray          # int64 (N,), the static-mesh triangle each point lies on
    key: str                      # digest of the scene mesh, the parameters and GT_VERSION
    path: Path                    # cache file
    from_cache: bool              # loaded from ``path`` rather than computed
    n_viewpoints: int             # free-space viewpoints visibility was tested from
    visible_fraction: float       # fraction of the whole static surface area that is visible
    seconds: float                # time to compute (as recorded when computed) or to load


# ---------------------------------------------------------------------------------------- visibility
def visibility_viewpoints(freespace: FreeSpace, radius_m: float, spacing_m: float, height_m: float) -> np.ndarray:
    """float64 (V, 3): camera centres at ``height_m`` over the navigable lattice (see :func:`free_space_lattice`)."""
    xy = free_space_lattice(freespace, radius_m, spacing_m)
    return np.c_[xy, np.full(len(xy), height_m)]


def visible_from_any(renderer: Renderer, points_m: np.ndarray, viewpoints_m: np.ndarray, *, vfov_deg: float,
                     min_depth_m: float, max_depth_m: float, tol_m: float) -> np.ndarray:
    """bool (N,): whether each point (N, 3) is seen by a level camera at some viewpoint (V, 3).

    The camera may turn freely about the vertical axis; see the module docstring for the test.
    A point, once found visible, is not tested again from later viewpoints.
    """
    assert points_m.ndim == 2 and points_m.shape[1] == 3
    assert viewpoints_m.ndim == 2 and viewpoints_m.shape[1] == 3
    tan_half = math.tan(math.radians(vfov_deg) / 2)
    visible = np.zeros(len(points_m), dtype=bool)
    for v in viewpoints_m:
        idx = np.flatnonzero(~visible)
        if len(idx) == 0:
            break
        d = points_m[idx] - v
        horiz = np.hypot(d[:, 0], d[:, 1])
        in_view = (horiz >= min_depth_m) & (horiz <= max_depth_m) & (np.abs(d[:, 2]) <= tan_half * horiz)
        idx, d = idx[in_view], d[in_view]
        if len(idx) == 0:
            continue
        dist = np.linalg.norm(d, axis=1)
        t, _, _ = renderer.cast(v, d / dist[:, None])
        visible[idx[t >= dist - tol_m]] = True
    return visible


def sample_visible_surface(scene: Scene, renderer: Renderer, viewpoints_m: np.ndarray, n: int,
                           rng: np.random.Generator, *, vfov_deg: float, min_depth_m: float, max_depth_m: float,
                           tol_m: float) -> tuple[np.ndarray, np.ndarray, float]:
    """``n`` points uniform over the visible static surface, their faces, and the visible fraction of the area.

    Returns (points float64 (n, 3), face indices int64 (n,), fraction). Draws uniform surface
    samples in batches and keeps the visible ones in draw order until there are ``n``.
    """
    kept: list[np.ndarray] = []
    kept_faces: list[np.ndarray] = []
    n_kept = n_drawn = n_visible = 0
    batch = 2 * n
    for _ in range(MAX_SAMPLE_ROUNDS):
        pts, faces = scene.sample_surface(batch, rng)
        vis = visible_from_any(renderer, pts, viewpoints_m, vfov_deg=vfov_deg, min_depth_m=min_depth_m,
                               max_depth_m=max_depth_m, tol_m=tol_m)
        kept.append(pts[vis])
        kept_faces.append(faces[vis])
        n_kept += int(vis.sum())
        n_drawn += batch
        n_visible += int(vis.sum())
        if n_kept >= n:
            return np.concatenate(kept)[:n], np.concatenate(kept_faces)[:n].astype(np.int64), n_visible / n_drawn
        frac = max(n_visible / n_drawn, 1e-3)
        batch = int(math.ceil(1.2 * (n - n_kept) / frac)) + 1000
    raise DagsError(f"scene {scene.name}: found only {n_kept} visible surface points in {n_drawn} samples; "
                    "is the camera height inside the building?")


# ---------------------------------------------------------------------------------------- cache
def _scene_digest(scene: Scene) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(scene.vertices_m, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(scene.faces, dtype=np.int64).tobytes())
    return h.hexdigest()


def gt_parameters(sim: SimConfig, cfg: EvalConfig) -> dict:
    """Every parameter the ground-truth points depend on (besides the mesh), as a JSON-able dict."""
    cam = sim.camera
    return dict(version=GT_VERSION, n_points=cfg.n_gt_points, seed=cfg.gt_seed,
                viewpoint_spacing_m=cfg.viewpoint_spacing_m, visibility_tol_m=cfg.visibility_tol_m,
                camera_height_m=cam.height_m, vfov_deg=cam.vfov_deg, min_depth_m=cam.min_depth_m,
                max_depth_m=cam.max_depth_m, robot_radius_m=sim.robot.radius_m,
                body_height_m=sim.robot.body_height_m, grid_res_m=sim.grid_res_m)


def gt_cache_key(scene: Scene, sim: SimConfig, cfg: EvalConfig) -> str:
    """Hex digest keying the cache file: the mesh, :func:`gt_parameters` (which include GT_VERSION)."""
    payload = json.dumps(dict(mesh=_scene_digest(scene), params=gt_parameters(sim, cfg)), sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:24]


def gt_cache_path(scene: Scene, sim: SimConfig, cfg: EvalConfig) -> Path:
    """Where the ground-truth points of ``scene`` with these parameters are cached."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(scene.name).name)[:64]
    return cfg.resolved_cache_dir() / "gt_points" / f"{stem}-{gt_cache_key(scene, sim, cfg)}.npz"


def _save_npz_atomically(path: Path, meta: dict, **arrays: np.ndarray) -> None:
    """Write a cache file (``arrays`` and ``meta`` as JSON) to a temporary file, then rename it into place,
    so that concurrent runs on one scene never read a half-written file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
    np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
    os.replace(tmp, path)


def ground_truth_points(sim: SimConfig, cfg: EvalConfig) -> GroundTruthPoints:
    """The ground-truth points of ``sim.scene``: loaded from the cache, or computed and cached.

    The cache file is written atomically (temporary file, then rename), so concurrent runs
    on one scene at worst compute the same points twice.
    """
    scene = load_scene(sim)
    path = gt_cache_path(scene, sim, cfg)
    key = gt_cache_key(scene, sim, cfg)
    t0 = time.perf_counter()
    if path.is_file():
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("key") == key:
                pts = z["points_m"].astype(np.float64)
                faces = z["face_idx"].astype(np.int64)
                return GroundTruthPoints(pts, faces, key, path, True, int(meta["n_viewpoints"]),
                                         float(meta["visible_fraction"]), time.perf_counter() - t0)
    renderer = scene_renderer(scene)
    fs = scene_freespace(scene, renderer, sim.grid_res_m, sim.robot.body_height_m)
    cam = sim.camera
    vps = visibility_viewpoints(fs, sim.robot.radius_m, cfg.viewpoint_spacing_m, cam.height_m)
    if len(vps) == 0:
        raise DagsError(f"scene {scene.name}: no navigable viewpoint for ground truth; "
                        "lower eval.viewpoint_spacing_m or check the scene's free space")
    rng = derive_rng(cfg.gt_seed, "gt-points", scene.name)
    pts, faces, frac = sample_visible_surface(scene, renderer, vps, cfg.n_gt_points, rng, vfov_deg=cam.vfov_deg,
                                       min_depth_m=cam.min_depth_m, max_depth_m=cam.max_depth_m,
                                       tol_m=cfg.visibility_tol_m)
    pts32 = pts.astype(np.float32)
    seconds = time.perf_counter() - t0
    meta = dict(key=key, scene=scene.name, params=gt_parameters(sim, cfg), n_viewpoints=len(vps),
                visible_fraction=frac, seconds=seconds)
    _save_npz_atomically(path, meta, points_m=pts32, face_idx=faces)
    return GroundTruthPoints(pts32.astype(np.float64), faces, key, path, False, len(vps), frac, seconds)


# ---------------------------------------------------------------------------------------- survey
SURVEY_VERSION = 1
"""Bump when the survey selection changes, so that stale cache files are not reused."""


@dataclass(frozen=True)
class Survey:
    """The views the "renders" reconstruction points are extracted from (see :func:`survey`)."""

    poses: np.ndarray             # float64 (S, 4, 4) T_world_cam
    n_candidates: int             # lattice views they were chosen from
    ceiling: float                # fraction of the ground-truth points a perfect map shows from them
    from_cache: bool
    seconds: float

    def note(self) -> str:
        """How the views were chosen, for a reconstruction's description."""
        return (f"{len(self.poses)} of {self.n_candidates} lattice views chosen to cover the ground truth "
                f"(a perfect map reaches C.R. {100 * self.ceiling:.1f} % from them)")


def survey(sim: SimConfig, cfg: EvalConfig, gt: GroundTruthPoints, *, renderer: Renderer | None = None,
           freespace: FreeSpace | None = None, gt_tree: cKDTree | None = None) -> Survey:
    """The survey views of ``sim.scene`` (:func:`dynactivegs.eval.views.covering_survey` with ``cfg``'s
    survey_spacing_m, survey_yaws, survey_cover, cr_threshold_cm, edge_jump_rel and voxel_m): loaded
    from the cache, or computed and cached (keyed by those, the camera, the robot radius and ``gt.key``)."""
    from dynactivegs.eval.views import covering_survey

    cam = sim.camera
    params = dict(version=SURVEY_VERSION, gt=gt.key, spacing_m=cfg.survey_spacing_m, yaws=cfg.survey_yaws,
                  cover=cfg.survey_cover, threshold_cm=cfg.cr_threshold_cm, edge_jump_rel=cfg.edge_jump_rel,
                  voxel_m=cfg.voxel_m, width_px=cam.width_px, height_px=cam.height_px, hfov_deg=cam.hfov_deg,
                  vfov_deg=cam.vfov_deg, min_depth_m=cam.min_depth_m, max_depth_m=cam.max_depth_m,
                  camera_height_m=cam.height_m, robot_radius_m=sim.robot.radius_m)
    key = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:24]
    path = gt.path.parent.parent / "survey" / f"{gt.path.stem.rsplit('-', 1)[0]}-{key}.npz"
    t0 = time.perf_counter()
    if path.is_file():
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            if meta.get("key") == key:
                return Survey(z["poses"].astype(np.float64), int(meta["n_candidates"]), float(meta["ceiling"]), True,
                              time.perf_counter() - t0)
    if renderer is None or freespace is None:
        scene = load_scene(sim)
        renderer = scene_renderer(scene) if renderer is None else renderer
        freespace = scene_freespace(scene, renderer, sim.grid_res_m, sim.robot.body_height_m) \
            if freespace is None else freespace
    poses, n_cand, ceiling = covering_survey(renderer, freespace, sim.robot.radius_m, cam, cfg.survey_spacing_m,
                                             cfg.survey_yaws, gt.points_m, cfg.survey_cover,
                                             cfg.cr_threshold_cm / 100.0, cfg.edge_jump_rel, cfg.voxel_m, gt_tree)
    seconds = time.perf_counter() - t0
    _save_npz_atomically(path, dict(key=key, params=params, n_candidates=n_cand, ceiling=ceiling, seconds=seconds),
                         poses=poses)
    return Survey(poses, n_cand, ceiling, False, seconds)


# ---------------------------------------------------------------------------------------- metrics
def voxel_downsample(points_m: np.ndarray, voxel_m: float) -> np.ndarray:
    """float64 (M, 3): the centroid of the points (N, 3) in each occupied voxel of size ``voxel_m``.

    Voxels are ordered by their integer coordinates, so the result does not depend on the
    order of the input points (up to float summation order).
    """
    assert points_m.ndim == 2 and points_m.shape[1] == 3
    pts = np.asarray(points_m, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        return np.zeros((0, 3))
    vox = np.floor(pts / voxel_m).astype(np.int64)
    _, inverse, counts = np.unique(vox, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 3))
    np.add.at(sums, inverse, pts)
    return sums / counts[:, None]


@dataclass(frozen=True)
class GeometryMetrics:
    """Acc, Comp (cm) and C.R. (%) of reconstruction points against ground-truth points."""

    acc_cm: float                 # mean recon -> GT nearest distance; NaN without reconstruction points
    comp_cm: float                # mean GT -> recon nearest distance; NaN without reconstruction points
    cr_pct: float                 # % of GT points with a recon point within cr_threshold_cm
    cr_threshold_cm: float
    n_recon: int
    n_gt: int


def surface_distances(points_m: np.ndarray, gt_tree: cKDTree, gt_faces: np.ndarray, triangles_m: np.ndarray,
                      k: int = ACC_NEIGHBOURS) -> np.ndarray:
    """float64 (N,): distance from each point (N, 3) to the nearest triangle among those carrying its ``k``
    nearest ground-truth samples (``gt_faces`` (M,) indexes ``triangles_m`` (F, 3, 3)); never more than
    the distance to the nearest sample."""
    k = min(k, gt_tree.n)
    d_pt, idx = gt_tree.query(points_m, k=k)
    d_pt, idx = d_pt.reshape(len(points_m), k), idx.reshape(len(points_m), k)
    faces = np.sort(gt_faces[idx], axis=1)
    first = np.ones_like(faces, dtype=bool)
    first[:, 1:] = faces[:, 1:] != faces[:, :-1]             # each (point, triangle) pair once
    rows, cols = np.nonzero(first)
    tri_faces = faces[rows, cols]
    dist = d_pt[:, 0].copy()
    for a in range(0, len(rows), ACC_CHUNK):
        r, f = rows[a:a + ACC_CHUNK], tri_faces[a:a + ACC_CHUNK]
        closest = trimesh.triangles.closest_point(triangles_m[f], points_m[r])
        np.minimum.at(dist, r, np.linalg.norm(closest - points_m[r], axis=1))
    return dist


def geometry_metrics(recon_m: np.ndarray, gt_m: np.ndarray, cr_threshold_cm: float = 5.0, *,
                     gt_tree: cKDTree | None = None, gt_faces: np.ndarray | None = None,
                     triangles_m: np.ndarray | None = None) -> GeometryMetrics:
    """Acc / Comp / C.R. of ``recon_m`` (N, 3) against ``gt_m`` (M, 3), both in metres.

    ``gt_tree``: a prebuilt ``cKDTree(gt_m)`` to reuse across calls. With ``gt_faces`` (M,) and
    ``triangles_m`` (F, 3, 3), the mesh triangle of each ground-truth point, Acc is measured to the
    surface (:func:`surface_distances`); without them, to the nearest ground-truth point.
    """
    assert recon_m.ndim == 2 and recon_m.shape[1] == 3 and gt_m.ndim == 2 and gt_m.shape[1] == 3
    assert len(gt_m) > 0, "ground truth must not be empty"
    assert (gt_faces is None) == (triangles_m is None), "give both gt_faces and triangles_m, or neither"
    if len(recon_m) == 0:
        return GeometryMetrics(math.nan, math.nan, 0.0, cr_threshold_cm, 0, len(gt_m))
    tree = cKDTree(gt_m) if gt_tree is None else gt_tree
    if gt_faces is None:
        d_acc, _ = tree.query(recon_m)
    else:
        d_acc = surface_distances(recon_m, tree, gt_faces, triangles_m)
    d_comp, _ = cKDTree(recon_m).query(gt_m)
    return GeometryMetrics(acc_cm=float(d_acc.mean() * 100.0), comp_cm=float(d_comp.mean() * 100.0),
                           cr_pct=float((d_comp * 100.0 < cr_threshold_cm).mean() * 100.0),
                           cr_threshold_cm=cr_threshold_cm, n_recon=len(recon_m), n_gt=len(gt_m))
