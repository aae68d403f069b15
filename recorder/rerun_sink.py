"""Rerun timelines of a run: what a person browses to see what the robot saw, believed and chose.

:class:`RerunSink` logs one step at a time to an explicit ``rr.RecordingStream`` (never the
global one) on two timelines, ``step`` (sequence) and ``sim_time`` (duration from
``Frame.stamp_ns``). Entity layout (world frame: Z up, metres):

==========================  =====================================================================
``world/camera``            camera pose (Transform3D) and pinhole; ``rgb``, ``depth``, ``people``
                            (the simulator's people mask, a segmentation image) below it
``images/beta``             perception's uncertainty beta, colour-mapped (viridis, log scale)
``images/render``           the map's render at the frame's pose (MappingOut.render_rgb)
``world/map``               the Gaussian map as coloured points (from a Gaussians object), else
                            the centres of MappingOut.surface_ijk voxels; subsampled
``world/fields/u_s|u_m``    U_s / U_m on voxels with information (n_obs > 0 / U_m > 0), colour-mapped
``world/occupancy``         the 2D occupancy map (GridMap), when given
``world/graph/nodes|edges`` the Voronoi graph, nodes coloured by subregion
``world/candidates``        candidate views as arrows along their yaw, coloured by S_local
``world/target``            the chosen target view; ``world/path`` the planned path
``world/trajectory``        the camera positions so far; ``world/people`` people as capsules
``metrics/<name>``          scalar plots of any name -> float dict
==========================  =====================================================================

The default blueprint shows the 3D view, the camera images, beta and the plots.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from dynactivegs import records

FLOOR_Z_M = 0.03
"""Height at which floor-plane drawings (graph, path, occupancy) are drawn, just above the floor."""

PERSON_RADIUS_M = 0.25


def colormap(values: np.ndarray, vmin: float, vmax: float, name: str = "viridis") -> np.ndarray:
    """uint8 (..., 3) colours of ``values`` mapped linearly from [vmin, vmax] (NaN -> grey)."""
    import matplotlib

    span = vmax - vmin if vmax > vmin else 1.0
    x = np.clip((np.asarray(values, np.float64) - vmin) / span, 0.0, 1.0)
    rgb = matplotlib.colormaps[name](np.nan_to_num(x, nan=0.0), bytes=True)[..., :3]
    rgb[np.isnan(values)] = 128
    return rgb


def label_colors(labels: np.ndarray) -> np.ndarray:
    """uint8 (N, 3): a stable, distinct-looking colour per integer label."""
    labels = np.asarray(labels, np.int64)
    hue = (labels * 0.61803398875) % 1.0                      # golden-ratio hues
    import matplotlib

    rgb = matplotlib.colormaps["hsv"](hue, bytes=True)[..., :3].copy()
    rgb[labels < 0] = 160
    return rgb


def _subsample(n: int, k: int, salt: int) -> np.ndarray:
    """Indices of at most k of n items, the same for the same (n, k, salt)."""
    if n <= k:
        return np.arange(n)
    rng = np.random.default_rng(salt)
    return np.sort(rng.choice(n, k, replace=False))


def default_blueprint() -> rrb.Blueprint:
    """3D world on the left; camera, beta and render in a column; metric plots at the bottom."""
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(
                rrb.Spatial3DView(name="world", origin="world"),
                rrb.Vertical(
                    rrb.Spatial2DView(name="camera", origin="world/camera"),
                    rrb.Spatial2DView(name="beta (uncertainty)", origin="images/beta"),
                    rrb.Spatial2DView(name="map render", origin="images/render"),
                ),
                column_shares=[3, 1],
            ),
            rrb.TimeSeriesView(name="metrics", origin="metrics"),
            row_shares=[3, 1],
        ),
        collapse_panels=True,
    )


class RerunSink:
    """Logs steps of a run to a Rerun recording (an ``.rrd`` file or a given ``RecordingStream``)."""

    def __init__(self, target: str | Path | rr.RecordingStream, *, application_id: str = "dynactivegs",
                 recording_id: str | None = None, max_map_points: int = 60_000, max_voxels: int = 20_000,
                 max_trajectory_points: int = 2_000) -> None:
        """``target``: path of an ``.rrd`` file to write, or a stream the caller set up (and closes)."""
        if isinstance(target, rr.RecordingStream):
            self.rec, self.path = target, None
            self.rec.send_blueprint(default_blueprint())
        else:
            self.path = Path(target)
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.rec = rr.RecordingStream(application_id, recording_id=recording_id)
            self.rec.save(self.path, default_blueprint=default_blueprint())
        self.max_map_points = max_map_points
        self.max_voxels = max_voxels
        self.max_trajectory_points = max_trajectory_points
        self._trajectory: list[np.ndarray] = []
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.rec.log("world/camera/people", rr.AnnotationContext([(0, "background", (0, 0, 0, 0)),
                                                                  (1, "person", (255, 40, 40, 140))]), static=True)

    # ----------------------------------------------------------------------- steps
    def set_time(self, step: int, stamp_ns: int) -> None:
        """Point both timelines at this step."""
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("sim_time", duration=np.timedelta64(int(stamp_ns), "ns"))

    def log_step(self, frame: records.Frame, *, truth: records.SimTruth | None = None,
                 perception: records.PerceptionOut | None = None, mapping: records.MappingOut | None = None,
                 fields: records.FieldsOut | None = None, selection: records.SelectionOut | None = None,
                 planning: records.PlanningOut | None = None, gaussians: Any = None,
                 occupancy: tuple[np.ndarray, np.ndarray, float] | None = None,
                 metrics: Mapping[str, float] | None = None) -> None:
        """Everything known about one step; what is None is not logged (the viewer keeps the last value).

        ``gaussians``: a ``dynactivegs.splat.Gaussians`` (or anything with ``means`` and ``rgb``
        tensors/arrays); ``occupancy``: (log-odds float32 (H, W) with row = y and col = x, the
        xy of cell (0, 0)'s min corner in metres, cell edge in metres), 0 log-odds = unknown.
        """
        self.set_time(frame.step, frame.stamp_ns)
        self._camera(frame)
        if truth is not None:
            self._truth(truth)
        if perception is not None:
            beta = np.log10(np.maximum(perception.beta, 1e-3))
            self.rec.log("images/beta", rr.Image(colormap(beta, -1.0, 0.5)))
        if mapping is not None:
            self.rec.log("images/render", rr.Image(mapping.render_rgb))
            if gaussians is None:
                self._surface(mapping)
        if gaussians is not None:
            self._gaussians(gaussians)
        if fields is not None:
            self._fields(fields)
        if occupancy is not None:
            self._occupancy(*occupancy)
        if selection is not None:
            self._selection(selection)
        if planning is not None:
            path = np.asarray(planning.path_xy_m, np.float64)
            self.rec.log("world/path", rr.LineStrips3D([np.c_[path, np.full(len(path), FLOOR_Z_M)]],
                                                       colors=[(255, 140, 0)], radii=0.03))
        if metrics:
            for name, value in metrics.items():
                self.rec.log(f"metrics/{name}", rr.Scalars([float(value)]))

    def log_records(self, recs: Mapping[str, Any], *, gaussians: Any = None,
                    occupancy: tuple[np.ndarray, np.ndarray, float] | None = None) -> None:
        """One step given as ``{topic: record}`` (a :class:`replay.source.LoggedStep` or a writer's dict)."""
        get = recs.get
        metrics = get("/metrics")
        self.log_step(get("/frame"), truth=get("/truth"), perception=get("/perception"), mapping=get("/mapping"),
                      fields=get("/fields"), selection=get("/selection"), planning=get("/planning"),
                      gaussians=gaussians if gaussians is not None else get("/map"), occupancy=occupancy,
                      metrics=metrics.values if metrics is not None else None)

    # ------------------------------------------------------------------- pieces
    def _camera(self, frame: records.Frame) -> None:
        T = frame.T_world_cam
        self.rec.log("world/camera", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
                     rr.Pinhole(image_from_camera=frame.K, resolution=[frame.width, frame.height],
                                camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.4))
        self.rec.log("world/camera/rgb", rr.Image(frame.rgb))
        self.rec.log("world/camera/depth", rr.DepthImage(frame.depth_m, meter=1.0, colormap="turbo"))
        self._trajectory.append(T[:3, 3].copy())
        traj = np.asarray(self._trajectory)
        if len(traj) > self.max_trajectory_points:
            traj = traj[np.linspace(0, len(traj) - 1, self.max_trajectory_points).astype(int)]
        self.rec.log("world/trajectory", rr.LineStrips3D([traj], colors=[(30, 144, 255)], radii=0.02))

    def _truth(self, truth: records.SimTruth) -> None:
        self.rec.log("world/camera/people", rr.SegmentationImage(truth.people_mask.astype(np.uint8), opacity=0.5))
        p = truth.people_xy_m
        h = np.asarray(truth.people_height_m, np.float64)
        self.rec.log("world/people", rr.Capsules3D(
            lengths=np.maximum(h - 2 * PERSON_RADIUS_M, 0.0), radii=np.full(len(p), PERSON_RADIUS_M),
            translations=np.c_[p, np.full(len(p), PERSON_RADIUS_M)], colors=[(230, 60, 60)]))

    def _surface(self, mapping: records.MappingOut) -> None:
        ijk = mapping.surface_ijk
        idx = _subsample(len(ijk), self.max_map_points, len(ijk))
        pts = (ijk[idx].astype(np.float64) + 0.5) * mapping.surface_voxel_m
        self.rec.log("world/map", rr.Points3D(pts, colors=colormap(pts[:, 2], 0.0, 2.5, "cividis"),
                                              radii=0.5 * mapping.surface_voxel_m))

    def log_refined_map(self, gaussians: Any, step: int, stamp_ns: int) -> None:
        """The map after the offline refinement, at ``step`` (one past the last) on the timeline."""
        self.set_time(step, stamp_ns)
        self._gaussians(gaussians)

    def _gaussians(self, g: Any) -> None:
        means, rgb = (np.asarray(_numpy(x), np.float64) for x in (g.means, g.rgb))
        idx = _subsample(len(means), self.max_map_points, len(means))
        colors = (np.clip(rgb[idx], 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
        self.rec.log("world/map", rr.Points3D(means[idx], colors=colors, radii=0.015))

    def _fields(self, f: records.FieldsOut) -> None:
        for name, values, has_info, vmax in (("u_s", f.u_s, f.n_obs > 0, None), ("u_m", f.u_m, f.u_m > 0, None)):
            ijk = np.argwhere(has_info)
            idx = _subsample(len(ijk), self.max_voxels, len(ijk))
            ijk = ijk[idx]
            v = values[tuple(ijk.T)]
            hi = float(v.max()) if vmax is None and len(v) else 1.0
            centres = f.origin_m + (ijk + 0.5) * f.voxel_m
            self.rec.log(f"world/fields/{name}", rr.Points3D(centres, colors=colormap(v, 0.0, hi, "plasma"),
                                                             radii=0.3 * f.voxel_m))

    def _occupancy(self, logodds: np.ndarray, origin_xy_m: np.ndarray, cell_m: float) -> None:
        lo = np.asarray(logodds, np.float32)
        occ = np.where(lo == 0, 255, np.round(100.0 / (1.0 + np.exp(-lo)))).astype(np.uint8)   # ROS: 255 unknown
        h, w = occ.shape
        self.rec.log("world/occupancy", rr.GridMap(
            data=occ.tobytes(), format=rr.components.ImageFormat(width=w, height=h, color_model="L",
                                                                 channel_datatype="U8"),
            cell_size=float(cell_m), translation=[float(origin_xy_m[0]), float(origin_xy_m[1]), 0.0],
            colormap=rr.components.Colormap.RvizMap, opacity=0.6))

    def _selection(self, s: records.SelectionOut) -> None:
        nodes = np.c_[s.node_xy_m, np.full(len(s.node_xy_m), FLOOR_Z_M)]
        self.rec.log("world/graph/nodes", rr.Points3D(nodes, colors=label_colors(s.node_region), radii=0.06))
        self.rec.log("world/graph/edges", rr.LineStrips3D(nodes[s.edges] if len(s.edges) else [],
                                                          colors=[(120, 120, 120)], radii=0.01))
        if len(s.cand_node):
            origin = nodes[s.cand_node]
            d = 0.3 * np.c_[np.cos(s.cand_yaw_rad), np.sin(s.cand_yaw_rad), np.zeros(len(origin))]
            finite = np.isfinite(s.cand_score)
            lo, hi = (float(s.cand_score[finite].min()), float(s.cand_score[finite].max())) if finite.any() else (0, 1)
            self.rec.log("world/candidates", rr.Arrows3D(origins=origin, vectors=d,
                                                         colors=colormap(s.cand_score, lo, hi, "RdYlGn")))
        else:
            self.rec.log("world/candidates", rr.Clear(recursive=False))
        if np.all(np.isfinite(s.target_xy_m)):
            t = np.r_[s.target_xy_m, FLOOR_Z_M]
            yaw = s.target_yaw_rad if np.isfinite(s.target_yaw_rad) else 0.0
            self.rec.log("world/target", rr.Arrows3D(origins=[t], vectors=[[0.6 * np.cos(yaw), 0.6 * np.sin(yaw), 0]],
                                                     colors=[(255, 0, 255)], radii=0.04, labels=[_target_label(s)]))
        else:
            self.rec.log("world/target", rr.Clear(recursive=False))

    def close(self) -> None:
        """Flush everything to the file (a caller-owned stream is flushed, not closed)."""
        self.rec.flush()
        if self.path is not None:
            self.rec.disconnect()

    def __enter__(self) -> RerunSink:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def _target_label(s: records.SelectionOut) -> str:
    """The target's label: how it was chosen, and what became of the one before when that is news."""
    if s.target_reason in ("", "keep", "none") or s.mode == "keep":
        return s.mode
    return f"{s.mode} (previous {s.target_reason})"


def _numpy(x: Any) -> np.ndarray:
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def recording_id_for(path: str | Path) -> str:
    """A stable recording id derived from a log path (so a replayed run's .rrd is recognisable)."""
    return hashlib.sha1(str(Path(path).resolve()).encode()).hexdigest()[:16]
