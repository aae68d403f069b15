"""Per-step time of the fields, graph update, selection and planning stages during exploration.

    python benchmarks/bench_stages.py [--scenes apartment-00,house-00] [--steps 500] [--variant full]

The robot explores with the project's own selection and planning stages (the actions come
from planning). Perception and mapping are stand-ins made from simulator ground truth
(:mod:`dynactivegs.sim.standin`): beta = 0.1 + 2 * people mask, the map's render is the
static scene rendered at the frame's pose, and its surface voxels are the voxelised static
points observed so far. So the times are those of the stages on realistic inputs, not of a
full pipeline run.

Prints one table: per stage the mean, median and max milliseconds per step over all steps,
and "graph" (the amortised Voronoi rebuild + subregions inside selection) over the steps
where it ran; "sel.score" is selection on the steps where it scored candidate views.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dynactivegs import fields
from dynactivegs.config import SimConfig
from dynactivegs.fields import FieldsConfig
from dynactivegs.planning import stage as planning
from dynactivegs.records import StepRecord
from dynactivegs.rng import derive_rng
from dynactivegs.selection import stage as selection
from dynactivegs.sim.standin import StandInUpstream
from dynactivegs.sim.world import Simulator


def run_scene(name: str, steps: int, variant: str, seed: int = 0) -> dict[str, object]:
    sim = Simulator(SimConfig(scene=name), seed=seed)
    up = StandInUpstream(sim)
    f_cfg = FieldsConfig()
    s_cfg = selection.SelectionConfig(variant=variant)  # type: ignore[arg-type]
    p_cfg = planning.PlanningConfig()
    f_state, s_state, p_state = fields.init_state(f_cfg), selection.init_state(s_cfg), planning.init_state(p_cfg)
    frame, truth = sim.observation()
    t_f, t_s, t_p, t_g, t_score = [], [], [], [], []
    collisions, modes = 0, {}
    for t in range(steps):
        perc, mapping = up.outputs(frame, truth)
        rec = StepRecord(frame=frame, perception=perc, mapping=mapping)
        a = time.perf_counter()
        f_state, f_out = fields.step(f_cfg, rec, f_state, derive_rng(seed, t, 3))
        b = time.perf_counter()
        rec = StepRecord(frame=frame, perception=perc, mapping=mapping, fields=f_out)
        prev_graph = s_state.graph_step
        s_state, s_out = selection.step(s_cfg, rec, s_state, derive_rng(seed, t, 4))
        c = time.perf_counter()
        rec = StepRecord(frame=frame, perception=perc, mapping=mapping, fields=f_out, selection=s_out)
        p_state, p_out = planning.step(p_cfg, rec, p_state, derive_rng(seed, t, 5))
        d = time.perf_counter()
        t_f.append(b - a)
        t_s.append(c - b)
        t_p.append(d - c)
        if s_state.graph_step != prev_graph:
            t_g.append(c - b)
        if s_out.mode not in ("keep", "none") and s_cfg.variant not in ("frontier", "random"):
            t_score.append(c - b)
        modes[s_out.mode] = modes.get(s_out.mode, 0) + 1
        frame, truth = sim.step(p_out.action)
        collisions += int(truth.collided)
    grid = s_state.grid
    return {"scene": name, "fields": t_f, "selection": t_s, "planning": t_p, "graph": t_g, "sel.score": t_score,
            "nodes": len(s_out.node_xy_m), "voxels": int(np.prod(f_out.u_s.shape)),
            "free_m2": float(grid.free(s_cfg.occupancy).sum()) * grid.cell_m ** 2, "collisions": collisions,
            "modes": modes}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default="apartment-00,house-00")
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--variant", default="full")
    args = ap.parse_args()
    print(f"stages per step after {args.steps} steps of exploration (selection variant {args.variant}); "
          "perception/mapping are ground-truth stand-ins")
    print(f"{'scene':14s} {'stage':10s} {'mean ms':>8s} {'median':>8s} {'max':>8s} {'n':>5s}")
    for name in args.scenes.split(","):
        t0 = time.perf_counter()
        r = run_scene(name, args.steps, args.variant)
        for key in ("fields", "selection", "graph", "sel.score", "planning"):
            xs = np.array(r[key]) * 1000.0
            if len(xs):
                print(f"{name:14s} {key:10s} {xs.mean():8.1f} {np.median(xs):8.1f} {xs.max():8.1f} {len(xs):5d}")
        total = (np.array(r["fields"]) + np.array(r["selection"]) + np.array(r["planning"])) * 1000.0
        print(f"{name:14s} {'all three':10s} {total.mean():8.1f} {np.median(total):8.1f} {total.max():8.1f} {len(total):5d}")
        print(f"{name:14s} nodes {r['nodes']}, query voxels {r['voxels']}, known free floor {r['free_m2']:.1f} m^2, "
              f"collisions {r['collisions']}, modes {r['modes']}, wall {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
