"""Time of the selection's occupancy-grid update per frame under its let-go rules, on a logged run's frames.

    python benchmarks/bench_occupancy_rules.py runs/full/apartment-03-seed0.mcap [--steps 1000] [--frames 50]

The logged frames (depth, pose, perception beta) are integrated into three grids side by side, one frame at a
time each, so the three share the machine's state: the run's own config, the plain rule
(``selection.occupancy.transient_frames``) and the cut rule (``transient_frames`` with
``transient_cut_m`` = the planner's disc, ``voronoi.robot_radius_m + margin_m``). Prints one table: per config the
mean, median and max milliseconds of :func:`dynactivegs.selection.occupancy.update_occupancy` per frame, and
the frames in which it let cells go (the first frame, which compiles the ray kernel, is integrated but not
timed). Open loop: the path is the logged one under every config.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from occupancy_errors import let_go_any  # noqa: E402  (the same test of a let-go)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)


def time_rules(mcap: Path, steps: int, frames: int) -> tuple[str, dict[str, dict[str, float]]]:
    """(a label, {config: {"mean_ms", "median_ms", "max_ms", "let_go", "frames"}}) over the first ``steps``
    logged frames of ``mcap``."""
    from dynactivegs.config import with_overrides
    from dynactivegs.selection.occupancy import OccupancyGrid, update_occupancy
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    disc_m = cfg.selection.voronoi.robot_radius_m + cfg.selection.voronoi.margin_m
    plain = [f"selection.occupancy.transient_frames={frames}", "selection.occupancy.transient_cut_m=0"]
    configs = {"logged": cfg.selection.occupancy,
               f"plain rule ({frames} frames)": with_overrides(cfg, plain).selection.occupancy,
               f"cut rule ({frames} frames, {disc_m:.2f} m)": with_overrides(
                   cfg, [plain[0], f"selection.occupancy.transient_cut_m={disc_m}"]).selection.occupancy}
    grids = {k: OccupancyGrid.empty(c.cell_m) for k, c in configs.items()}
    ms: dict[str, list[float]] = {k: [] for k in configs}
    let_go = dict.fromkeys(configs, 0)
    for st in reader.steps():
        if st.step >= steps:
            break
        f, beta = st["/frame"], st["/perception"].beta
        for k, c in configs.items():
            before = grids[k]
            t0 = time.perf_counter()
            grids[k] = update_occupancy(before, c, f.depth_m, f.K, f.T_world_cam, beta)
            if st.step > 0:                            # the first frame compiles the ray kernel: not timed
                ms[k].append(1000.0 * (time.perf_counter() - t0))
            let_go[k] += let_go_any(before, grids[k])
    out = {k: {"mean_ms": float(np.mean(v)), "median_ms": float(np.median(v)), "max_ms": float(np.max(v)),
               "let_go": let_go[k], "frames": len(v)} for k, v in ms.items() if v}
    return f"{cfg.sim.scene} seed {cfg.seed}", out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--steps", type=int, default=1000, help="frames of each log to integrate (default 1000)")
    ap.add_argument("--frames", type=int, default=50,
                    help="transient_frames of the two let-go rules (default 50)")
    args = ap.parse_args()
    if args.steps < 1:
        sys.exit(f"error: bad --steps {args.steps}: must be >= 1")
    if args.frames < 1:
        sys.exit(f"error: bad --frames {args.frames}: must be >= 1")
    from dynactivegs.errors import DagsError

    print("| run | config | frames | mean ms | median ms | max ms | let go (frames) |\n"
          "|---|---|---|---|---|---|---|", flush=True)
    for path in args.mcap:
        try:
            label, out = time_rules(path, args.steps, args.frames)
        except DagsError as e:
            sys.exit(f"error: {e}")
        for k, r in out.items():
            print(f"| {label} | {k} | {r['frames']} | {r['mean_ms']:.1f} | {r['median_ms']:.1f} | "
                  f"{r['max_ms']:.1f} | {r['let_go']} |", flush=True)


if __name__ == "__main__":
    main()
