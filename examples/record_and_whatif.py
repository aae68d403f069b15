"""Record a short run, then ask "what if the planner ignored people?" by replaying it from planning.

    python examples/record_and_whatif.py [--scene apartment-00] [--steps 40] [--out out/whatif]

The replay is open loop: it re-runs planning on the recorded frames and selection outputs
with ``planning.path.motion_weight=0`` and reports how the paths and actions changed.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from dynactivegs.config import preset
from recorder.live import record_run
from replay.engine import replay


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--scene", default="apartment-00")
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--out", type=Path, default=Path("out/whatif"))
    a = p.parse_args()
    cfg = preset("full")
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, scene=a.scene))
    log = a.out / "run.mcap"
    res = record_run(cfg, a.steps, record=log, progress=True)
    print(f"recorded {res.steps} steps to {log} ({res.log_bytes / 1e6:.1f} MB), "
          f"motion weight {cfg.planning.path.motion_weight}")
    replay(log, from_stage="planning", overrides=["planning.path.motion_weight=0"])


if __name__ == "__main__":
    main()
