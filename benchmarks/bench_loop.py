"""Steps/s of the closed loop with and without recording, and the MCAP bytes per step.

    python benchmarks/bench_loop.py [--scene apartment-00] [--steps 100] [--no-rrd]

Runs ``dagsrun``'s loop (:func:`recorder.live.record_run`, the ``full`` preset at default
settings) three times from the same seed: no sinks, ``--record``, and ``--record --rrd``;
prints a table. The runs are identical up to the sinks, so the time difference is the cost
of recording. Goals (issue 6): a 1000-step apartment episode in <= 20 min on 2 CPU cores
(<= 1.2 s/step); recording <= 5 % of step time; <= 200 kB of log per step.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dynactivegs.config import preset  # noqa: E402
from recorder.live import record_run  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--scene", default="apartment-00")
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--no-rrd", dest="rrd", action="store_false")
    a = p.parse_args()
    cfg = preset("full")
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, scene=a.scene))
    cam = cfg.sim.camera
    rows = []
    with tempfile.TemporaryDirectory() as d:
        variants = [("loop only", None, None), ("--record", Path(d, "a.mcap"), None)]
        if a.rrd:
            variants.append(("--record --rrd", Path(d, "b.mcap"), Path(d, "b.rrd")))
        for name, log, rrd in variants:
            res = record_run(cfg, a.steps, record=log, rrd=rrd, progress=False, handle_sigint=False)
            rrd_kb = rrd.stat().st_size / res.steps / 1e3 if rrd is not None else None
            rows.append((name, res.seconds_per_step, res.log_bytes / res.steps / 1e3 if log else None, rrd_kb))
    base = rows[0][1]
    print(f"{a.scene}, {a.steps} steps, {cam.width_px}x{cam.height_px}, preset full, "
          f"torch threads as set by the environment")
    print(f"{'run':<16} {'s/step':>7} {'steps/s':>8} {'overhead':>9} {'MCAP kB/step':>13} {'rrd kB/step':>12}")
    for name, sps, kb, rkb in rows:
        over = f"{100 * (sps - base) / base:+.1f} %" if name != "loop only" else ""
        print(f"{name:<16} {sps:>7.3f} {1 / sps:>8.2f} {over:>9} {'' if kb is None else f'{kb:.0f}':>13} "
              f"{'' if rkb is None else f'{rkb:.0f}':>12}")
    print(f"1000-step episode: {1000 * base / 60:.1f} min (goal <= 20 min)")


if __name__ == "__main__":
    main()
