"""What more passes of the offline refinement buy, measured on logged runs (open loop: same map, same keyframes).

    python benchmarks/refine_passes.py runs/full/apartment-00-seed0.mcap [more.mcap ...] --passes 3,6,12 \
        [--set mapping.densify_stride=1 ...]

For each run log it re-runs the mapping stage over the logged frames (as ``dagsreplay --from-stage
mapping`` does: the loop's map, keyframes and Adam moments, exactly), refines the map over the
keyframes as the run did (``mapping.refine``: random order from the run's seed, one Adam step per
keyframe per pass) and measures it with ``dagsbench``'s evaluation at each pass count of
``--passes``, continuing the same optimisation from one count to the next (the measured copy is
pruned as the refinement's end prunes it). The ``logged`` row is the run's own refined map; the row
with the run's ``mapping.refine_passes`` should match it.

``--set`` re-runs mapping with changed ``mapping.*`` settings: a what-if on the same path. Perception's
outputs stay the logged ones (in the loop, perception compares each frame with the previous map's
render), so it is open loop for perception as well as for the path.

It prints one Markdown table: per run and pass count, the Gaussians, Acc (cm), C.R. (%), PSNR,
SSIM, depth L1 (cm), the PSNR over correctly placed pixels (``psnr_right``) and the seconds of
refinement, plus the means over runs per pass count.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

COLUMNS = ("n_gaussians", "acc_cm", "cr_pct", "psnr_db", "ssim", "depth_l1_cm", "psnr_right_db")


def read_run(mcap: Path, overrides: tuple[str, ...] = ()):
    """(config, the mapping state after the last step, trajectory (T, 2), logged refined map or None) of a
    run log. The mapping stage is re-run over the logged frames and perception outputs (as
    ``dagsreplay --from-stage mapping`` does), which gives the loop's map, keyframes and Adam moments
    exactly; with ``overrides`` (``mapping.*`` settings) the map of that what-if."""
    from dataclasses import replace

    from dynactivegs import pipeline
    from dynactivegs.config import with_overrides
    from dynactivegs.errors import DagsError
    from dynactivegs.mapping import stage as ms
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    bad = [o for o in overrides if not o.startswith("mapping.")]
    if bad:
        raise DagsError(f"--set {bad[0]}: only mapping.* settings change a re-run of the mapping stage")
    cfg = with_overrides(cfg, list(overrides))
    state = ms.init_state(cfg.mapping)
    traj, prev = [], None
    later = {s.name: None for s in pipeline.STAGES[1:]}
    for st in reader.steps():
        truth = st["/truth"]
        traj.append((truth.robot.x_m, truth.robot.y_m))
        rec = replace(st.step_record(prev), **later)
        state, prev = ms.step(cfg.mapping, rec, state, pipeline.stage_rng(cfg.seed, rec.frame.step, 1))
    if not state.keyframes:
        raise DagsError(f"{mcap}: the run kept no keyframes; pass a log of a dagsbench run")
    return cfg, state, np.asarray(traj, np.float64).reshape(-1, 2), reader.refined_map()


def sweep_run(mcap: Path, passes: list[int], eval_cfg=None,
              overrides: tuple[str, ...] = ()) -> tuple[str, list[tuple[str, dict[str, float]]]]:
    """(a label, [(row name, numbers)]) for one run log: the logged refined map, then each pass count (of the
    what-if map with ``overrides``); ``eval_cfg`` (an :class:`~dynactivegs.eval.config.EvalConfig`) defaults to
    ``dagsbench``'s."""
    from dynactivegs.eval.config import EvalConfig
    from dynactivegs.eval.metrics import SceneEvaluator
    from dynactivegs.mapping import stage as ms
    from dynactivegs.rng import derive_rng

    cfg, state, traj, logged = read_run(mcap, overrides)
    g, adam, kfs = state.gaussians, state.adam, state.keyframes
    ev = SceneEvaluator(cfg.sim, eval_cfg or EvalConfig())
    step = len(traj)

    def measure(gs, seconds: float) -> dict[str, float]:
        m = ev.evaluate(gs, step=step, trajectory_xy_m=traj)
        return {"n_gaussians": float(len(gs)), **{k: float(getattr(m, k)) for k in COLUMNS[1:]},
                "seconds": seconds}

    rows = []
    if logged is not None:
        rows.append(("logged", measure(logged, float("nan"))))
    rng = derive_rng(cfg.seed, "refine")
    done, spent = 0, 0.0
    for p in sorted(passes):
        t0 = time.perf_counter()
        while done < p:
            for i in rng.permutation(len(kfs)):
                g, adam, _ = ms.optimise(cfg.mapping, g, adam, [kfs[int(i)]])
            done += 1
        spent += time.perf_counter() - t0
        pruned, _, _ = ms.prune(cfg.mapping, g, adam)
        rows.append((f"{p} passes", measure(pruned, spent)))
        print(f"  {mcap.name}: {p} passes, {spent:.0f} s, PSNR {rows[-1][1]['psnr_db']:.2f}", file=sys.stderr,
              flush=True)
    return f"{cfg.sim.scene} seed {cfg.seed} ({len(kfs)} keyframes)", rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsbench writes them under OUT/runs/PRESET/)")
    ap.add_argument("--passes", default="3,6,12", help="comma list of pass counts to measure (default: 3,6,12)")
    ap.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                    help="mapping what-ifs for the re-run, e.g. mapping.densify_stride=1 (open loop)")
    args = ap.parse_args()
    try:
        passes = sorted({int(x) for x in args.passes.split(",") if x.strip()})
    except ValueError:
        sys.exit(f"error: bad --passes {args.passes!r}: give a comma list of whole numbers, e.g. 3,6,12")
    if not passes or passes[0] < 1:
        sys.exit(f"error: bad --passes {args.passes!r}: pass counts must be >= 1")
    import torch

    from dynactivegs.errors import DagsError

    torch.set_num_threads(1)
    print("| run | map | Gaussians | Acc cm | C.R. % | PSNR dB | SSIM | depth L1 cm | PSNR right dB | refine s |\n"
          "|---|---|---|---|---|---|---|---|---|---|", flush=True)
    by_name: dict[str, list[dict[str, float]]] = {}
    for path in args.mcap:
        try:
            label, rows = sweep_run(path, passes, overrides=tuple(args.set))
        except DagsError as e:
            sys.exit(f"error: {e}")
        for name, r in rows:
            by_name.setdefault(name, []).append(r)
            print(f"| {label} | {name} | {r['n_gaussians']:.0f} | {r['acc_cm']:.2f} | {r['cr_pct']:.2f} | "
                  f"{r['psnr_db']:.2f} | {r['ssim']:.3f} | {r['depth_l1_cm']:.2f} | {r['psnr_right_db']:.2f} | "
                  f"{r['seconds']:.0f} |", flush=True)
    if len(args.mcap) > 1:
        for name, rs in by_name.items():
            m = {k: float(np.mean([r[k] for r in rs])) for k in (*COLUMNS, "seconds")}
            print(f"| **mean of {len(rs)}** | {name} | {m['n_gaussians']:.0f} | {m['acc_cm']:.2f} | {m['cr_pct']:.2f} | "
                  f"{m['psnr_db']:.2f} | {m['ssim']:.3f} | {m['depth_l1_cm']:.2f} | {m['psnr_right_db']:.2f} | "
                  f"{m['seconds']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
