"""Render one picture of a real run laid out like the Rerun viewer's default blueprint.

The data is what the Rerun timeline of the same run holds (``dagsrun --rrd``): the camera's
RGB, beta, the map's render at the camera pose and the people mask (from the simulator's
ground truth, which no stage reads); a top-down view with the Gaussian map, U_m on the floor,
the Voronoi graph coloured by subregion, the candidate views, the target, the planned path,
the trajectory and the people; and two metric plots. For machines without a screen, and for
the README.

    python examples/render_run_png.py [--steps 120] [--preset full] [--out docs/viewer.png]
"""

from __future__ import annotations

import argparse
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from dynactivegs.config import preset  # noqa: E402
from dynactivegs.fields.project import motion_floor_map  # noqa: E402
from dynactivegs.pipeline import run  # noqa: E402


class Keep:
    """A pipeline sink keeping the last step's records and the per-step numbers."""

    def __init__(self) -> None:
        self.traj, self.n_gauss, self.loss = [], [], []
        self.last = None
        self.cands = None          # (step, SelectionOut) of the last step that scored candidate views

    def on_step(self, rec, truth, states, metrics) -> None:
        self.traj.append((truth.robot.x_m, truth.robot.y_m))
        self.n_gauss.append(metrics["n_gaussians"])
        self.loss.append(metrics["perception_loss"])
        self.last = (rec, truth, states[1].gaussians)
        if len(rec.selection.cand_node):
            self.cands = (rec.frame.step, rec.selection)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=120)
    ap.add_argument("--preset", default="full")
    ap.add_argument("--out", default="docs/viewer.png")
    args = ap.parse_args()
    cfg = preset(args.preset)
    keep = Keep()
    t0 = time.perf_counter()
    run(cfg, args.steps, sink=keep)
    print(f"{args.steps} steps in {time.perf_counter() - t0:.1f} s")
    rec, truth, g = keep.last

    fig = plt.figure(figsize=(14, 12.5), dpi=80)
    grid = fig.add_gridspec(3, 4, height_ratios=[1.15, 3.6, 1.1], left=0.04, right=0.98, bottom=0.05, top=0.93,
                            hspace=0.22, wspace=0.12)
    fig.suptitle(f"{cfg.sim.scene}, {args.preset} preset, seed {cfg.seed}: step {rec.frame.step} "
                 f"(after {args.steps} steps of a real run)", fontsize=12)
    images = [(rec.frame.rgb, "camera RGB", None), (rec.perception.beta, "beta (uncertainty)", "magma"),
              (rec.mapping.render_rgb, "map render (before update)", None),
              (truth.people_mask, "people mask (ground truth)", "gray")]
    for i, (img, title, cmap) in enumerate(images):
        ax = fig.add_subplot(grid[0, i])
        im = ax.imshow(img, cmap=cmap)
        if title.startswith("beta"):
            fig.colorbar(im, ax=ax, fraction=0.03)
        ax.set_title(title, fontsize=9)
        ax.axis("off")

    ax = fig.add_subplot(grid[1, :3])
    fm = motion_floor_map(rec.fields, 0.1, 1.9)
    if fm.values.size:
        ext = [fm.origin_xy_m[0], fm.origin_xy_m[0] + fm.values.shape[0] * fm.cell_m,
               fm.origin_xy_m[1], fm.origin_xy_m[1] + fm.values.shape[1] * fm.cell_m]
        um = np.ma.masked_less_equal(fm.values.T, 1e-3)
        ax.imshow(um, origin="lower", extent=ext, cmap="Reds", alpha=0.6, vmin=0)
    means = g.means.detach().numpy()
    rgb = np.clip(g.rgb.detach().numpy(), 0, 1)
    op = g.opacities.detach().numpy()
    keep_idx = np.flatnonzero((op > 0.5) & (means[:, 2] < 2.0))[::3]
    ax.scatter(means[keep_idx, 0], means[keep_idx, 1], s=1, c=rgb[keep_idx], label="Gaussian map (z < 2 m)")
    sel, plan = rec.selection, rec.planning
    xy = sel.node_xy_m
    for a, b in sel.edges:
        ax.plot(xy[[a, b], 0], xy[[a, b], 1], color="0.5", lw=0.8, zorder=2)
    ax.scatter(xy[:, 0], xy[:, 1], c=sel.node_region, cmap="tab10", s=14, zorder=3, label="Voronoi graph (subregions)")
    if keep.cands is not None:
        c_step, cs = keep.cands
        score = np.where(np.isfinite(cs.cand_score), cs.cand_score, -np.inf)
        best = {}                                   # one arrow per node: its best-scoring view
        for i in np.argsort(score)[::-1]:
            best.setdefault(int(cs.cand_node[i]), i)
        i = np.fromiter(best.values(), int)
        o = cs.node_xy_m[cs.cand_node[i]]
        ax.quiver(o[:, 0], o[:, 1], np.cos(cs.cand_yaw_rad[i]), np.sin(cs.cand_yaw_rad[i]), cs.cand_score[i],
                  cmap="RdYlGn", scale=1 / 0.4, scale_units="xy", angles="xy", width=0.004, zorder=4)
        ax.plot([], [], color="tab:olive", label=f"candidate views of step {c_step}, best per node\n"
                f"(red to green: S_local)")
    t = np.asarray(keep.traj)
    ax.plot(t[:, 0], t[:, 1], color="tab:blue", lw=1.2, label="trajectory")
    if len(plan.path_xy_m):
        ax.plot(plan.path_xy_m[:, 0], plan.path_xy_m[:, 1], color="tab:green", lw=2.2, label="planned path")
    ax.annotate("", xy=sel.target_xy_m + 0.5 * np.array([np.cos(sel.target_yaw_rad), np.sin(sel.target_yaw_rad)]),
                xytext=sel.target_xy_m, arrowprops=dict(color="tab:purple", width=2, headwidth=8))
    ax.scatter(*sel.target_xy_m, marker="*", s=180, color="tab:purple", zorder=5, label=f"target ({sel.mode})")
    ax.scatter(truth.people_xy_m[:, 0], truth.people_xy_m[:, 1], s=90, facecolors="none", edgecolors="k",
               zorder=5, label="people")
    ax.scatter(*t[-1], marker="o", s=60, color="tab:blue", zorder=6)
    ax.set_aspect("equal")
    ax.set_title("top view (m): Gaussian map, U_m on the floor (red), Voronoi graph, candidates, target, path, "
                 "trajectory, people", fontsize=9)
    handles, labels = ax.get_legend_handles_labels()

    ax = fig.add_subplot(grid[1, 3])
    ax.axis("off")
    ax.legend(handles, labels, loc="lower left", fontsize=9, markerscale=1.5, frameon=False)
    ax.text(0, 1, "\n".join([f"step {rec.frame.step}", f"Gaussians {rec.mapping.n_gaussians}",
                             f"target mode: {sel.mode}", f"graph nodes {len(xy)}",
                             f"subregions {len(set(sel.node_region.tolist()))}",
                             f"candidates {len(sel.cand_node)}", f"action {plan.action}",
                             f"people: {int(truth.people_mask.mean() * 100)} % of pixels"]),
            va="top", fontsize=10, family="monospace", transform=ax.transAxes)
    steps = np.arange(1, len(keep.n_gauss) + 1)
    ax = fig.add_subplot(grid[2, :2])
    ax.plot(steps, keep.n_gauss)
    ax.set_title("Gaussian count", fontsize=9)
    ax = fig.add_subplot(grid[2, 2:])
    ax.plot(steps, keep.loss)
    ax.set_title("perception (uncertainty) loss", fontsize=9)
    ax.set_xlabel("step", fontsize=8)
    fig.savefig(args.out)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
