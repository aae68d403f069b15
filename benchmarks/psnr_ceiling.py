"""How far a run's held-out PSNR is from what its map and its images allow.

    python benchmarks/psnr_ceiling.py runs/full/apartment-01-seed0.mcap [more.mcap ...] [--online]

For each run log it prints, next to the held-out PSNR ``dagsbench`` reports (mean over views):

- **train**: the same map rendered at the run's keyframes, over their static pixels (people
  masked out with the simulator's truth). A map that does not fit the views it was trained on
  is limited by its optimisation; one that fits them and not the held-out views, by what it
  has not seen or has placed wrongly.
- **overfit**: ``--overfit`` keyframes, evenly spread over the run, each fitted alone for
  ``--iters`` Adam steps of the mapping loss, starting from the map: what the map's Gaussians
  can represent of one view when nothing else competes. Static pixels, as in *train*.
- **sampling floor**: the simulator renders one ray per pixel at the pixel centre with
  nearest-texel lookups, while a camera integrates over the pixel. This compares the held-out
  ground truth with the same views rendered at ``--supersample`` x the resolution and
  box-filtered: an error a map cannot remove, since it would need a different sample of the
  texture in every view. Its PSNR is roughly the ceiling this puts on the held-out PSNR (a map
  that renders each pixel's average texture colour scores about this).

All numbers are means over views, in dB.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import chosen_map, logged_config  # noqa: E402  (the same reading of a run log)


def static_psnr_db(pred_rgb: np.ndarray, true_rgb: np.ndarray, static: np.ndarray) -> float:
    """PSNR (dB) of two float (H, W, 3) images in [0, 1] over the pixels where ``static`` (H, W) holds."""
    err = ((np.clip(pred_rgb, 0, 1) - true_rgb) ** 2)[static]
    return float(-10.0 * np.log10(max(err.mean(), 1e-12))) if err.size else float("nan")


def box_filtered(renderer, T: np.ndarray, K: np.ndarray, cam, factor: int) -> np.ndarray:
    """float (H, W, 3) render of the static scene at ``factor`` x the resolution, averaged over each pixel's block."""
    Ks = K.copy()
    Ks[:2] *= factor
    w, h = cam.width_px, cam.height_px
    hi = renderer.render(T, Ks, w * factor, h * factor, min_depth_m=cam.min_depth_m,
                         max_depth_m=cam.max_depth_m).rgb.astype(np.float64) / 255.0
    return hi.reshape(h, factor, w, factor, 3).mean(axis=(1, 3))


def run_ceiling(mcap: Path, online: bool, n_overfit: int, iters: int, factor: int,
                eval_cfg=None) -> tuple[str, dict[str, float]]:
    """(a label, the row's numbers) of the run logged in ``mcap``; ``eval_cfg`` (an
    :class:`~dynactivegs.eval.config.EvalConfig`) defaults to ``dagsbench``'s."""
    import torch

    from dynactivegs.errors import DagsError
    from dynactivegs.eval.config import EvalConfig
    from dynactivegs.eval.metrics import SceneEvaluator
    from dynactivegs.mapping import stage as ms
    from dynactivegs.mapping.adam import AdamState
    from dynactivegs.splat.render import render
    from recorder.mcap_log import MAP_TOPIC
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    traj, keyframes, static, last_map = [], [], [], None
    for st in reader.steps():
        truth = st["/truth"]
        traj.append((truth.robot.x_m, truth.robot.y_m))
        if st["/mapping"].keyframe:
            f = st["/frame"]
            beta = st["/perception"].beta if cfg.mapping.weighted else None
            keyframes.append(ms.Keyframe(f.step, f.rgb, f.depth_m, beta, f.K, f.T_world_cam))
            static.append(~truth.people_mask)
        if MAP_TOPIC in st:
            last_map = st[MAP_TOPIC]
    g = chosen_map(reader, last_map, online, mcap)
    if not keyframes:
        raise DagsError(f"{mcap}: the log has no keyframes")
    cam = cfg.sim.camera
    ev = SceneEvaluator(cfg.sim, eval_cfg or EvalConfig())
    poses, rgb, _ = ev.heldout(np.asarray(traj, np.float64))

    def view_psnr(gs, K: np.ndarray, T: np.ndarray, true_rgb: np.ndarray, mask: np.ndarray | None = None) -> float:
        with torch.no_grad():
            out = render(gs, K, T, cam.width_px, cam.height_px, near_plane=cam.min_depth_m)
        pred = out.rgb.cpu().numpy().astype(np.float64)
        return static_psnr_db(pred, true_rgb / 255.0, np.ones(pred.shape[:2], bool) if mask is None else mask)

    heldout = [view_psnr(g, ev.K, T, rgb[i]) for i, T in enumerate(poses)]
    train = [view_psnr(g, kf.K, kf.T_world_cam, kf.rgb, m) for kf, m in zip(keyframes, static)]
    before, after = [], []
    for j in np.linspace(0, len(keyframes) - 1, n_overfit).round().astype(int):
        gs, adam = g, AdamState.zeros_like(g)
        for _ in range(iters):
            gs, adam, _ = ms.optimise(cfg.mapping, gs, adam, [keyframes[j]])
        before.append(train[j])
        after.append(view_psnr(gs, keyframes[j].K, keyframes[j].T_world_cam, keyframes[j].rgb, static[j]))
    floor = [static_psnr_db(box_filtered(ev.renderer, T, ev.K, cam, factor), rgb[i] / 255.0,
                            np.ones(rgb.shape[1:3], bool))
             for i, T in enumerate(poses)]
    label = f"{cfg.sim.scene} seed {cfg.seed}, {Path(mcap).parent.name}"
    return label, {"heldout": float(np.mean(heldout)), "train": float(np.mean(train)),
                   "overfit_before": float(np.mean(before)), "overfit_after": float(np.mean(after)),
                   "floor": float(np.mean(floor))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsbench writes them under OUT/runs/PRESET/)")
    ap.add_argument("--online", action="store_true", help="the last map snapshot instead of the refined map")
    ap.add_argument("--overfit", type=int, default=3, help="how many keyframes to fit alone")
    ap.add_argument("--iters", type=int, default=100, help="Adam steps of each single-view fit")
    ap.add_argument("--supersample", type=int, default=4, help="rays per pixel side of the box-filtered renders")
    args = ap.parse_args()
    if args.overfit < 1 or args.iters < 1 or not 2 <= args.supersample <= 8:
        sys.exit("error: --overfit and --iters must be >= 1 and --supersample in [2, 8]")
    import torch

    from dynactivegs.errors import DagsError

    torch.set_num_threads(1)
    print(f"| run | held-out | train (static px) | overfit {args.overfit} views x {args.iters} steps | "
          f"sampling floor ({args.supersample}x{args.supersample}) |\n|---|---|---|---|---|", flush=True)
    for path in args.mcap:
        try:
            label, r = run_ceiling(path, args.online, args.overfit, args.iters, args.supersample)
        except DagsError as e:
            sys.exit(f"error: {e}")
        print(f"| {label} | {r['heldout']:.2f} | {r['train']:.2f} | {r['overfit_before']:.2f} -> "
              f"{r['overfit_after']:.2f} | {r['floor']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
