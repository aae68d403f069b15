"""Seeded synthetic records of every type, sized like a real run (for codec, log, viewer tests and benchmarks).

Values are shaped like the pipeline's (smooth images, depth from planes, sparse fields, a
graph with candidates) so that sizes after compression mean something; they are not a
simulation. ``edge_cases=True`` adds NaN, -0.0, infinities and empty arrays where a record
allows them.
"""

from __future__ import annotations

import numpy as np

from dynactivegs import records
from recorder.codec import Metrics, StepEnd


def _smooth(rng: np.random.Generator, h: int, w: int, cell: int = 8) -> np.ndarray:
    """float64 (h, w) in [0, 1]: bilinear upsampling of a coarse random grid."""
    gh, gw = h // cell + 2, w // cell + 2
    g = rng.random((gh, gw))
    y = np.linspace(0, gh - 1.001, h)
    x = np.linspace(0, gw - 1.001, w)
    y0, x0 = y.astype(int), x.astype(int)
    fy, fx = (y - y0)[:, None], (x - x0)[None, :]
    return ((1 - fy) * (1 - fx) * g[y0][:, x0] + (1 - fy) * fx * g[y0][:, x0 + 1]
            + fy * (1 - fx) * g[y0 + 1][:, x0] + fy * fx * g[y0 + 1][:, x0 + 1])


def camera(w: int, h: int) -> np.ndarray:
    """float64 (3, 3) intrinsics of a 90 x 60 degree camera."""
    fx = 0.5 * w / np.tan(np.radians(45))
    fy = 0.5 * h / np.tan(np.radians(30))
    return np.array([[fx, 0, w / 2], [0, fy, h / 2], [0, 0, 1]], np.float64)


def pose(x: float, y: float, yaw: float, height_m: float = 1.25) -> np.ndarray:
    """float64 (4, 4) T_world_cam of an OpenCV camera looking along ``yaw`` at ``height_m``."""
    fwd = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    right = np.array([np.sin(yaw), -np.cos(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = right, down, fwd, (x, y, height_m)
    return T


def step_records(step: int, *, seed: int = 0, w: int = 160, h: int = 92, grid: tuple[int, int, int] = (80, 70, 17),
                 n_nodes: int = 200, n_cand: int = 1000, n_surface: int = 15000, n_people: int = 3,
                 edge_cases: bool = False) -> dict[str, object]:
    """The records of one step by topic: /frame, /truth, the five stage outputs and /metrics."""
    rng = np.random.default_rng([seed, step])
    stamp_ns = 1_000_000_000 + step * 250_000_000
    yaw = 0.1 * step
    x, y = 2.0 + 0.05 * step, 3.0
    rgb = np.clip(_smooth(rng, h, w)[..., None] * [200, 180, 150] + rng.normal(0, 6, (h, w, 3)), 0, 255).astype(np.uint8)
    depth = (1.5 + 3.0 * _smooth(rng, h, w, 32)).astype(np.float32)
    depth[rng.random((h, w)) < 0.02] = 0.0
    mask = np.zeros((h, w), bool)
    mask[20:60, 40:60] = True
    frame = records.Frame(step, stamp_ns, rgb, depth, camera(w, h), pose(x, y, yaw))
    people = rng.uniform(0, 8, (n_people, 2))
    truth = records.SimTruth(step, stamp_ns, mask, records.robot_pose_of(frame), people,
                             rng.uniform(-np.pi, np.pi, n_people), rng.uniform(1.6, 1.9, n_people), bool(step % 5 == 0))
    beta = (0.101 + 0.5 * _smooth(rng, h, w, 4) ** 4).astype(np.float32)
    beta[mask] += 1.5
    perception = records.PerceptionOut(beta, float("nan") if step == 0 else float(rng.random()), step > 0)
    alpha = np.clip(1.2 * _smooth(rng, h, w, 32), 0, 1).astype(np.float32)
    surf = np.unique(rng.integers(0, [120, 100, 20], (n_surface, 3)).astype(np.int32), axis=0)
    mapping = records.MappingOut(rgb // 2 + 20, (depth * (alpha > 0.5)).astype(np.float32), alpha, surf, 0.05,
                                 10_000 + 100 * step, 120, 7, float(rng.random()), step % 3 == 0)
    X, Y, Z = grid
    n_obs = np.zeros(grid, np.float32)
    seen = _smooth(rng, X, Y, 16)[..., None] > 0.4
    n_obs[np.broadcast_to(seen, grid)] = rng.gamma(2.0, 3.0, int(seen.sum()) * Z).astype(np.float32)
    u_s = (1.0 / np.sqrt(n_obs + 1.0) + 0.2 * (n_obs > 0) * rng.random(grid)).astype(np.float32)
    u_m = np.zeros(grid, np.float32)
    busy = (slice(3 * X // 8, X // 2), slice(2 * Y // 7, 3 * Y // 7))   # a corridor where people walk
    u_m[busy] = rng.random(u_m[busy].shape).astype(np.float32)
    visible = np.zeros(grid, bool)
    visible[X // 4:5 * X // 8, Y // 7:4 * Y // 7, Z // 8:7 * Z // 8] = True
    fields = records.FieldsOut(np.array([-1.5, -1.5, 0.0]), 0.15, u_s, u_m, n_obs, visible)
    nodes = rng.uniform(0, 10, (n_nodes, 2))
    edges = np.stack([np.arange(n_nodes - 1), np.arange(1, n_nodes)], 1).astype(np.int32)
    cand_node = rng.integers(0, n_nodes, n_cand).astype(np.int32)
    gain, risk, cost = rng.random(n_cand) * 50, rng.random(n_cand) * 5, rng.random(n_cand) * 10
    selection = records.SelectionOut(nodes[7].copy(), 0.5, 7, "local", nodes, edges,
                                     np.linalg.norm(nodes[edges[:, 0]] - nodes[edges[:, 1]], axis=1),
                                     (np.arange(n_nodes) // 25).astype(np.int32), rng.random(n_nodes) < 0.1,
                                     rng.random(n_nodes) < 0.9, cand_node, rng.uniform(-np.pi, np.pi, n_cand), gain, risk, cost,
                                     gain - 0.5 * risk - 0.1 * cost, rng.uniform(0.0, 0.6, (24, 24)).astype(np.float32),
                                     np.array([x - 0.6, y - 0.6]), 0.05, ("keep", "stuck", "reached")[step % 3])
    path = np.linspace([x, y], nodes[7], 12)
    planning = records.PlanningOut(step % 3, path, float(rng.random() * 10), step % 4 == 0, False, False)
    metrics = Metrics(step, {"mapping/loss": mapping.loss, "gaussians": float(mapping.n_gaussians),
                             "coverage": min(1.0, 0.01 * step)})
    if edge_cases:
        perception = records.PerceptionOut(np.array([[np.nan, -0.0, np.inf], [-np.inf, 1e-45, 3.0]], np.float32),
                                           float("nan"), False)
        nan_payload = np.array([0x7FC00001, 0xFFC12345], np.uint32).view(np.float32)   # NaNs with payloads
        fields = records.FieldsOut(np.array([np.nan, -0.0, 1e300]), 0.15, np.zeros((0, 3, 2), np.float32),
                                   np.zeros((0, 3, 2), np.float32), np.zeros((0, 3, 2), np.float32),
                                   np.zeros((0, 3, 2), bool))
        mapping = records.MappingOut(mapping.render_rgb, mapping.render_depth_m, alpha, np.zeros((0, 3), np.int32),
                                     0.05, 0, 0, 0, float("nan"), False)
        planning = records.PlanningOut(3, np.zeros((0, 2)), float("nan"), True, True, True)
        selection = records.SelectionOut(np.array([np.nan, np.nan]), float("nan"), -1, "none",
                                         np.zeros((0, 2)), np.zeros((0, 2), np.int32), np.zeros(0), np.zeros(0, np.int32),
                                         np.zeros(0, bool), np.zeros(0, bool), np.zeros(0, np.int32), np.zeros(0),
                                         np.zeros(0), np.zeros(0),
                                         np.zeros(0), np.zeros(0), np.zeros((0, 0), np.float32), np.zeros(2), 0.0,
                                         "none")
        truth = records.SimTruth(step, stamp_ns, mask, truth.robot, np.zeros((0, 2)), np.zeros(0), np.zeros(0), False)
        metrics = Metrics(step, {"nan": float("nan"), "payload": float(nan_payload[0]), "neg0": -0.0})
    return {"/frame": frame, "/truth": truth, "/perception": perception, "/mapping": mapping, "/fields": fields,
            "/selection": selection, "/planning": planning, "/metrics": metrics}


def all_record_types(step: int = 3, seed: int = 0, edge_cases: bool = False, **size: int) -> list[object]:
    """One instance of every type in :data:`recorder.codec.RECORD_TYPES` (small sizes unless given)."""
    size = {"w": 24, "h": 16, "grid": (6, 5, 4), "n_nodes": 9, "n_cand": 20, "n_surface": 50, **size}
    recs = step_records(step, seed=seed, edge_cases=edge_cases, **size)
    full = records.StepRecord(recs["/frame"], recs["/mapping"], recs["/perception"], recs["/mapping"],
                              recs["/fields"], recs["/selection"], recs["/planning"])
    return [*recs.values(), recs["/truth"].robot, full, records.StepRecord(recs["/frame"]),
            StepEnd(step, recs["/frame"].stamp_ns, 8)]
