"""Drive the robot through an apartment and write its frames and a floor plan as PNGs.

    python examples/drive_and_render.py --scene apartment-00 --steps 120 --out out/drive

Opens nothing and needs no data: the scene is generated. Look at ``out/drive/floorplan.png``
(trajectory and people's tracks) and ``out/drive/contact_sheet.png`` (RGB | depth | people).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from dynactivegs.config import DagsConfig, SimConfig
from dynactivegs.sim.demo import drive_and_render


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="apartment-00")
    ap.add_argument("--steps", type=int, default=120)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("out/drive"))
    a = ap.parse_args()
    cfg = dataclasses.replace(DagsConfig(seed=a.seed), sim=SimConfig(scene=a.scene))
    summary = drive_and_render(cfg, a.steps, a.out)
    print(f"{summary.steps} steps at {summary.steps_per_s:.1f} steps/s; people visible in "
          f"{summary.frames_with_people} frames; see {summary.floorplan_png} and {summary.contact_sheet_png}")


if __name__ == "__main__":
    main()
