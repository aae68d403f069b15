"""How far the selection's occupancy grid is from the scene's true free space, on logged runs.

    python benchmarks/occupancy_errors.py runs/full/apartment-00-seed1.mcap [more.mcap ...] \
        [--set selection.occupancy.logodds_max=2.0 ...]

For each run log it integrates the logged frames into an occupancy grid with the selection
stage's rule (:func:`dynactivegs.selection.occupancy.update_occupancy`, the logged depth, pose
and perception beta), once with the run's config and, with ``--set``, once more with the
overrides, and compares the grid with the simulator's free space of the static scene (people
are not in it) at 25/50/75/100 % of the run and at its worst step:

- **false occupied** (m2): cells the grid holds OCCUPIED that are free floor at least
  ``--margin`` from any obstacle (edge cells, where a cell straddles a wall face, do not count).
  These are what people standing still leave behind; they cut the graph at doorways.
- **false free** (m2): cells the grid holds FREE that lie inside an obstacle (at least one cell
  in from its edge): what rays grazing walls or passing under tables clear.
- **known free** (%): the share of the true free floor the grid holds FREE.
- **cut off** (m2): floor that a disc of the planner's radius (``voronoi.robot_radius_m + margin_m``) can
  travel in the grid and, in truth, reach from where the robot is, but that the grid parts from the robot: what
  a doorway held shut keeps out of reach; with the **steps cut off** by at least ``--cut-min`` m2 so far.
- **let go** (frames): the frames so far in which ``selection.occupancy.transient_frames`` let cells go (a cell's
  obstacle top drops back to 0 only then). A run whose what-if lets nothing go would run the same in closed loop:
  the grid, and so every choice, is the logged one.

Open loop: the frames are the logged ones, so a what-if config changes the grid, not the path.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def truth_maps(sim_cfg) -> tuple[object, np.ndarray, np.ndarray]:
    """(the scene's FreeSpace, float (H, W) distance of free cells to the nearest obstacle cell in metres,
    float (H, W) distance of obstacle cells to the nearest free cell in metres)."""
    from scipy.ndimage import distance_transform_edt

    from dynactivegs.sim import scenes

    scene = scenes.load_scene(sim_cfg)
    fs = scenes.scene_freespace(scene, scenes.scene_renderer(scene), sim_cfg.grid_res_m, sim_cfg.robot.body_height_m)
    free = fs.floor & ~fs.occupied
    return fs, distance_transform_edt(free) * fs.res_m, distance_transform_edt(~free) * fs.res_m


def truth_cell(fs, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(whether on the map, row, column) of the cells of the truth map ``fs`` (origin_xy_m, res_m, shape (rows,
    cols)) that hold the points ``xy`` (..., 2); row and column are clipped into the map, so they index its arrays
    also where the point is off it."""
    t = np.floor((np.asarray(xy, np.float64) - np.asarray(fs.origin_xy_m)) / fs.res_m).astype(np.int64)  # (col, row)
    rows, cols = fs.shape
    inside = (t[..., 0] >= 0) & (t[..., 0] < cols) & (t[..., 1] >= 0) & (t[..., 1] < rows)
    return inside, np.clip(t[..., 1], 0, rows - 1), np.clip(t[..., 0], 0, cols - 1)


def truth_pieces(clear_m: np.ndarray, radius_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The truth map's floor a disc of ``radius_m`` can travel (``clear_m`` at least ``radius_m``), once per run:
    (int labels of its 8-connected pieces, 0 elsewhere; row and column of each cell's nearest such floor)."""
    from scipy import ndimage

    passable = clear_m >= radius_m
    labels, _ = ndimage.label(passable, structure=np.ones((3, 3), np.bool_))
    _, (near_r, near_c) = ndimage.distance_transform_edt(~passable, return_indices=True)
    return labels, near_r, near_c


def cut_off_m2(grid, occ_cfg, fs, truth: tuple[np.ndarray, np.ndarray, np.ndarray], robot_xy: np.ndarray,
               radius_m: float) -> float:
    """Area (m2) of the grid's free floor that a disc of ``radius_m`` can travel in the grid and, in truth, reach
    from the robot at ``robot_xy`` (the truth's pieces, :func:`truth_pieces` for the same radius), but that the
    grid's occupied cells part, for that disc, from the piece nearest the robot (unseen floor counts as open
    here): floor that obstacles the grid holds shut off, not floor behind unseen floor or a door too narrow for the
    disc anyway."""
    from scipy import ndimage

    from dynactivegs.selection.voronoi import traversable_mask

    trav = traversable_mask(~grid.occupied(occ_cfg), grid.cell_m, radius_m)   # unseen floor does not part
    true_lab, near_r, near_c = truth
    if not trav.any() or not true_lab.any():
        return 0.0
    lab, _ = ndimage.label(trav, structure=np.ones((3, 3), np.bool_))
    i, j = np.clip(grid.world_to_cell(np.asarray(robot_xy, np.float64)), 0, np.array(grid.shape) - 1)
    _, (ri, rj) = ndimage.distance_transform_edt(~trav, return_indices=True)
    own = lab[ri[i, j], rj[i, j]]
    _, tr, tc = truth_cell(fs, np.asarray(robot_xy, np.float64))
    true_own = true_lab[near_r[tr, tc], near_c[tr, tc]]
    h, w = grid.shape
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    ok, r, c = truth_cell(fs, grid.cell_to_world(np.stack([ii, jj], axis=-1)))
    known = traversable_mask(grid.free(occ_cfg), grid.cell_m, radius_m)
    apart = known & (lab != own) & ok & (true_lab[r, c] == true_own)
    return float(apart.sum()) * grid.cell_m ** 2


def let_go_cells(before, after) -> np.ndarray:
    """bool, ``after``'s shape: the cells the update from grid ``before`` to ``after`` let go: only that sets a
    cell's obstacle top (which otherwise only rises) back to 0. The grid may have grown: ``before`` sits inside
    ``after``."""
    di, dj = before.origin_ij[0] - after.origin_ij[0], before.origin_ij[1] - after.origin_ij[1]
    h, w = before.shape
    gone = np.zeros(after.shape, np.bool_)
    gone[di:di + h, dj:dj + w] = (before.top_m > 0) & (after.top_m[di:di + h, dj:dj + w] <= 0)
    return gone


def let_go_any(before, after) -> bool:
    """Whether the update from grid ``before`` to ``after`` let a cell go (:func:`let_go_cells`)."""
    return bool(let_go_cells(before, after).any())


def grid_errors(grid, occ_cfg, fs, clear_m: np.ndarray, inside_m: np.ndarray, margin_m: float) -> dict[str, float]:
    """false occupied / false free areas (m2) and the known share (%) of the true free floor of one grid."""
    states = grid.states(occ_cfg)
    h, w = grid.shape
    ii, jj = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    xy = grid.cell_to_world(np.stack([ii, jj], axis=-1))
    ok, r, c = truth_cell(fs, xy)
    cell_area = grid.cell_m ** 2
    true_free = ok & (clear_m[r, c] > 0)
    false_occ = ok & (clear_m[r, c] >= margin_m) & (states == 2)
    false_free = ok & (inside_m[r, c] > fs.res_m) & (states == 1)
    n_free = float((fs.floor & ~fs.occupied).sum()) * fs.res_m ** 2
    return {"false_occ_m2": float(false_occ.sum()) * cell_area, "false_free_m2": float(false_free.sum()) * cell_area,
            "known_free_pct": 100.0 * float((true_free & (states == 1)).sum()) * cell_area / max(n_free, 1e-9)}


def run_errors(mcap: Path, overrides: list[str], margin_m: float,
               cut_min_m2: float = 0.25) -> tuple[str, dict[str, list[tuple[int, dict]]]]:
    """(a label, {config name: [(step, errors)] at the checkpoints and the worst step}) of one run log; the
    errors also hold ``cut_off_m2``, ``steps_cut`` (the steps so far with at least ``cut_min_m2`` cut off) and
    ``let_go`` (the frames so far that let cells go)."""
    from dynactivegs.config import with_overrides
    from dynactivegs.selection.occupancy import OccupancyGrid, update_occupancy
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    configs = {"logged": cfg.selection.occupancy}
    if overrides:
        configs["what-if"] = with_overrides(cfg, overrides).selection.occupancy
    fs, clear_m, inside_m = truth_maps(cfg.sim)
    radius_m = cfg.selection.voronoi.robot_radius_m + cfg.selection.voronoi.margin_m
    truth = truth_pieces(clear_m, radius_m)
    steps_cut, let_go = dict.fromkeys(configs, 0), dict.fromkeys(configs, 0)
    grids = {k: OccupancyGrid.empty(c.cell_m) for k, c in configs.items()}
    per_step: dict[str, list[tuple[int, dict]]] = {k: [] for k in configs}
    n = 0
    for st in reader.steps():
        f = st["/frame"]
        beta = st["/perception"].beta
        for k, c in configs.items():
            before = grids[k]
            grids[k] = update_occupancy(before, c, f.depth_m, f.K, f.T_world_cam, beta)
            let_go[k] += let_go_any(before, grids[k])
            e = grid_errors(grids[k], c, fs, clear_m, inside_m, margin_m)
            e["cut_off_m2"] = cut_off_m2(grids[k], c, fs, truth, f.T_world_cam[:2, 3], radius_m)
            steps_cut[k] += e["cut_off_m2"] >= cut_min_m2
            e["steps_cut"], e["let_go"] = steps_cut[k], let_go[k]
            per_step[k].append((st.step, e))
        n += 1
    out: dict[str, list[tuple[int, dict]]] = {}
    for k, rows in per_step.items():
        picks = [rows[max(0, int(round(fr * n)) - 1)] for fr in FRACTIONS]
        worst = max(rows, key=lambda r: r[1]["false_occ_m2"])
        out[k] = picks + [worst]
    return f"{cfg.sim.scene} seed {cfg.seed}", out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="what-if overrides, e.g. selection.occupancy.logodds_max=2.0")
    ap.add_argument("--margin", type=float, default=0.15,
                    help="false occupied cells are at least this far (m) from a true obstacle (default 0.15)")
    ap.add_argument("--cut-min", type=float, default=0.25,
                    help="a step counts as cut off when at least this much floor (m2) is (default 0.25)")
    args = ap.parse_args()
    if args.margin < 0:
        sys.exit(f"error: bad --margin {args.margin}: must be >= 0 m")
    if args.cut_min <= 0:
        sys.exit(f"error: bad --cut-min {args.cut_min}: must be > 0 m2")
    from dynactivegs.errors import DagsError

    print("| run | config | step | false occupied m2 | false free m2 | known free % | cut off m2 | steps cut off | "
          "let go (frames) |\n|---|---|---|---|---|---|---|---|---|", flush=True)
    for path in args.mcap:
        try:
            label, out = run_errors(path, args.set, args.margin, args.cut_min)
        except DagsError as e:
            sys.exit(f"error: {e}")
        for k, rows in out.items():
            for i, (step, e) in enumerate(rows):
                name = f"{step} (worst)" if i == len(FRACTIONS) else str(step)
                print(f"| {label} | {k} | {name} | {e['false_occ_m2']:.3f} | {e['false_free_m2']:.3f} | "
                      f"{e['known_free_pct']:.1f} | {e['cut_off_m2']:.2f} | {e['steps_cut']} | {e['let_go']} |",
                      flush=True)


if __name__ == "__main__":
    main()
