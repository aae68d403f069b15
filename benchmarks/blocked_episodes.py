"""What held a run's robot up, from its log: each blocked episode's cause, place and outcome.

    python benchmarks/blocked_episodes.py runs/baseline/*.mcap runs/weighted/*.mcap

A step is **blocked** when the planner's local collision check stopped a forward move
(``PlanningOut.blocked``); runs of blocked steps with at most ``path_stats.EPISODE_GAP`` other steps between
them are one **episode** (one hold-up, as in ``path_stats.py``). Each blocked step gets a cause from the log's
frame and the simulator's truth of that step:

- **person**: the depth frame showed the forward step blocked (the planner's own test,
  :func:`~dynactivegs.planning.actions.forward_blocked`, on the logged frame) and at least half of the returns in
  the swept box were a person's pixels (the truth's people mask);
- **static**: the frame showed the step blocked by the scene itself (walls, furniture, door jambs): the planned
  path led the robot up against something the map and the graph let it aim at;
- **remembered**: nothing in view blocked the step, but a spot where the robot was blocked or bumped a few steps
  ago lay ahead (the planner re-routes round it);
- **evade**: the robot was turning away from a spot it kept bumping into or waiting at (no path then).

An episode's cause is person when any of its steps was, else static when any was, else **other**. Per run log one
Markdown row: blocked steps by cause; episodes by cause; blocked steps per episode; the share of episodes that
began with the robot in a **corridor** room (procedural scenes); the share whose target was **given up**
(the selection's next new target, within the episode or ``EPISODE_GAP`` steps after it, replaced it as
unreachable, stuck or timed out; ``reached`` ones are counted too); the steps with a person within
``path_stats.NEAR_M`` of the robot (how much crowd the path met) and the person episodes per 100 of them (how
often meeting someone became a hold-up). Two more columns say whether the people met were in the maps the planner
drives by: **people px let in %**, the share of the frames' people pixels whose uncertainty beta was at most
``selection.occupancy.beta_max`` (such returns become obstacles in the selection's occupancy grid; above it they
only clear space there), and **close people in the clearance map %**, over the steps and people standing within
the selection's logged clearance window (``SelectionOut.local_clear_m``, about 0.6 m round the robot) in the open
(farther than their radius and ``OPEN_M`` from the scene's own obstacles), the share that window held as an
obstacle (a known obstacle within their radius of their centre), so that the planner could steer round them before
the collision check had to stop the robot. The window holds the grid's obstacles and, with
``selection.local_people_steps`` above 0, the people returns (beta above beta_max) of the last steps too, so at 0
the column reads the grid alone and above 0 it also counts the people that window holds; tables made before the
option head it "close people in the grid %". A second table pools each preset's runs.

Two presets with the same selection and planner that are held up differently are told apart here: by meeting
more people (more steps near people at the same rate), by meeting them worse (a higher rate), or by aiming at
the scene's own obstacles (static).
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

from occupancy_errors import truth_cell, truth_maps  # noqa: E402  (the scene's true free floor, its clearance)
from path_stats import EPISODE_GAP, GIVE_UP, NEAR_M, episode_spans  # noqa: E402  (the same episodes)
from people_in_view import _f, in_corridor, print_runs  # noqa: E402  (the same rooms and tables)
from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

STEP_CAUSES = ("person", "static", "remembered", "evade")
EPISODE_CAUSES = ("person", "static", "other")
COLUMNS = ("run", "steps", "blocked: person / static / remembered / evade", "episodes: person / static / other",
           "blocked per episode", "in corridor %", "given up / reached %", "steps near people",
           "person episodes per 100 near", "people px let in %", "close people in the clearance map %")
PERSON_SHARE = 0.5
"""A seen block is a person's when at least this share of the returns in the swept box are people pixels."""
OPEN_M = 0.1
"""A person counts for the grid column only when at least their radius and this far from the scene's obstacles."""


@dataclass(frozen=True)
class Setting:
    """What one run's steps are measured against: the scene's rooms, the run's ActionConfig and occupancy
    beta_max, the truth map (FreeSpace and its free cells' clearance, m) and the people's radius (m)."""

    rooms: list
    acfg: object
    beta_max: float
    fs: object
    clear_m: np.ndarray
    person_m: float


@dataclass
class BlockedRecord:
    """One run's (or a preset's pooled runs') steps and episodes."""

    steps: int = 0
    near: int = 0                                                   # steps with a person within NEAR_M
    people_px: int = 0                                              # people pixels over all frames
    let_in_px: int = 0                                              # of them with beta <= beta_max
    close: int = 0                                                  # (step, person) in the window, in the open
    in_grid: int = 0                                                # of them held as an obstacle
    causes: list[str] = field(default_factory=list)                 # per blocked step
    episodes: list[tuple[str, int, bool, str]] = field(default_factory=list)   # (cause, blocked, corridor, outcome)

    def extend(self, other: "BlockedRecord") -> None:
        for name in ("steps", "near", "people_px", "let_in_px", "close", "in_grid"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.causes.extend(other.causes)
        self.episodes.extend(other.episodes)

    def summary(self) -> dict[str, float]:
        steps = collections.Counter(self.causes)
        eps = collections.Counter(e[0] for e in self.episodes)
        n = len(self.episodes)
        pct = (lambda k: 100.0 * k / n if n else float("nan"))
        return {"steps": self.steps, "near": self.near, "episodes": n,
                **{f"blocked_{c}": steps[c] for c in STEP_CAUSES}, **{f"ep_{c}": eps[c] for c in EPISODE_CAUSES},
                "per_episode": sum(e[1] for e in self.episodes) / n if n else float("nan"),
                "corridor_pct": pct(sum(e[2] for e in self.episodes)),
                "given_up_pct": pct(sum(e[3] in GIVE_UP for e in self.episodes)),
                "reached_pct": pct(sum(e[3] == "reached" for e in self.episodes)),
                "person_rate": 100.0 * eps["person"] / self.near if self.near else float("nan"),
                "let_in_pct": 100.0 * self.let_in_px / self.people_px if self.people_px else float("nan"),
                "in_grid_pct": 100.0 * self.in_grid / self.close if self.close else float("nan")}


def turned_away(plan) -> bool:
    """Whether a logged PlanningOut is a step of the turn-away (blocked, and no re-plan: a block seen or remembered
    always re-plans, the turn-away does not)."""
    return bool(plan.blocked and not plan.replanned)


def step_cause(plan, frame, truth, acfg) -> str | None:
    """The cause (one of STEP_CAUSES) of a blocked step, None for a step that was not blocked. ``plan`` is the
    step's PlanningOut, ``frame`` its FrameRecord, ``truth`` its SimTruth, ``acfg`` the run's ActionConfig."""
    from dynactivegs.planning.actions import forward_hits

    if plan is None or not plan.blocked:
        return None
    if turned_away(plan):
        return "evade"
    hits = forward_hits(frame.depth_m, frame.K, frame.T_world_cam, acfg)
    if len(hits) < acfg.min_blocking_points:
        return "remembered"
    return "person" if truth.people_mask.ravel()[hits].mean() >= PERSON_SHARE else "static"


def close_people(sel, truth, setting: Setting) -> tuple[int, int]:
    """(people in the selection's clearance window standing in the open, how many of them the window held as an
    obstacle) at one step: the module docstring's clearance map column."""
    if sel is None or sel.local_clear_m.size == 0:
        return 0, 0
    size = sel.local_clear_m.shape[0]
    j, i = np.floor((truth.people_xy_m - sel.local_origin_xy_m) / sel.local_cell_m).astype(np.int64).T
    on_map, row, col = truth_cell(setting.fs, truth.people_xy_m)
    open_ = on_map & (setting.clear_m[row, col] > setting.person_m + OPEN_M)
    close = open_ & (i >= 0) & (i < size) & (j >= 0) & (j < size)
    held = sel.local_clear_m[i[close], j[close]] <= setting.person_m
    return int(close.sum()), int(held.sum())


def record_of(steps, setting: Setting, gap: int = EPISODE_GAP) -> BlockedRecord:
    """The record of one run from its steps, each ``(frame, truth, perception, planning, selection)`` (the last
    three may be None: a stage that did not run), measured against ``setting``."""
    rec, causes, corridor, reasons = BlockedRecord(), [], [], []
    for frame, truth, perception, plan, sel in steps:
        rec.steps += 1
        robot = np.array([truth.robot.x_m, truth.robot.y_m])
        rec.near += bool((np.hypot(*(truth.people_xy_m - robot).T) < NEAR_M).any())   # (P, 2), P may be 0
        if perception is not None:
            rec.people_px += int(truth.people_mask.sum())
            rec.let_in_px += int((perception.beta[truth.people_mask] <= setting.beta_max).sum())
        close, held = close_people(sel, truth, setting)
        rec.close += close
        rec.in_grid += held
        causes.append(step_cause(plan, frame, truth, setting.acfg))
        corridor.append(in_corridor(setting.rooms, *robot))
        reasons.append(None if sel is None or sel.target_reason == "keep" else sel.target_reason)
    rec.causes = [c for c in causes if c is not None]
    for a, b in episode_spans(np.array([c is not None for c in causes]), gap):
        mine = set(causes[a:b + 1])
        cause = "person" if "person" in mine else "static" if "static" in mine else "other"
        outcome = next((r for r in reasons[a + 1:b + gap + 2] if r is not None), "kept")
        rec.episodes.append((cause, sum(c is not None for c in causes[a:b + 1]), corridor[a], outcome))
    return rec


def blocked_record(mcap: Path) -> tuple[str, str, BlockedRecord]:
    """(a label, the preset, the record of the module docstring) of one run log."""
    from dynactivegs.sim.scenes import load_scene
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    fs, clear_m, _ = truth_maps(cfg.sim)
    setting = Setting(load_scene(cfg.sim).rooms, cfg.planning.actions, cfg.selection.occupancy.beta_max, fs, clear_m,
                      cfg.sim.crowd.radius_m)
    rec = record_of(((st["/frame"], st["/truth"], st.get("/perception"), st.get("/planning"), st.get("/selection"))
                     for st in reader.steps()), setting)
    if not rec.steps:
        raise ValueError(f"{mcap}: the log holds no whole step; pass the .mcap of a run that took at least one")
    preset = reader.metadata.get("preset", "?")
    return f"{preset} {cfg.sim.scene} seed {cfg.seed}", preset, rec


def let_in_correlations(runs: list[tuple[str, dict[str, float]]]) -> dict[str, tuple[float, float, int]]:
    """Spearman (rho, p, runs) of the people px let in with the person episodes per 100 near steps over ``runs``
    (preset, summary): over all of them ("all runs") and within each preset; nan where fewer than 3 runs have
    both, or one side is constant."""
    from people_in_view import _rho

    out = {}
    for name in ("all runs", *dict.fromkeys(p for p, _ in runs)):
        pairs = np.array([(s["let_in_pct"], s["person_rate"]) for p, s in runs if name in ("all runs", p)
                          and np.isfinite(s["let_in_pct"]) and np.isfinite(s["person_rate"])]).reshape(-1, 2)
        out[name] = (*_rho(pairs[:, 0], pairs[:, 1]), len(pairs))
    return out


def row(label: str, rec: BlockedRecord) -> str:
    s = rec.summary()
    return (f"| {label} | {s['steps']} | " + " / ".join(str(s[f'blocked_{c}']) for c in STEP_CAUSES) + " | "
            + " / ".join(str(s[f'ep_{c}']) for c in EPISODE_CAUSES) + f" | {_f(s['per_episode'], '.1f')} | "
            f"{_f(s['corridor_pct'], '.0f')} | {_f(s['given_up_pct'], '.0f')} / {_f(s['reached_pct'], '.0f')} | "
            f"{s['near']} | {_f(s['person_rate'], '.1f')} | {_f(s['let_in_pct'], '.1f')} | "
            f"{_f(s['in_grid_pct'], '.1f')} |")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    args = ap.parse_args(argv)
    runs: list[tuple[str, dict[str, float]]] = []

    def read(path: Path) -> tuple[str, str, BlockedRecord]:
        label, preset, rec = blocked_record(path)
        runs.append((preset, rec.summary()))
        return label, preset, rec

    print_runs(COLUMNS, args.mcap, read, row, BlockedRecord)
    print("\nrank correlation (Spearman) over runs of people px let in with person episodes per 100 near: "
          + "; ".join(f"{name} {_f(rho, '+.2f')} (p {_f(p, '.2g')}, {n} runs)"
                      for name, (rho, p, n) in let_in_correlations(runs).items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
