"""Where a run's held-out PSNR is lost: holes, wrong depth, or appearance on the right surface.

    python benchmarks/psnr_breakdown.py runs/full/apartment-01-seed0.mcap [more.mcap ...] [--online]

For each run log it renders the refined map (``--online``: the last map snapshot, the map as the
loop left it) at the run's held-out views, the same views and ground truth ``dagsbench`` scores (with
the evaluation settings of the metrics file beside the log, if there is one),
and splits each view's pixels four ways (:func:`dynactivegs.eval.rendering.psnr_split`):

- **hole**: the render's opacity is below 0.9 (the map has nothing there);
- **front**: the rendered depth is nearer than the true depth by more than max(10 cm, 5 %)
  (floaters, or a surface where there is none);
- **behind**: farther by as much (the true surface is missing and the view sees past it);
- **right**: the rest, pixels whose surface is in the right place.

``dagsbench`` keeps the means of this split in each run's metrics (``hole_err_pct``,
``front_err_pct``, ``behind_err_pct``, ``psnr_right_db``); this script gives it for logs measured
before that, for the map as the loop left it, and with the worst views.

Across those classes it splits the pixels by the path (:func:`dynactivegs.eval.rendering.seen_split`):
**unseen** pixels show surface the run's camera never saw (each pixel's true surface point, replayed
through the run's frames with the rule of Obs. views: within 3 cm of a frame's depth return), and the
PSNR over the seen ones alone is what the map made of what it was shown. Where two runs' held-out PSNR
differ, this tells the path's share from the map's.

It prints the PSNR, each class's share of the pixels and of the squared error, the PSNR over
the ``right`` pixels alone (what the colours of correctly placed Gaussians reach), the unseen
pixels' shares, the PSNR over the seen ones and, beside it, over all pixels the same way, and the worst
views. All numbers are means over views, except the unseen / seen columns, which pool the pixels of all
views (a view showing little seen surface would otherwise weigh as much as one that shows nothing else);
pooled PSNR lies below the mean of per-view PSNRs, so compare the seen one with the pooled one beside it.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def logged_config(reader, mcap: Path):
    """The run's :class:`~dynactivegs.config.Config` from the log opened in ``reader``."""
    from dynactivegs.config import config_from_json
    from dynactivegs.errors import DagsError

    if reader.config_json is None:
        raise DagsError(f"{mcap}: the log has no config; it was not written by dagsrun or dagsbench")
    return config_from_json(reader.config_json)


def logged_eval_config(mcap: Path):
    """The evaluation settings of the run logged in ``mcap``: those of the metrics file ``dagsbench`` wrote beside
    the log when there is one, else the defaults."""
    import json

    from dynactivegs.config import config_from_json
    from dynactivegs.eval.config import EvalConfig

    metrics = Path(mcap).with_suffix(".json")
    if not metrics.is_file():
        return EvalConfig()
    try:
        return config_from_json(json.dumps(json.loads(metrics.read_text())["eval_config"]), EvalConfig)
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"metrics file {metrics} is not dagsbench's ({type(e).__name__}: {e}); move it away "
                         "to use the default evaluation") from e


def chosen_map(reader, last_map, online: bool, mcap: Path):
    """The map to measure: the log's refined map, or (``online``) ``last_map``, its last snapshot."""
    from dynactivegs.errors import DagsError

    g = last_map if online else reader.refined_map()
    if g is None:
        raise DagsError(f"{mcap}: no {'map snapshot' if online else 'refined map'} in the log"
                        f"{'' if online else '; pass --online to use the last map snapshot'}")
    return g


def run_breakdown(mcap: Path, online: bool) -> tuple[str, list[dict[str, Any]]]:
    """(a label, one breakdown per held-out view) of the run logged in ``mcap``: the PSNR, the fields of its
    :class:`~dynactivegs.eval.rendering.PsnrSplit`, and under ``seen`` its
    :class:`~dynactivegs.eval.rendering.SeenSplit`."""
    import torch

    from dynactivegs.eval.metrics import SceneEvaluator
    from dynactivegs.eval.progress import ObservedSurface, pixel_points
    from dynactivegs.eval.rendering import psnr_db, psnr_split, seen_split
    from dynactivegs.splat.render import render
    from recorder.mcap_log import MAP_TOPIC
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    traj, frames, last_map = [], [], None
    for st in reader.steps():
        traj.append((st["/truth"].robot.x_m, st["/truth"].robot.y_m))
        f = st["/frame"]
        frames.append((f.depth_m, f.K, f.T_world_cam))
        if MAP_TOPIC in st:
            last_map = st[MAP_TOPIC]
    g = chosen_map(reader, last_map, online, mcap)
    ev = SceneEvaluator(cfg.sim, logged_eval_config(mcap))
    poses, rgb, depth = ev.heldout(np.asarray(traj, np.float64))
    points, has_return = pixel_points(poses, depth, ev.K)
    observed = ObservedSurface(points)
    for frame in frames:
        observed.update(*frame)
    seen = np.zeros_like(has_return)
    seen[has_return] = observed.seen
    cam = cfg.sim.camera
    rows = []
    with torch.no_grad():
        for i, T in enumerate(poses):
            out = render(g, ev.K, T, cam.width_px, cam.height_px, near_plane=cam.min_depth_m)
            split = psnr_split(out.rgb, out.depth.cpu().numpy(), out.alpha.cpu().numpy(), rgb[i], depth[i])
            rows.append({"psnr_db": psnr_db(out.rgb, rgb[i]), **dataclasses.asdict(split),
                         "seen": seen_split(out.rgb, rgb[i], seen[i])})
    label = f"{cfg.sim.scene} seed {cfg.seed}, {Path(mcap).parent.name}"
    return label, rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsbench writes them under OUT/runs/PRESET/)")
    ap.add_argument("--online", action="store_true", help="the last map snapshot instead of the refined map")
    ap.add_argument("--worst", type=int, default=3, help="how many of the worst views to list")
    args = ap.parse_args(argv)
    from dynactivegs.errors import DagsError
    from dynactivegs.eval.rendering import SeenSplit

    head = ("| run | PSNR | hole px / err | front px / err | behind px / err | PSNR right px | unseen px / err "
            "| PSNR seen / all px | worst views (dB) |\n|---|---|---|---|---|---|---|---|---|")
    print(head, flush=True)
    for path in args.mcap:
        try:
            label, rows = run_breakdown(path, args.online)
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        mean = {k: float(np.nanmean([r[k] for r in rows])) for k in rows[0] if k != "seen"}
        unseen_px, unseen_err, seen_psnr, all_psnr = SeenSplit.pooled([r["seen"] for r in rows])
        worst = ", ".join(f"{x:.1f}" for x in sorted(r["psnr_db"] for r in rows)[:args.worst])
        print(f"| {label} | {mean['psnr_db']:.2f} | "
              + " | ".join(f"{100 * mean[f'{c}_px']:.1f} / {100 * mean[f'{c}_err']:.1f} %"
                           for c in ("hole", "front", "behind"))
              + f" | {mean['right_psnr_db']:.2f} | {100 * unseen_px:.1f} / {100 * unseen_err:.1f} %"
              + f" | {seen_psnr:.2f} / {all_psnr:.2f} | {worst} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
