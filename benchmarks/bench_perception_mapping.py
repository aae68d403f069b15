"""Perception + mapping on a scripted tour: per-step time and quality, with and without weighting.

The robot follows the scripted driver (ground-truth free space) through ``apartment-00`` with
the default crowd walking through the view, at the default 160x92 camera and the default
iteration counts. Rows: the default (filter-bank features, weighted mapping), the seeded
random-CNN features, and the ablation without weighted mapping. Columns: mean seconds per
step of each stage, AUROC of beta against the simulator's people mask (after the warm-up),
ghosts (opaque Gaussians within 0.3 m of a person's track and > 0.1 m from any static
surface), PSNR of static renders at held-out poses (trajectory poses turned by +-25 deg),
and the map's size.

    python benchmarks/bench_perception_mapping.py [--steps 150] [--scene apartment-00]
"""

from __future__ import annotations

import argparse
import os

import torch

from dynactivegs.config import FeatureConfig, MappingConfig, PerceptionConfig, SimConfig
from dynactivegs.eval.scripted_tour import run_tour


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--scene", default="apartment-00")
    ap.add_argument("--warmup", type=int, default=30)
    args = ap.parse_args()
    rows = [("filters, weighted (default)", PerceptionConfig(), MappingConfig()),
            ("random_conv, weighted", PerceptionConfig(features=FeatureConfig(backend="random_conv")), MappingConfig()),
            ("filters, no weighting", PerceptionConfig(), MappingConfig(weighted=False))]
    print(f"scene {args.scene}, {args.steps} steps, warm-up {args.warmup}, torch threads {torch.get_num_threads()}, "
          f"cpus {os.cpu_count()}")
    print(f"| {'setting':<28} | perception s | mapping s | total s | AUROC | ghosts | held-out PSNR dB | Gaussians |")
    print(f"|{'-' * 30}|-------------:|----------:|--------:|------:|-------:|-----------------:|----------:|")
    for name, pc, mc in rows:
        r = run_tour(SimConfig(scene=args.scene), pc, mc, args.steps, seed=0, warmup=args.warmup)
        print(f"| {name:<28} | {r.perception_s:12.3f} | {r.mapping_s:9.3f} | {r.perception_s + r.mapping_s:7.3f} | "
              f"{r.auroc:5.3f} | {r.ghosts:6d} | {r.psnr_db:16.2f} | {r.n_gaussians:9d} |", flush=True)


if __name__ == "__main__":
    main()
