"""``dagsrun``: run the robot in a scene and write what it produced.

At this stage of the project the run drives the simulator on the scripted tour (the
exploration pipeline's stages plug in here as they land) and writes RGB, depth and
people-mask PNGs, a contact sheet and a top-down floor plan with the robot's trajectory and
the people's tracks.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import tyro

from dynactivegs.config import DagsConfig
from dynactivegs.errors import DagsError


@dataclass(frozen=True)
class RunArgs:
    """Run the robot in a scene and write frames, a contact sheet and a floor plan."""

    scene: str | None = None
    """Scene to run in (tiny-NN, apartment-NN, house-NN or a .glb/.gltf/.ply/.obj path); overrides --sim.scene."""
    steps: int = 60
    """Number of robot actions."""
    out: Path = Path("out/run")
    """Output directory."""
    save_every: int = 1
    """Write every k-th frame as PNG."""
    progress: bool = True
    """Show a progress bar."""
    cfg: Annotated[DagsConfig, tyro.conf.arg(name="")] = field(default_factory=DagsConfig)


def run(args: RunArgs) -> int:
    from dynactivegs.sim.demo import drive_and_render

    if args.steps < 1:
        raise DagsError(f"bad value --steps {args.steps}: must be >= 1")
    if args.save_every < 1:
        raise DagsError(f"bad value --save-every {args.save_every}: must be >= 1")
    cfg = args.cfg
    if args.scene is not None:
        cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, scene=args.scene))
    s = drive_and_render(cfg, args.steps, args.out, save_every=args.save_every, progress=args.progress)
    print(f"{cfg.sim.scene}: {s.steps} steps in {s.seconds:.1f} s ({s.steps_per_s:.1f} steps/s), "
          f"{s.people} people, people in view in {s.frames_with_people} frames, {s.collisions} blocked moves")
    print(f"frames:        {s.out_dir / 'frames'}")
    print(f"floor plan:    {s.floorplan_png}")
    print(f"contact sheet: {s.contact_sheet_png}")
    return 0


def main(argv: list[str] | None = None) -> int:
    try:
        return run(tyro.cli(RunArgs, args=argv, prog="dagsrun"))
    except DagsError as e:
        print(f"dagsrun: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
