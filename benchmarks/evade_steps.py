"""The turn-away's forward steps on logged runs: which bumped, and which ``planning.evade_map_check`` would refuse.

    python benchmarks/evade_steps.py runs/full/apartment-00-seed1.mcap [more.mcap ...]

After bumps or waits in a row the planner turns away and tries one forward step (``planning.bump_evade_after``,
``wait_evade_after``); it takes that step where the depth frame shows nothing in the way. For each run log this
finds those steps (a forward step of the turn-away, as ``blocked_episodes.py`` tells it: blocked, no re-plan), whether
the robot then moved (by ``planning.bump_tol_m`` or more; else it bumped) and whether the step keeps clear of the
known obstacles around the robot (:func:`dynactivegs.planning.actions.clear_headings` on the logged
``SelectionOut.local_clear_m``): the test ``planning.evade_map_check`` adds, under which the robot turns on rather
than step. One row per run: the steps that bumped and that moved, each split by what the check says, and the
steps of the bumps it refuses; the last line sums the runs.

Open loop: a refused step changes what comes after it, which a log cannot show; ``dagsreplay LOG --from-stage
planning --set planning.evade_map_check=true`` shows the first steps that differ.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Iterable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from blocked_episodes import turned_away  # noqa: E402  (the same turn-away steps)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)


def evade_steps(steps: Iterable, acfg, bump_tol_m: float) -> list[dict]:
    """One dict per turn-away forward step in ``steps`` (a run log's steps in order: ``get(topic)`` gives the
    records), with the step, ``moved`` (the next step's robot is ``bump_tol_m`` or more away) and ``map_ok``
    (the step keeps clear of the logged window's obstacles); a last step with no next one is left out."""
    from dynactivegs.planning.actions import clear_headings
    from dynactivegs.sim.robot import Action

    out, pending = [], None
    for st in steps:
        rb = st.get("/truth").robot
        if pending is not None:
            pending["moved"] = math.hypot(rb.x_m - pending.pop("x"), rb.y_m - pending.pop("y")) >= bump_tol_m
            out.append(pending)
            pending = None
        pl = st.get("/planning")
        if pl.action == Action.FORWARD and turned_away(pl):
            sel = st.get("/selection")
            ok = clear_headings(sel.local_clear_m, sel.local_origin_xy_m, sel.local_cell_m, rb,
                                np.array([rb.yaw_rad]), acfg)[0]
            pending = {"step": int(st.step), "map_ok": bool(ok), "x": rb.x_m, "y": rb.y_m}
    return out


def run_steps(mcap: Path) -> tuple[str, list[dict]]:
    """(a label, :func:`evade_steps`) of one run log."""
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    return f"{cfg.sim.scene} seed {cfg.seed}", evade_steps(reader.steps(), cfg.planning.actions,
                                                            cfg.planning.bump_tol_m)


def counts(steps: list[dict]) -> tuple[int, int, int, int]:
    """(bumped and refused, bumped and allowed, moved and refused, moved and allowed) by the map check."""
    return (sum(not s["moved"] and not s["map_ok"] for s in steps), sum(not s["moved"] and s["map_ok"] for s in steps),
            sum(s["moved"] and not s["map_ok"] for s in steps), sum(s["moved"] and s["map_ok"] for s in steps))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    args = ap.parse_args(argv)
    from dynactivegs.errors import DagsError

    print("| run | turn-away steps | bumped: refused / allowed | moved: refused / allowed | bumps refused at steps |\n"
          "|---|---|---|---|---|", flush=True)
    total = np.zeros(4, int)
    for path in args.mcap:
        try:
            label, steps = run_steps(path)
        except DagsError as e:
            sys.exit(f"error: {e}")
        c = counts(steps)
        total += c
        at = ", ".join(str(s["step"]) for s in steps if not s["moved"] and not s["map_ok"])
        print(f"| {label} ({path.parent.name}) | {len(steps)} | {c[0]} / {c[1]} | {c[2]} / {c[3]} | {at} |",
              flush=True)
    b, m = total[0] + total[1], total[2] + total[3]
    print(f"\n{b + m} turn-away steps in {len(args.mcap)} runs: {b} bumped, of them the map check refuses {total[0]}; "
          f"{m} moved, of them it refuses {total[2]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
