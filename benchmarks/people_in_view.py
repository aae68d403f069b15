"""Where a run's camera saw people, and whether eq. (9)'s motion risk R_m of a chosen view foretold them.

    python benchmarks/people_in_view.py runs/full/*.mcap runs/weighted/*.mcap

From each run log (its frames, the simulator's truth and the selection's logged candidates) one Markdown row:

- **people px %**: the share of the camera's pixels on a person, over all steps; split into the steps the local
  collision check **blocked** a forward move and the others, and by where the robot stood: in a **corridor** room
  or elsewhere (procedural scenes; rooms of other kinds, and the doorways between rooms, count as elsewhere);
- **corridor %**: the share of steps the robot stood in a corridor, and of the new targets (every variant's, scored
  or not) that lay in one;
- **choices**: new targets with a scored candidate view (``random`` and ``frontier`` choices are not scored);
  **R_m rank**: the chosen view's eq. (9) risk among that step's candidates (0 = the least risky candidate,
  1 = the most, ties halved), mean over the choices: how far the selection steered away from where people were
  seen (every variant's log holds R_m, also where eq. (7) does not use it);
- **arrivals**: the choices whose view was reached, and the mean **steps** from the choice to the arrival;
  **px at arrival %**: people px in the frame of the step the selection reported the view reached (the view it
  chose), mean over the arrivals;
- **rho**: the rank correlation (Spearman) of the chosen views' R_m rank with people px at arrival, over the
  run's arrivals, and its p-value.

A second block pools each preset's runs: the same means over all their steps and choices, and rho over all their
arrivals (the rank is within each step's candidates, so it pools across runs); a third splits each preset's
arrivals at their median steps from the choice into the sooner and the later half (how fast what R_m knows goes
stale). A positive rho says the views that
eq. (9) rated risky did show more people when the robot got there; near 0, R_m (where people were seen before)
says little about where they are by the time the robot arrives, which can take tens of steps.
"""

from __future__ import annotations

import argparse
import collections
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from choice_weights import logged_choice  # noqa: E402  (the same matching of the target to its candidate)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

COLUMNS = ("run", "people px %", "px blocked / other %", "corridor % steps / targets", "px corridor / elsewhere %",
           "choices", "R_m rank", "arrivals (steps)", "px at arrival %", "rho (p)")


@dataclass
class PeopleInView:
    """One run's (or a preset's pooled runs') per-step and per-choice record."""

    px: list[float] = field(default_factory=list)           # per step: the share of pixels on a person
    blocked: list[bool] = field(default_factory=list)       # per step: the collision check stopped a forward move
    corridor: list[bool] = field(default_factory=list)      # per step: the robot stood in a corridor
    target_corridor: list[bool] = field(default_factory=list)   # per new target: it lay in a corridor
    rank: list[float] = field(default_factory=list)         # per scored choice: the chosen view's R_m rank
    arrival: list[tuple[float, float, int]] = field(default_factory=list)   # per reached choice: (rank, px, steps)

    def extend(self, other: "PeopleInView") -> None:
        for name in ("px", "blocked", "corridor", "target_corridor", "rank", "arrival"):
            getattr(self, name).extend(getattr(other, name))

    def summary(self) -> dict[str, float]:
        px, blocked, corridor = np.asarray(self.px), np.asarray(self.blocked, bool), np.asarray(self.corridor, bool)
        pct = (lambda m: 100.0 * float(px[m].mean()) if m.any() else float("nan"))
        arrived = np.asarray(self.arrival, float).reshape(-1, 3)
        rho, rho_p = _rho(arrived[:, 0], arrived[:, 1])
        return {"steps": len(px), "px_pct": pct(np.ones(len(px), bool)), "px_blocked_pct": pct(blocked),
                "px_other_pct": pct(~blocked), "corridor_pct": 100.0 * float(corridor.mean()) if len(px) else 0.0,
                "target_corridor_pct": 100.0 * float(np.mean(self.target_corridor)) if self.target_corridor else 0.0,
                "px_corridor_pct": pct(corridor), "px_elsewhere_pct": pct(~corridor), "choices": len(self.rank),
                "rank": float(np.mean(self.rank)) if self.rank else float("nan"), "arrivals": len(arrived),
                "arrival_steps": float(arrived[:, 2].mean()) if len(arrived) else float("nan"),
                "px_arrival_pct": 100.0 * float(arrived[:, 1].mean()) if len(arrived) else float("nan"),
                "rho": rho, "rho_p": rho_p}


def _rho(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Spearman (rho, p) of ``x`` and ``y``; nan for fewer than 3 pairs or a constant side."""
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan"), float("nan")
    from scipy.stats import spearmanr

    return tuple(float(v) for v in spearmanr(x, y))


def by_delay(arrival: list[tuple[float, float, int]]) -> tuple[float, list[dict[str, float]]]:
    """The median steps from choice to arrival, and for the arrivals at most that many steps after their choice and
    for the later ones: n, mean people px % at arrival, rho and its p (R_m rank against people px)."""
    a = np.asarray(arrival, float).reshape(-1, 3)
    median = float(np.median(a[:, 2])) if len(a) else float("nan")
    halves = []
    for part in (a[a[:, 2] <= median], a[a[:, 2] > median]):
        rho, p = _rho(part[:, 0], part[:, 1])
        halves.append({"n": len(part), "px_pct": 100.0 * float(part[:, 1].mean()) if len(part) else float("nan"),
                       "rho": rho, "rho_p": p})
    return median, halves


def risk_rank(risk: np.ndarray, chosen: int) -> float:
    """Where candidate ``chosen``'s risk lies among ``risk``: 0 below all the others, 1 above, ties halved."""
    others = np.delete(risk, chosen)
    if len(others) == 0:
        return 0.5
    return float(((others < risk[chosen]).sum() + 0.5 * (others == risk[chosen]).sum()) / len(others))


def in_corridor(rooms, x: float, y: float) -> bool:
    return any(r.kind == "corridor" and r.x0 <= x <= r.x1 and r.y0 <= y <= r.y1 for r in rooms)


def record_of(steps, rooms) -> PeopleInView:
    """The record of one run from its steps, each ``(truth, planning, selection)`` (the last two may be None: a
    stage that did not run), and the scene's rooms."""
    rec, pending = PeopleInView(), None           # pending: (the R_m rank, the step) of the target driven to
    for step, (truth, plan, sel) in enumerate(steps):
        px = float(truth.people_mask.mean())
        rec.px.append(px)
        rec.blocked.append(plan is not None and bool(plan.blocked))
        rec.corridor.append(in_corridor(rooms, truth.robot.x_m, truth.robot.y_m))
        if sel is None or sel.target_reason == "keep":
            continue
        if pending is not None and sel.target_reason == "reached":
            rec.arrival.append((pending[0], px, step - pending[1]))   # this step's frame: the view it was for
        pending = None
        if sel.target_node >= 0:
            rec.target_corridor.append(in_corridor(rooms, *sel.target_xy_m))
        scored = np.isfinite(sel.cand_score)                # the candidates eq. (7) (or its variant) scored
        chosen = logged_choice(sel, scored) if sel.target_node >= 0 and len(sel.cand_node) else None
        if chosen is not None:
            pending = (risk_rank(sel.cand_risk, chosen), step)
            rec.rank.append(pending[0])
    return rec


def people_in_view(mcap: Path) -> tuple[str, str, PeopleInView]:
    """(a label, the preset, the record of the module docstring) of one run log."""
    from dynactivegs.sim.scenes import load_scene
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    rec = record_of(((st["/truth"], st.get("/planning"), st.get("/selection")) for st in reader.steps()),
                    load_scene(cfg.sim).rooms)
    if not rec.px:
        raise ValueError(f"{mcap}: the log holds no whole step; pass the .mcap of a run that took at least one")
    preset = reader.metadata.get("preset", "?")
    return f"{preset} {cfg.sim.scene} seed {cfg.seed}", preset, rec


def _f(value: float, spec: str) -> str:
    """``value`` formatted by ``spec``, or "-" where it is undefined (nan: no corridor, no arrival, too few)."""
    return "-" if value != value else format(value, spec)


def row(label: str, s: dict[str, float]) -> str:
    return (f"| {label} | {s['px_pct']:.1f} | {_f(s['px_blocked_pct'], '.1f')} / {_f(s['px_other_pct'], '.1f')} | "
            f"{s['corridor_pct']:.0f} / {s['target_corridor_pct']:.0f} | {_f(s['px_corridor_pct'], '.1f')} / "
            f"{_f(s['px_elsewhere_pct'], '.1f')} | {s['choices']} | {_f(s['rank'], '.2f')} | {s['arrivals']} "
            f"({_f(s['arrival_steps'], '.0f')}) | {_f(s['px_arrival_pct'], '.1f')} | {_f(s['rho'], '+.2f')} "
            f"(p {_f(s['rho_p'], '.2g')}) |")


def print_runs(columns: tuple[str, ...], paths: list[Path], read, row_of, empty) -> tuple[dict, collections.Counter]:
    """Prints a Markdown table of ``columns`` with one row per run log, then the same table with each preset's runs
    pooled; returns ({preset: pooled record}, {preset: runs}). ``read(path)`` gives (label, preset, record),
    ``row_of(label, record)`` a row, ``empty()`` a record to pool into (by its ``extend``). A log that cannot be
    read exits with its one-line error."""
    from dynactivegs.errors import DagsError

    header = "| " + " | ".join(columns) + " |\n" + "|---" * len(columns) + "|"
    print(header, flush=True)
    pooled: dict = collections.defaultdict(empty)
    counts: collections.Counter = collections.Counter()
    for path in paths:
        try:
            label, preset, rec = read(path)
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        pooled[preset].extend(rec)
        counts[preset] += 1
        print(row_of(label, rec), flush=True)
    print("\n" + header.replace("| run |", "| preset (runs) |"))
    for preset, rec in pooled.items():
        print(row_of(f"{preset} ({counts[preset]})", rec))
    return pooled, counts


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    args = ap.parse_args(argv)
    pooled, counts = print_runs(COLUMNS, args.mcap, people_in_view, lambda label, rec: row(label, rec.summary()),
                                PeopleInView)
    print("\n| preset (runs) | median steps to arrival | sooner: arrivals, px %, rho (p) | later: arrivals, px %, "
          "rho (p) |\n|---|---|---|---|")
    for preset, rec in pooled.items():
        median, halves = by_delay(rec.arrival)
        cells = " | ".join(f"{h['n']}, {_f(h['px_pct'], '.1f')}, {_f(h['rho'], '+.2f')} (p {_f(h['rho_p'], '.2g')})"
                           for h in halves)
        print(f"| {preset} ({counts[preset]}) | {_f(median, '.0f')} | {cells} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
