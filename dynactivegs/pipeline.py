"""The stage table, ``tick`` and the closed loop (DESIGN.md §1, §3).

``STAGES`` lists the five stages in order. :func:`tick` runs one stage and everything after
it for one step, given the step's record filled up to that stage; it is what both the live
loop and ``dagsreplay --from-stage`` call, so a replay runs exactly the live code.

Randomness: stage ``i`` at step ``t`` draws from ``derive_rng(seed, "stage", t, i)`` and from
nothing else, so re-running a stage alone draws the same numbers.

:func:`run` is the closed loop: simulator frame -> stages -> action -> simulator, for the step
budget, with a :class:`StepSink` called after every step (the recorder writes MCAP and Rerun
from it; the core never imports them), then the offline refinement of the map.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable, Protocol

import numpy as np

from dynactivegs.config import DagsConfig, check_consistent
from dynactivegs.errors import DagsError
from dynactivegs.fields import stage as fields_stage
from dynactivegs.mapping import stage as mapping_stage
from dynactivegs.perception import stage as perception_stage
from dynactivegs.planning import stage as planning_stage
from dynactivegs.records import SimTruth, StepRecord
from dynactivegs.rng import derive_rng
from dynactivegs.selection import stage as selection_stage


@dataclass(frozen=True)
class Stage:
    """One row of the stage table: its name (= the StepRecord field and the config field) and functions."""

    name: str
    step: Callable
    init_state: Callable[[DagsConfig], object]


STAGES: tuple[Stage, ...] = (
    Stage("perception", perception_stage.step, lambda c: perception_stage.init_state(c.perception, c.seed)),
    Stage("mapping", mapping_stage.step, lambda c: mapping_stage.init_state(c.mapping)),
    Stage("fields", fields_stage.step, lambda c: fields_stage.init_state(c.fields)),
    Stage("selection", selection_stage.step, lambda c: selection_stage.init_state(c.selection)),
    Stage("planning", planning_stage.step, lambda c: planning_stage.init_state(c.planning)),
)
STAGE_NAMES: tuple[str, ...] = tuple(s.name for s in STAGES)


def stage_index(name: str) -> int:
    """Index of a stage by name; a one-line error lists the names for an unknown one."""
    if name not in STAGE_NAMES:
        raise DagsError(f"unknown stage {name!r}: use one of {', '.join(STAGE_NAMES)}")
    return STAGE_NAMES.index(name)


def init_states(cfg: DagsConfig) -> list[object]:
    """Step 0's state of every stage, built from the config alone (a one-line error for settings the stages copy
    from the robot that disagree with it: :func:`~dynactivegs.config.check_consistent`)."""
    check_consistent(cfg)
    return [s.init_state(cfg) for s in STAGES]


def stage_rng(seed: int, step: int, index: int) -> np.random.Generator:
    return derive_rng(seed, "stage", step, index)


def tick(cfg: DagsConfig, rec: StepRecord, states: list[object], from_stage: int = 0,
         timings: dict[str, float] | None = None) -> tuple[list[object], StepRecord]:
    """Runs stages ``from_stage..`` on ``rec`` (filled with the outputs of the stages before).

    Returns the new states (a new list; entries before ``from_stage`` unchanged) and the record
    with every output filled. ``timings``, if given, receives seconds per stage.
    """
    states = list(states)
    for i in range(from_stage, len(STAGES)):
        s = STAGES[i]
        assert all(getattr(rec, STAGES[j].name) is not None for j in range(i)), f"{s.name} needs the stages before it"
        t0 = time.perf_counter()
        states[i], out = s.step(getattr(cfg, s.name), rec, states[i], stage_rng(cfg.seed, rec.frame.step, i))
        if timings is not None:
            timings[s.name] = time.perf_counter() - t0
        rec = replace(rec, **{s.name: out})
    return states, rec


class StepSink(Protocol):
    """Receives every finished step of a live run (the recorder's MCAP and Rerun writers)."""

    def on_step(self, rec: StepRecord, truth: SimTruth, states: list[object], metrics: dict[str, float]) -> None: ...


@dataclass(frozen=True)
class RunResult:
    """What a closed-loop run leaves: the final stage states (the map is ``states[1].gaussians``)."""

    states: list
    steps: int
    trajectory_xy_m: np.ndarray       # float64 (S, 2) robot positions per step
    seconds_per_step: float
    collisions: int


def run(cfg: DagsConfig, steps: int, *, sink: StepSink | None = None, refine: bool = False,
        progress: Callable[[int, dict[str, float]], None] | None = None) -> RunResult:
    """The closed loop for ``steps`` steps from a fresh simulator, then (``refine``) the map's offline
    refinement (:func:`refine_map`). The sink sees the map before refinement.

    ``progress(k, metrics)`` is called after each step (for a progress bar).
    """
    from dynactivegs.sim.world import Simulator   # the simulator is only needed for live runs

    if steps < 1:
        raise DagsError(f"steps must be >= 1; got {steps}")
    sim = Simulator(cfg.sim, cfg.seed)
    states = init_states(cfg)
    frame, truth = sim.observation()
    prev_mapping = None
    traj, collisions = [], 0
    t_start = time.perf_counter()
    for k in range(steps):
        timings: dict[str, float] = {}
        states, rec = tick(cfg, StepRecord(frame=frame, prev_mapping=prev_mapping), states, 0, timings)
        metrics = step_metrics(rec, timings)
        if sink is not None:
            sink.on_step(rec, truth, states, metrics)
        if progress is not None:
            progress(k + 1, metrics)
        traj.append((truth.robot.x_m, truth.robot.y_m))
        prev_mapping = rec.mapping
        frame, truth = sim.step(rec.planning.action)
        collisions += int(truth.collided)
    elapsed = time.perf_counter() - t_start
    if refine:
        states = refine_map(cfg, states)
    return RunResult(states, steps, np.asarray(traj, np.float64).reshape(-1, 2), elapsed / steps, collisions)


def refine_reads_perception(cfg: DagsConfig) -> bool:
    """Whether :func:`refine_map` reads the perception state (its MLP predicts the keyframes' beta again)."""
    return cfg.mapping.weighted and cfg.mapping.refine_beta == "final"


def refine_map(cfg: DagsConfig, states: list[object],
               progress: Callable[[int], None] | None = None) -> list[object]:
    """The stage states with the map after the offline refinement over all keyframes (DESIGN.md §5,
    ``mapping.refine_passes`` passes; :func:`dynactivegs.mapping.stage.refine`). Its random order comes
    from the seed alone. ``progress(k)`` is called after each Adam step. With ``mapping.refine_beta=final``
    the keyframes' beta is first predicted again by the perception state's MLP."""
    m_state = states[1]
    if refine_reads_perception(cfg):
        m_state = replace(m_state, keyframes=tuple(
            replace(kf, beta=perception_stage.predict_beta(cfg.perception, states[0], kf.rgb, kf.depth_m.shape))
            for kf in m_state.keyframes))
    iters = mapping_stage.refine_iters(cfg.mapping, m_state)
    m_state = mapping_stage.refine(cfg.mapping, m_state, iters, derive_rng(cfg.seed, "refine"), progress)
    return [states[0], m_state, *states[2:]]


def step_metrics(rec: StepRecord, timings: dict[str, float]) -> dict[str, float]:
    """Cheap per-step numbers for plots and the progress bar (no ground truth)."""
    m: dict[str, float] = {f"time_{k}_s": v for k, v in timings.items()}
    m["perception_loss"] = float(rec.perception.loss)
    m["mapping_loss"] = float(rec.mapping.loss)
    m["n_gaussians"] = float(rec.mapping.n_gaussians)
    m["beta_mean"] = float(np.mean(rec.perception.beta))
    return m
