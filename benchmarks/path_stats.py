"""How a run's path spent its steps, from its log: where two presets' maps differ by their paths.

    python benchmarks/path_stats.py runs/full/apartment-03-seed1.mcap runs/baseline/apartment-03-seed1.mcap

For each run log it reads the logged poses, selection and planning outputs and the simulator's
truth and prints one Markdown row:

- **path m**: the distance the robot drove; **cells**: the distinct ``--cell`` m floor cells it
  stood in (how much of the flat it went through);
- **targets**: new targets chosen, split by how (``local``: in the robot's subregion, ``global``:
  in another, eq. 10 for ``full``; for the other scored variants the same split by where the best
  view lay; ``random`` and ``frontier`` choices are not counted), and what became of the previous
  ones: **reached**, **given up** (unreachable, stuck or timed out), and the steps per reached target;
- **actions**: forward / turn / stop steps, the steps the local collision check blocked, and the
  steps whose move the simulator stopped (collisions);
- **blocked episodes**: how many times the robot was held up: runs of blocked steps, two runs merged when
  at most ``EPISODE_GAP`` steps lie between them (a robot waiting for someone turns between tries), so
  blocked / episodes is how long a hold-up lasted and episodes how often one began;
- **detour %**: the share of steps the robot followed a path longer (by more than ``DETOUR_TOL``) than
  the shortest graph path between the same two nodes: where the planner's motion term (eq. 11) or a blocked
  spot's penalty made it go round; **loops**: the mean number of independent cycles (edges - nodes +
  components) of the selection's graph over the steps, how many ways round anything the graph offers (a
  tree offers none, and then every edge cost gives the same path);
- **people near**: the mean number of people within ``NEAR_M`` of the robot per step (the simulator's
  truth): how much of the crowd the path went through;
- **people px %**: the share of the camera's pixels that saw a person, over all steps (what the
  camera spent on what the map must not keep).

With ``--metrics`` each row also gets the run's refined C.R. and PSNR (from the metrics file ``dagsbench``
wrote beside the log) and its observed surface (**Obs. %**: the share of the coverage probe's ground-truth
points the camera saw, :class:`dynactivegs.eval.progress.ObservedSurface`; **Obs. views %**: the share of
the held-out views' pixels showing surface it saw; from the metrics file, or measured here from the log's
frames for runs made before they were recorded), and a last line gives the rank correlation (Spearman) of
path m, cells, reached targets, Obs. and Obs. views with PSNR over the runs, each taken
relative to its scene's mean (scenes differ in how high PSNR can go): which of the path's traits go with a
better map.

Two presets that map the same way (open loop, ``refine_passes.py --set``) but score differently
closed loop differ here: the map a path allows depends on where it went and what it looked at.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

GIVE_UP = ("unreachable", "stuck", "timeout")
COLUMNS = ("run", "path m", "cells", "targets local / global", "reached", "given up", "steps per reached",
           "forward / turn / stop", "blocked", "blocked episodes", "collisions", "detour %", "loops", "people near",
           "people px %")
EPISODE_GAP = 5
"""Two runs of blocked steps with at most this many other steps between them are one episode."""
NEAR_M = 1.5
"""People within this distance (m) of the robot count as near it."""
DETOUR_TOL = 0.05
"""A held path more than this fraction longer than the shortest graph path between its end nodes is a detour."""


def episode_spans(blocked: np.ndarray, gap: int = EPISODE_GAP) -> list[tuple[int, int]]:
    """The episodes in the per-step ``blocked`` flags as (first, last) blocked step: runs of blocked steps, merged
    when at most ``gap`` unblocked steps lie between two."""
    idx = np.flatnonzero(blocked)
    if len(idx) == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > gap + 1)
    return [(int(a), int(b)) for a, b in zip(np.r_[idx[0], idx[breaks + 1]], np.r_[idx[breaks], idx[-1]])]


def blocked_episodes(blocked: np.ndarray, gap: int = EPISODE_GAP) -> int:
    """The number of episodes in the per-step ``blocked`` flags (:func:`episode_spans`)."""
    return len(episode_spans(blocked, gap))


def cycle_rank(n_nodes: int, edges: np.ndarray) -> int:
    """Independent cycles of an undirected graph with ``n_nodes`` nodes and ``edges`` (E, 2): E - N + components."""
    from scipy.sparse.csgraph import connected_components

    from dynactivegs.planning.paths import cost_matrix
    from dynactivegs.selection.voronoi import edge_list_arrays

    if n_nodes == 0:
        return 0
    arrays = edge_list_arrays(n_nodes, edges, np.ones(len(edges)))
    n_comp = connected_components(cost_matrix(arrays, arrays.length_m), directed=False)[0]
    return int(len(edges) - n_nodes + n_comp)


def detour_ratio(node_xy: np.ndarray, edges: np.ndarray, length_m: np.ndarray, path_xy: np.ndarray) -> float:
    """How much longer a planned path's node chain is than the shortest graph path between its end nodes
    (1 = the shortest). ``path_xy`` (P, 2) is a :class:`~dynactivegs.records.PlanningOut` path: the robot, then
    graph node positions, then the target; the points that are nodes (within 1 mm) make the chain, each link
    measured by its edge's ``length_m`` (straight, when two are not joined by an edge). 1 when fewer than two
    of them are nodes."""
    from dynactivegs.planning.paths import cost_matrix, dijkstra
    from dynactivegs.selection.voronoi import edge_list_arrays

    if len(node_xy) == 0 or len(path_xy) < 2:
        return 1.0
    d = np.hypot(*(node_xy[None, :, :] - path_xy[:, None, :]).transpose(2, 0, 1))        # (P, N)
    chain = [int(k) for k, ok in zip(d.argmin(axis=1), d.min(axis=1) < 1e-3) if ok]
    chain = [k for i, k in enumerate(chain) if i == 0 or k != chain[i - 1]]
    if len(chain) < 2:
        return 1.0
    arrays = edge_list_arrays(len(node_xy), edges, length_m)
    lengths = cost_matrix(arrays, arrays.length_m)
    held = sum(float(lengths[a, b]) or float(np.hypot(*(node_xy[a] - node_xy[b])))
               for a, b in zip(chain[:-1], chain[1:]))
    best = float(dijkstra(arrays, arrays.length_m, chain[0])[0][chain[-1]])
    return held / best if best > 0 else 1.0


def path_stats(mcap: Path, cell_m: float, observed: Any = None, evaluator: Any = None
               ) -> tuple[str, str, dict[str, float]]:
    """(a label, the scene, the numbers of the module docstring) of one run log; with ``observed`` (an
    :class:`~dynactivegs.eval.progress.ObservedSurface`, updated with every logged frame) also its
    ``observed_pct``, and with ``evaluator`` too (the scene's
    :class:`~dynactivegs.eval.metrics.SceneEvaluator`) its ``observed_view_pct``."""
    from dynactivegs.records import robot_pose_of
    from dynactivegs.sim.robot import Action
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    xy, truth_xy, people, reasons, modes = [], [], [], collections.Counter(), collections.Counter()
    actions, blocked, collisions, near = collections.Counter(), [], 0, []
    detour, loops, sel_now, ratio = [], [], None, 1.0
    for st in reader.steps():
        frame = st["/frame"]
        if observed is not None:
            observed.update(frame.depth_m, frame.K, frame.T_world_cam)
        pose = robot_pose_of(frame)
        xy.append((pose.x_m, pose.y_m))
        truth = st["/truth"]
        truth_xy.append((truth.robot.x_m, truth.robot.y_m))
        people.append(float(truth.people_mask.mean()))
        near.append(int((np.hypot(*(truth.people_xy_m - truth_xy[-1]).T) < NEAR_M).sum()))   # (P, 2), P may be 0
        collisions += bool(truth.collided)
        sel, plan = st.get("/selection"), st.get("/planning")
        if sel is not None:
            sel_now = sel
            loops.append(cycle_rank(len(sel.node_xy_m), sel.edges))
            reasons[sel.target_reason] += 1
            if sel.target_reason != "keep" and sel.mode in ("local", "global"):
                modes[sel.mode] += 1
        if plan is not None:
            actions[Action(plan.action)] += 1
            if plan.replanned and sel_now is not None:
                ratio = detour_ratio(sel_now.node_xy_m, sel_now.edges, sel_now.edge_length_m, plan.path_xy_m)
            detour.append(ratio > 1.0 + DETOUR_TOL)
        blocked.append(plan is not None and bool(plan.blocked))
    if not xy:
        raise ValueError(f"{mcap}: the log holds no whole step; pass the .mcap of a run that took at least one")
    pos = np.asarray(xy)
    reached = reasons["reached"]
    out = {
        "steps": len(pos),
        "path_m": float(np.hypot(*np.diff(pos, axis=0).T).sum()),
        "cells": len({tuple(c) for c in np.floor(pos / cell_m).astype(np.int64)}),
        "local": modes["local"], "global": modes["global"],
        "reached": reached, "given_up": sum(reasons[k] for k in GIVE_UP),
        "steps_per_reached": len(pos) / reached if reached else float("nan"),
        "forward": actions[Action.FORWARD], "turn": actions[Action.TURN_LEFT] + actions[Action.TURN_RIGHT],
        "stop": actions[Action.STOP], "blocked": int(np.sum(blocked)), "episodes": blocked_episodes(np.array(blocked)),
        "collisions": collisions, "detour_pct": 100.0 * float(np.mean(detour)) if detour else 0.0,
        "loops": float(np.mean(loops)) if loops else 0.0, "people_near": float(np.mean(near)),
        "people_pct": 100.0 * float(np.mean(people)),
    }
    if observed is not None:
        out["observed_pct"] = observed.pct
        if evaluator is not None:
            out["observed_view_pct"] = evaluator.observed_view_pct(observed, np.asarray(truth_xy))
    return f"{reader.metadata.get('preset', '?')} {cfg.sim.scene} seed {cfg.seed}", cfg.sim.scene, out


def run_metrics(mcap: Path) -> tuple[float, float, float | None, float | None, Any, Any]:
    """(C.R. %, PSNR dB, observed surface %, its share of the held-out views %, and when the file predates
    either (they are None then) an :class:`~dynactivegs.eval.progress.ObservedSurface` and the scene's
    :class:`~dynactivegs.eval.metrics.SceneEvaluator` to measure them from the log with) of the last
    checkpoint of the metrics file dagsbench wrote beside ``mcap``."""
    from dynactivegs.config import config_from_json
    from dynactivegs.eval.config import EvalConfig
    from dynactivegs.eval.metrics import SceneEvaluator

    path = mcap.with_suffix(".json")
    if not path.is_file():
        raise ValueError(f"no metrics file {path} beside the log; pass logs from dagsbench's OUT/runs/PRESET/ "
                         "or leave out --metrics")
    try:
        done = json.loads(path.read_text())
        last = done["checkpoints"][-1]
        cr, psnr, seen, views = (float(last["cr_pct"]), float(last["psnr_db"]), last.get("observed_pct"),
                                 last.get("observed_view_pct"))
        if seen is not None and views is not None:
            return cr, psnr, float(seen), float(views), None, None
        cfg = config_from_json(json.dumps(done["config"]))
        ecfg = config_from_json(json.dumps(done["eval_config"]), EvalConfig)
    except (ValueError, KeyError, IndexError, TypeError) as e:
        raise ValueError(f"metrics file {path} is not dagsbench's ({type(e).__name__}: {e}); "
                         "re-run dagsbench --reevaluate for that run") from e
    evaluator = SceneEvaluator(cfg.sim, ecfg)
    return cr, psnr, None, None, evaluator.observed_surface(), evaluator


TRAITS = ("path_m", "cells", "reached", "observed_pct", "observed_view_pct")


def within_scene_correlations(runs: list[tuple[str, dict[str, float], float]]
                               ) -> tuple[dict[str, tuple[float, float]], int] | None:
    """Spearman (rho, p) of each of TRAITS with PSNR over ``runs`` (scene, stats, psnr_db), every value taken
    relative to its scene's mean, and how many runs that was (those of scenes with 2 runs or more); None when
    that is fewer than 3."""
    from scipy.stats import spearmanr

    by_scene: dict[str, list[tuple[dict[str, float], float]]] = collections.defaultdict(list)
    for scene, stats, psnr in runs:
        by_scene[scene].append((stats, psnr))
    groups = [g for g in by_scene.values() if len(g) >= 2]
    if sum(len(g) for g in groups) < 3:
        return None
    psnr = np.concatenate([np.array([p for _, p in g]) - np.mean([p for _, p in g]) for g in groups])
    out = {}
    for t in TRAITS:
        if not all(t in s for g in groups for s, _ in g):
            continue
        x = np.concatenate([np.array([s[t] for s, _ in g], float) - np.mean([s[t] for s, _ in g]) for g in groups])
        rho, p = spearmanr(x, psnr)
        out[t] = (float(rho), float(p))
    return out, len(psnr)


def row(label: str, s: dict[str, float]) -> str:
    return (f"| {label} | {s['path_m']:.1f} | {s['cells']} | {s['local']} / {s['global']} | {s['reached']} | "
            f"{s['given_up']} | {s['steps_per_reached']:.0f} | {s['forward']} / {s['turn']} / {s['stop']} | "
            f"{s['blocked']} | {s['episodes']} | {s['collisions']} | {s['detour_pct']:.1f} | {s['loops']:.1f} | "
            f"{s['people_near']:.2f} | {s['people_pct']:.1f} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--cell", type=float, default=0.5, help="floor cell size (m) for the cells count (default 0.5)")
    ap.add_argument("--metrics", action="store_true",
                    help="add each run's C.R. and PSNR from its metrics file, and the traits' correlation with PSNR")
    args = ap.parse_args(argv)
    if not args.cell > 0:
        sys.exit(f"error: bad --cell {args.cell}: must be > 0 m")
    from dynactivegs.errors import DagsError

    columns = COLUMNS + (("C.R. %", "PSNR dB", "Obs. %", "Obs. views %") if args.metrics else ())
    print("| " + " | ".join(columns) + " |\n" + "|---" * len(columns) + "|", flush=True)
    runs = []
    for path in args.mcap:
        try:
            metrics = run_metrics(path) if args.metrics else None
            label, scene, stats = path_stats(path, args.cell, *(metrics[4:] if metrics else ()))
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        line = row(label, stats)
        if metrics is not None:
            if metrics[4] is None:                        # from the metrics file
                stats.update(observed_pct=metrics[2], observed_view_pct=metrics[3])
            line += (f" {metrics[0]:.1f} | {metrics[1]:.2f} | {stats['observed_pct']:.1f} |"
                     f" {stats['observed_view_pct']:.1f} |")
            runs.append((scene, stats, metrics[1]))
        print(line, flush=True)
    if args.metrics:
        corr = within_scene_correlations(runs)
        print("\nwithin-scene rank correlation with PSNR: " + (
            "needs 3 runs or more in scenes with 2 or more" if corr is None else
            ", ".join(f"{t.replace('_', ' ')} {rho:+.2f} (p {p:.2g})" for t, (rho, p) in corr[0].items())
            + f" over {corr[1]} runs"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
