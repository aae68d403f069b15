"""``dagsrun``: the closed loop in a scene, with an MCAP log (``--record``) and a Rerun timeline (``--rrd``).

With no arguments it runs the ``full`` method for 150 steps on the embedded default scene
(apartment-00), about a minute on a laptop CPU, and prints the map's metrics.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from dynactivegs.config import DagsConfig, PRESETS, preset, to_json, with_overrides
from dynactivegs.errors import DagsError

DEFAULT_STEPS = 150


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dagsrun", description="Run the robot's closed loop (perception, mapping, "
                                "fields, selection, planning) in a scene with moving people.")
    p.add_argument("--scene", help="tiny-NN, apartment-NN, house-NN, loop-NN or a .glb/.gltf/.ply/.obj path "
                   "(default: the preset's, apartment-00)")
    p.add_argument("--preset", default="full", help=f"one of {', '.join(PRESETS)} (default: full)")
    p.add_argument("--steps", type=int, default=DEFAULT_STEPS, help=f"robot actions (default: {DEFAULT_STEPS})")
    p.add_argument("--seed", type=int, help="master seed (default: the preset's, 0)")
    p.add_argument("--record", type=Path, metavar="OUT.mcap", help="write the run's MCAP log (replay with dagsreplay)")
    p.add_argument("--rrd", type=Path, metavar="OUT.rrd", help="write a Rerun timeline of the run")
    p.add_argument("--device", choices=("cpu", "cuda"), help="where mapping runs (sets mapping.device)")
    p.add_argument("--set", dest="overrides", action="append", default=[], nargs="+", metavar="KEY=VALUE",
                   help="config overrides, e.g. --set mapping.weighted=false sim.camera.width_px=64")
    p.add_argument("--out", type=Path, default=Path("out/run"), help="directory of summary.json (default: out/run)")
    p.add_argument("--map-every", type=int, default=50, help="steps between Gaussian-map snapshots (default: 50)")
    p.add_argument("--no-eval", dest="evaluate", action="store_false",
                   help="skip the map's metrics against the scene at the end")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    return p


def build_config(args: argparse.Namespace) -> DagsConfig:
    """The run's config: the preset, then --scene, --seed, --device, then --set overrides in order."""
    cfg = preset(args.preset)
    if args.scene is not None:
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, scene=args.scene))
    if args.seed is not None:
        cfg = with_overrides(cfg, [f"seed={args.seed}"])
    if args.device is not None:
        if args.device == "cuda":
            import torch

            if not torch.cuda.is_available():
                raise DagsError(f"--device cuda: no CUDA device available to torch {torch.__version__}; use --device cpu")
        cfg = with_overrides(cfg, [f"mapping.device={args.device}"])
    return with_overrides(cfg, [kv for group in args.overrides for kv in group])


def run(args: argparse.Namespace) -> int:
    from recorder.live import record_run
    from recorder.summary import evaluate_map, print_summary

    if args.steps < 1:
        raise DagsError(f"bad value --steps {args.steps}: must be >= 1")
    cfg = build_config(args)
    from dynactivegs.sim.scenes import load_scene   # fails early, in one line, for an unknown scene

    load_scene(cfg.sim)
    res = record_run(cfg, args.steps, record=args.record, rrd=args.rrd, map_every=args.map_every,
                     progress=args.progress, extra_metadata={"preset": args.preset})
    metrics = evaluate_map(cfg, res) if args.evaluate and res.steps > 0 else None
    args.out.mkdir(parents=True, exist_ok=True)
    summary = args.out / "summary.json"
    summary.write_text(json.dumps({"config": json.loads(to_json(cfg)), "steps": res.steps,
                                   "interrupted": res.interrupted, "seconds_per_step": res.seconds_per_step,
                                   "last_step_metrics": res.last_metrics, "collisions": res.collisions,
                                   "map_metrics": dataclasses.asdict(metrics) if metrics is not None else None},
                                  indent=1, default=str))
    print_summary(cfg, res, metrics, summary)
    return 130 if res.interrupted else 0


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return run(args)
    except DagsError as e:
        print(f"dagsrun: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
