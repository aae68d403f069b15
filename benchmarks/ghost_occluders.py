"""What the map's ghosts do to the selection: occluders over the free floor, and each choice made without them.

    python benchmarks/ghost_occluders.py runs/baseline/*.mcap runs/weighted/*.mcap

Eq. (8)'s soft visibility takes its occluders from the Gaussian map's opaque surface (``MappingOut.surface_ijk``).
Where the map took in a person (the unweighted map of ``baseline``, or a person the weighting missed), that surface
stands in free space and hides what lies behind it from every candidate view. Here a **ghost voxel** is a surface
voxel whose centre lies over the scene's true free floor (the simulator's static free space, people not in it) at
least ``--margin`` from any obstacle, between 0.15 and 2.1 m up: people's heights, not the floor's own voxels, and
nothing at a wall or a piece of furniture. Per run log, one Markdown row:

- **ghost voxels**: per step, mean and largest count, and the share of them standing in a **corridor** room
  (procedural scenes);
- **choices**: the logged new targets while the map had ghost voxels; at each, the selection is run again from
  the same state (the run's own selection state, re-built by re-running the selection over the logged steps) with
  the ghost voxels taken out of the map's surface: **changed %** of the choices; **corridor** targets logged /
  ghost-free; **I_s hidden %**, the share of the candidates' summed eq. (8) gain the ghosts hid
  (1 - logged / ghost-free);
- **replayed = logged**: the steps where the re-run selection with the logged map gave back the logged target, of
  all steps (anything but all says the re-built state is not the run's, and the row means little).

Then the same pooled per preset. Open loop: the robot's path is the logged one, so this says how the ghosts moved
each choice the run made, not where a run without ghosts would have gone.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from occupancy_errors import truth_cell, truth_maps  # noqa: E402  (the scene's true free floor, its clearance)
from people_in_view import in_corridor, print_runs  # noqa: E402  (the same corridor test and tables)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

COLUMNS = ("run", "steps", "ghost voxels mean / max", "in corridor %", "choices", "changed %",
           "corridor logged / ghost-free", "I_s hidden %", "replayed = logged")
HEIGHT_M = (0.15, 2.1)
"""Ghost voxel centres lie between these heights (m): above the floor's voxels, up to a tall person."""


@dataclass
class GhostRecord:
    """One run's (or a preset's pooled runs') counts."""

    ghosts: list[int] = field(default_factory=list)            # per step: ghost voxels in the map's surface
    ghosts_corridor: int = 0                                    # of all those, standing in a corridor
    choices: int = 0                                            # logged new targets while there were ghosts
    changed: int = 0                                            # ... the ghost-free selection chose otherwise
    corridor_logged: int = 0
    corridor_free: int = 0
    gain_logged: float = 0.0                                    # the candidates' summed I_s at those choices
    gain_free: float = 0.0                                      # ... with the ghost voxels out
    replayed: int = 0                                           # steps whose re-run target is the logged one

    def extend(self, other: "GhostRecord") -> None:
        self.ghosts.extend(other.ghosts)
        for name in ("ghosts_corridor", "choices", "changed", "corridor_logged", "corridor_free", "gain_logged",
                     "gain_free", "replayed"):
            setattr(self, name, getattr(self, name) + getattr(other, name))


def ghost_voxels(surface_ijk: np.ndarray, voxel_m: float, fs, clear_m: np.ndarray, margin_m: float) -> np.ndarray:
    """bool (M,): the surface voxels (int (M, 3), edge ``voxel_m``) that are ghosts (module docstring) over the
    truth map ``fs`` (origin_xy_m, res_m, shape (rows, cols)) whose free cells are ``clear_m`` (rows, cols) metres
    from the nearest obstacle (0 off the free floor)."""
    c = (surface_ijk.astype(np.float64) + 0.5) * voxel_m
    inside, row, col = truth_cell(fs, c[:, :2])
    clear = clear_m[row, col]
    return inside & (clear > 0) & (clear >= margin_m) & (c[:, 2] > HEIGHT_M[0]) & (c[:, 2] < HEIGHT_M[1])


def _new_target(sel) -> bool:
    return sel is not None and sel.target_reason != "keep" and sel.target_node >= 0


def _same_target(a, b) -> bool:
    """Whether selection outputs ``a`` and ``b`` hold the same target view (node and heading)."""
    from dynactivegs.sim.robot import wrap_angle

    return a.target_node == b.target_node and abs(wrap_angle(a.target_yaw_rad - b.target_yaw_rad)) < 1e-6


def ghost_record(mcap: Path, margin_m: float) -> tuple[str, str, GhostRecord]:
    """(a label, the preset, the record of the module docstring) of one run log."""
    from dynactivegs import pipeline
    from dynactivegs.sim.scenes import load_scene
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    fs, clear_m, _ = truth_maps(cfg.sim)
    rooms = load_scene(cfg.sim).rooms
    first = pipeline.stage_index("selection")
    after = {s.name: None for s in pipeline.STAGES[first:]}
    states = pipeline.init_states(cfg)
    rec, prev = GhostRecord(), None
    for ls in reader.steps():
        logged = ls.step_record(prev)
        prev = logged.mapping
        m = logged.mapping
        ghost = ghost_voxels(m.surface_ijk, m.surface_voxel_m, fs, clear_m, margin_m)
        rec.ghosts.append(int(ghost.sum()))
        ghost_xy = (m.surface_ijk[ghost, :2] + 0.5) * m.surface_voxel_m
        rec.ghosts_corridor += sum(in_corridor(rooms, x, y) for x, y in ghost_xy)
        step_in = replace(logged, **after)
        new_states, out = pipeline.tick(cfg, step_in, states, first)
        sel = logged.selection
        rec.replayed += int(_same_target(out.selection, sel))
        if _new_target(sel) and ghost.any():
            no_ghosts = replace(m, surface_ijk=np.ascontiguousarray(m.surface_ijk[~ghost]))
            free = pipeline.tick(cfg, replace(step_in, mapping=no_ghosts), states, first)[1].selection
            rec.choices += 1
            rec.changed += int(not _same_target(free, sel))
            rec.corridor_logged += in_corridor(rooms, *sel.target_xy_m)
            rec.corridor_free += _new_target(free) and in_corridor(rooms, *free.target_xy_m)
            if len(free.cand_gain) == len(sel.cand_gain):   # the same candidates: the graph is the occupancy grid's
                rec.gain_logged += float(sel.cand_gain.sum())
                rec.gain_free += float(free.cand_gain.sum())
        states = new_states
    if not rec.ghosts:
        raise ValueError(f"{mcap}: the log holds no whole step; pass the .mcap of a run that took at least one")
    preset = reader.metadata.get("preset", "?")
    return f"{preset} {cfg.sim.scene} seed {cfg.seed}", preset, rec


def row(label: str, r: GhostRecord) -> str:
    g = np.asarray(r.ghosts, float)
    pct = (lambda a, b: f"{100.0 * a / b:.0f}" if b else "-")
    hidden = f"{100.0 * (1.0 - r.gain_logged / r.gain_free):.1f}" if r.gain_free > 0 else "-"
    return (f"| {label} | {len(g)} | {g.mean():.0f} / {g.max():.0f} | {pct(r.ghosts_corridor, g.sum())} | "
            f"{r.choices} | {pct(r.changed, r.choices)} | {r.corridor_logged} / {r.corridor_free} | {hidden} | "
            f"{r.replayed} / {len(g)} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--margin", type=float, default=0.15,
                    help="ghost voxels stand at least this far (m) from a true obstacle (default 0.15)")
    args = ap.parse_args(argv)
    if args.margin < 0:
        sys.exit(f"error: bad --margin {args.margin}: must be >= 0 m")
    print_runs(COLUMNS, args.mcap, lambda path: ghost_record(path, args.margin), row, GhostRecord)
    return 0


if __name__ == "__main__":
    sys.exit(main())
