"""Where a run's held-out PSNR is lost: the surface the held-out views show that the run's camera never saw.

    python benchmarks/unseen_surface.py --out unseen.png runs/full/apartment-03-seed2.mcap \\
        runs/baseline/apartment-03-seed2.mcap

Held-out PSNR follows the share of the held-out views' pixels that show surface the camera saw
(**Obs. views**, :meth:`dynactivegs.eval.progress.ObservedSurface.view_share`; within-scene rank
correlation +0.94 over 50 apartment runs, benchmarks/results/apartment-1000-observed). For each run log
this replays the frames into an :class:`~dynactivegs.eval.progress.ObservedSurface` of the coverage
probe's points, takes the held-out views the evaluation renders for the run's trajectory, and

- prints one Markdown row: Obs. %, Obs. views %, and (procedural scenes) the rooms whose unseen surface
  fills the most held-out pixels, as shares of all the views' pixels (a wall's face counts for the room it
  faces);
- draws one floor-plan panel per run into ``--out`` (PNG): seen probe points grey, unseen ones the views
  show red (sized by the pixels they fill), the path blue, the held-out views as green arrows.

The evaluation settings are those of the metrics file ``dagsbench`` wrote beside the log when there is one,
else the defaults (``--set eval.KEY=VALUE`` style overrides are not taken: pass dagsbench's logs).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config, logged_eval_config  # noqa: E402  (the same reading of a run log)

ROOM_STEP_M = 0.06
"""A point belongs to the room that holds it moved this far along its normal (off the wall's face)."""


def unseen_of_run(mcap: Path) -> dict[str, Any]:
    """Replay one run log: its label, trajectory (T, 2), held-out poses, the ObservedSurface after the last
    frame, each probe point's held-out pixel weight, and the scene (for rooms)."""
    from dynactivegs.eval.metrics import SceneEvaluator
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    evaluator = SceneEvaluator(cfg.sim, logged_eval_config(mcap))
    observed = evaluator.observed_surface()
    traj = []
    for st in reader.steps():
        f = st["/frame"]
        observed.update(f.depth_m, f.K, f.T_world_cam)
        traj.append((st["/truth"].robot.x_m, st["/truth"].robot.y_m))
    if not traj:
        raise ValueError(f"{mcap}: the log holds no whole step; pass the .mcap of a run that took at least one")
    trajectory = np.asarray(traj, np.float64)
    poses, _, depth = evaluator.heldout(trajectory)
    weights = observed.view_weights(poses, depth, evaluator.K)
    label = f"{reader.metadata.get('preset', '?')} {cfg.sim.scene} seed {cfg.seed}"
    return {"label": label, "trajectory": trajectory, "poses": poses, "observed": observed, "weights": weights,
            "scene": evaluator.scene}


def room_losses(run: dict[str, Any], top: int = 3) -> list[tuple[str, float]]:
    """The ``top`` rooms whose unseen surface fills the most held-out pixels: (room name, % of all the views'
    pixels), largest first; empty for scenes without rooms."""
    rooms = run["scene"].rooms
    if not rooms:
        return []
    o, w = run["observed"], run["weights"]
    lost = w * ~o.seen
    xy = o.points_m[:, :2] + ROOM_STEP_M * o.normals[:, :2]
    out = []
    for r in rooms:
        out.append((r.name, 100.0 * float(lost[r.contains(xy)].sum()) / float(w.sum())))
    return sorted(out, key=lambda t: -t[1])[:top]


def draw(runs: list[dict[str, Any]], out: Path) -> None:
    """One floor-plan panel per run (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(runs), figsize=(6.5 * len(runs), 6), squeeze=False)
    for ax, run in zip(axes[0], runs):
        o, w, poses, traj = run["observed"], run["weights"], run["poses"], run["trajectory"]
        p = o.points_m
        ax.scatter(p[o.seen, 0], p[o.seen, 1], s=1, c="0.8", label="seen")
        lost = ~o.seen & (w > 0)
        ax.scatter(p[lost, 0], p[lost, 1], s=3 + 150 * w[lost] / max(float(w.max()), 1e-12), c="red",
                   label="unseen, in held-out views")
        ax.plot(traj[:, 0], traj[:, 1], "-", c="tab:blue", lw=0.6, label="path")
        ax.quiver(poses[:, 0, 3], poses[:, 1, 3], poses[:, 0, 2], poses[:, 1, 2], color="green", scale=25,
                  width=0.004, label="held-out views")
        ax.set_aspect("equal")
        ax.set_title(f"{run['label']}: Obs. {o.pct:.1f} %, Obs. views {run['share']:.1f} %", fontsize=10)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
    axes[0][0].legend(loc="lower left", fontsize=7, markerscale=2)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--out", type=Path, help="PNG with one floor-plan panel per run (default: none)")
    args = ap.parse_args(argv)
    if args.out is not None and args.out.suffix.lower() != ".png":
        sys.exit(f"error: bad --out {args.out}: give a .png path")
    from dynactivegs.errors import DagsError
    from dynactivegs.eval.progress import weighted_share

    print("| run | Obs. % | Obs. views % | held-out pixels lost by room (% of all) |\n|---|---|---|---|", flush=True)
    runs = []
    for path in args.mcap:
        try:
            run = unseen_of_run(path)
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        run["share"] = weighted_share(run["weights"], run["observed"].seen)
        rooms = ", ".join(f"{name} {pct:.1f}" for name, pct in room_losses(run)) or "-"
        print(f"| {run['label']} | {run['observed'].pct:.1f} | {run['share']:.1f} | {rooms} |", flush=True)
        runs.append(run)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        draw(runs, args.out)
        print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
