"""What the cut rule lets go on logged runs: people or furniture, and whether people returns tell them apart.

    python benchmarks/let_go_events.py runs/full/apartment-03-seed0.mcap [more.mcap ...] [--set KEY=VALUE ...]

For each run log it integrates the logged frames (depth, pose, perception beta) into the selection's occupancy
grid (:func:`dynactivegs.selection.occupancy.update_occupancy`) with the run's config and the ``--set``
overrides (open loop: the path is the logged one), and at every frame that lets cells go
(``selection.occupancy.transient_frames``) prints one row per let-go piece (8-connected): its cells, how many of
them lie on the simulator's free floor of the static scene (people are not in it: such a cell was held by
someone standing; the rest lie in furniture or walls), its highest obstacle top before, and the most frames in
which a cell of the piece or within ``transient_clear_m`` of it held people returns
(:attr:`~dynactivegs.selection.occupancy.OccupancyGrid.people`): the test of
``selection.occupancy.transient_people_frames`` (in brackets: of a cell of the piece itself). The last lines
count the pieces on free floor and in furniture that each threshold of that test (1, 2, 5, 10 frames) would have kept.

A piece counts as furniture when most of its cells are not free floor in truth (the truth map's cells are
``sim.grid_res_m``, so a piece against a face of furniture may hold a cell of each).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from occupancy_errors import let_go_cells, truth_cell, truth_maps  # noqa: E402  (the same truth map and let-go)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

THRESHOLDS = (1, 2, 5, 10)


def pieces_let_go(before, after, fs, clear_m: np.ndarray, clear_r: float) -> list[dict]:
    """One dict per 8-connected piece of cells the update from grid ``before`` to ``after`` let go (obstacle top
    back to 0; ``after`` may have grown): cells, free (of them on the truth map ``fs``'s free floor: ``clear_m``
    > 0), top_m (its highest top before), people (the most people-return frames of a cell of it or within
    ``clear_r`` cells of it, in ``after``) and own (of a cell of it)."""
    from scipy import ndimage

    gone = let_go_cells(before, after)
    if not gone.any():
        return []
    di, dj = before.origin_ij[0] - after.origin_ij[0], before.origin_ij[1] - after.origin_ij[1]
    h, w = before.shape
    top_before = np.zeros(after.shape, np.float32)
    top_before[di:di + h, dj:dj + w] = before.top_m
    r = int(round(clear_r))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    pieces, n = ndimage.label(gone, structure=np.ones((3, 3), np.bool_))
    out = []
    for k in range(1, n + 1):
        piece = pieces == k
        ij = np.argwhere(piece)
        ok, rr, cc = truth_cell(fs, after.cell_to_world(ij))
        near = ndimage.binary_dilation(piece, structure=yy ** 2 + xx ** 2 <= r * r)
        out.append({"cells": len(ij), "free": int((ok & (clear_m[rr, cc] > 0)).sum()),
                    "top_m": float(top_before[piece].max()), "people": int(after.people[near].max()),
                    "own": int(after.people[piece].max())})
    return out


def run_events(mcap: Path, overrides: list[str]) -> tuple[str, list[dict]]:
    """(a label, one dict per let-go piece, :func:`pieces_let_go`, with its step) of one run log."""
    from dynactivegs.config import with_overrides
    from dynactivegs.selection.occupancy import OccupancyGrid, update_occupancy
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    if overrides:
        cfg = with_overrides(cfg, overrides)
    occ = cfg.selection.occupancy
    fs, clear_m, _ = truth_maps(cfg.sim)
    grid = OccupancyGrid.empty(occ.cell_m)
    events: list[dict] = []
    for st in reader.steps():
        f = st["/frame"]
        before = grid
        grid = update_occupancy(before, occ, f.depth_m, f.K, f.T_world_cam, st["/perception"].beta)
        events += [{"step": st.step, **e} for e in pieces_let_go(before, grid, fs, clear_m,
                                                                  occ.transient_clear_m / occ.cell_m)]
    return f"{cfg.sim.scene} seed {cfg.seed}", events


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="overrides of the logged config, e.g. selection.occupancy.transient_frames=50")
    args = ap.parse_args()
    from dynactivegs.errors import DagsError

    print("| run | step | cells | on free floor | top m | people-return frames near (own) | what |\n"
          "|---|---|---|---|---|---|---|", flush=True)
    kept = {t: [0, 0] for t in THRESHOLDS}                   # [people kept, furniture kept]
    kept_own = {t: [0, 0] for t in THRESHOLDS}               # the same with the piece's own cells only
    total = [0, 0]
    for path in args.mcap:
        try:
            label, events = run_events(path, args.set)
        except DagsError as e:
            sys.exit(f"error: {e}")
        for e in events:
            furniture = 2 * e["free"] < e["cells"]
            total[furniture] += 1
            for t in THRESHOLDS:
                kept[t][furniture] += e["people"] < t
                kept_own[t][furniture] += e["own"] < t
            print(f"| {label} ({path.parent.name}) | {e['step']} | {e['cells']} | {e['free']} | {e['top_m']:.2f} | "
                  f"{e['people']} ({e['own']}) | {'furniture' if furniture else 'person'} |", flush=True)
    print(f"\npieces let go: {total[0]} on free floor (people), {total[1]} in furniture or walls")
    for t in THRESHOLDS:
        print(f"transient_people_frames {t}: would keep {kept[t][0]} of {total[0]} people pieces and "
              f"{kept[t][1]} of {total[1]} furniture pieces; with the piece's own cells only {kept_own[t][0]} and "
              f"{kept_own[t][1]}")


if __name__ == "__main__":
    main()
