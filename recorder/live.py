"""A live closed-loop run with its sinks: the MCAP log, the Rerun timeline, the progress bar.

:func:`record_run` is what ``dagsrun`` calls. It runs :func:`dynactivegs.pipeline.run` with
a :class:`McapSink` (``--record``) and a :class:`RerunStepSink` (``--rrd``), shows a progress
bar, and on Ctrl-C stops after the step in progress, so the log ends with a whole step and
is closed cleanly (a second Ctrl-C stops at once; the log still replays up to its last
whole step, because every step is its own chunk on disk). After the step budget the map is
refined over all keyframes (``mapping.refine_passes``, with its own progress bar); a Ctrl-C
there stops the refinement and the log keeps every step, without a refined map.

What the MCAP log holds per step (``docs/log_schema.md``): the frame and every stage output
(``/frame``, ``/perception`` ... ``/planning``), the simulator's ground truth on ``/truth``,
the step's metrics on ``/metrics``, and every ``map_every`` steps and at the last step the
Gaussian map on ``/map``; after the last step, the map after the offline refinement on
``/map_refined`` (and on the Rerun timeline one step past the last). No stage state is
snapshotted: ``dagsreplay`` rebuilds the initial states from the config in the metadata and
fast-forwards (see :mod:`replay.engine`).
"""

from __future__ import annotations

import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynactivegs import pipeline
from dynactivegs.config import DagsConfig
from dynactivegs.errors import DagsError
from dynactivegs.records import SimTruth, StepRecord

DEFAULT_MAP_EVERY = 50
"""Steps between Gaussian-map snapshots in the MCAP log and the Rerun timeline (and always the last step)."""


def known_area_m2(selection_state: Any) -> float:
    """Floor area the occupancy grid has seen (log-odds != 0), square metres."""
    grid = getattr(selection_state, "grid", None)
    if grid is None:
        return 0.0
    return float(np.count_nonzero(grid.logodds)) * grid.cell_m ** 2


def occupancy_of(selection_state: Any) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(log-odds, xy of cell (0, 0), cell edge) of selection's occupancy grid, as RerunSink takes it."""
    grid = getattr(selection_state, "grid", None)
    if grid is None or grid.logodds.size == 0:
        return None
    row, col = grid.origin_ij
    return grid.logodds, np.array([col * grid.cell_m, row * grid.cell_m]), grid.cell_m


class McapSink:
    """A :class:`dynactivegs.pipeline.StepSink` writing every step to a :class:`recorder.mcap_log.LogWriter`."""

    def __init__(self, writer: Any, *, last_step: int, map_every: int = DEFAULT_MAP_EVERY,
                 also_at: tuple[int, ...] = ()) -> None:
        self.writer = writer
        self.last_step = last_step
        self.map_every = map_every
        self.also_at = frozenset(also_at)
        """Steps whose map is logged besides every ``map_every``-th (dagsbench: its checkpoints)."""

    def on_step(self, rec: StepRecord, truth: SimTruth, states: list[object], metrics: dict[str, float]) -> None:
        step, t = rec.frame.step, rec.frame.stamp_ns
        self.writer.write_step_record(rec)
        self.writer.write("/truth", truth, t)
        self.writer.write_metrics(step, metrics, t)
        if wants_map(step, self.last_step, self.map_every) or step in self.also_at:
            self.writer.write_map(states[1].gaussians, t)
        self.writer.end_step(step, t)


class RerunStepSink:
    """A :class:`dynactivegs.pipeline.StepSink` logging every step to a :class:`recorder.rerun_sink.RerunSink`."""

    def __init__(self, sink: Any, *, last_step: int, map_every: int = DEFAULT_MAP_EVERY) -> None:
        self.sink = sink
        self.last_step = last_step
        self.map_every = map_every

    def on_step(self, rec: StepRecord, truth: SimTruth, states: list[object], metrics: dict[str, float]) -> None:
        step = rec.frame.step
        g = states[1].gaussians if wants_map(step, self.last_step, self.map_every) else None
        self.sink.log_step(rec.frame, truth=truth, perception=rec.perception, mapping=rec.mapping, fields=rec.fields,
                           selection=rec.selection, planning=rec.planning, gaussians=g,
                           occupancy=occupancy_of(states[3]), metrics=metrics)


def wants_map(step: int, last_step: int, every: int) -> bool:
    return step == last_step or (every > 0 and step % every == 0 and step > 0)


class _Stop(Exception):
    """Raised between steps after a Ctrl-C."""


@dataclass
class _Fanout:
    """Calls every sink; keeps the last states and the trajectory (for the summary of an interrupted run)."""

    sinks: list[Any]
    states: list[object] | None = None
    steps: int = 0
    trajectory: list[tuple[float, float]] = field(default_factory=list)
    collisions: int = 0
    last_metrics: dict[str, float] = field(default_factory=dict)
    last_stamp_ns: int = 0

    def on_step(self, rec: StepRecord, truth: SimTruth, states: list[object], metrics: dict[str, float]) -> None:
        metrics = {**metrics, "known_area_m2": known_area_m2(states[3])}
        for s in self.sinks:
            s.on_step(rec, truth, states, metrics)
        self.states, self.steps, self.last_metrics = states, self.steps + 1, metrics
        self.last_stamp_ns = rec.frame.stamp_ns
        self.trajectory.append((truth.robot.x_m, truth.robot.y_m))
        self.collisions += int(truth.collided)


@dataclass
class LiveResult:
    """What :func:`record_run` did: steps run, timing, the final states and what it wrote."""

    steps: int
    requested: int
    seconds: float
    interrupted: bool
    states: list[object]
    trajectory_xy_m: np.ndarray
    collisions: int
    last_metrics: dict[str, float]
    log_path: Path | None
    log_bytes: int
    rrd_path: Path | None
    refine_iters: int = 0
    """Adam steps of the offline refinement that ``states`` include (0: the map as the last step left it)."""
    refine_seconds: float = 0.0
    """Time of the refinement (``seconds`` is the loop's alone)."""

    @property
    def seconds_per_step(self) -> float:
        return self.seconds / max(self.steps, 1)


def record_run(cfg: DagsConfig, steps: int, *, record: Path | None = None, rrd: Path | None = None,
               map_every: int = DEFAULT_MAP_EVERY, progress: bool = True, extra_metadata: dict[str, str] | None = None,
               handle_sigint: bool = True) -> LiveResult:
    """Run the closed loop for ``steps`` steps, writing the MCAP log and/or the .rrd as asked."""
    if steps < 1:
        raise DagsError(f"bad value --steps {steps}: must be >= 1")
    sinks: list[Any] = []
    writer = rerun = None
    if record is not None:
        from recorder.mcap_log import LogWriter, run_metadata

        writer = LogWriter(record, run_metadata(cfg, cfg.seed, steps_requested=str(steps), **(extra_metadata or {})))
        sinks.append(McapSink(writer, last_step=steps - 1, map_every=map_every))
    if rrd is not None:
        from recorder.rerun_sink import RerunSink, recording_id_for

        rerun = RerunSink(rrd, recording_id=recording_id_for(record if record is not None else rrd))
        sinks.append(RerunStepSink(rerun, last_step=steps - 1, map_every=map_every))
    fan = _Fanout(sinks)
    bar = _bar(steps, cfg.sim.scene) if progress else None
    stop = {"asked": False}

    def on_progress(k: int, metrics: dict[str, float]) -> None:
        if bar is not None:
            bar.set_postfix_str(f"{int(metrics['n_gaussians'])} Gaussians, "
                                f"{fan.last_metrics.get('known_area_m2', 0.0):.1f} m^2 known", refresh=False)
            bar.update(1)
        if stop["asked"]:
            raise _Stop

    def on_sigint(signum: int, frame: Any) -> None:
        stop["asked"] = True
        signal.signal(signal.SIGINT, previous)       # a second Ctrl-C stops at once

    previous = signal.getsignal(signal.SIGINT)
    if handle_sigint:
        signal.signal(signal.SIGINT, on_sigint)
    t0 = time.perf_counter()
    t_loop = None
    interrupted = False
    refined, refine_seconds = 0, 0.0
    try:
        pipeline.run(cfg, steps, sink=fan, progress=on_progress)
        if bar is not None:
            bar.close()
        t_loop = time.perf_counter()
        refined = _refine(cfg, fan, stop, progress)
        refine_seconds = time.perf_counter() - t_loop
        if refined:
            if writer is not None:
                writer.write_refined_map(fan.states[1].gaussians, fan.last_stamp_ns + 1)
            if rerun is not None:
                rerun.log_refined_map(fan.states[1].gaussians, steps, fan.last_stamp_ns + 1)
    except _Stop:
        interrupted = True
    except BaseException:
        if writer is not None:
            writer.abort()                          # the file keeps every whole step written so far
        raise
    finally:
        seconds = (t_loop if t_loop is not None else time.perf_counter()) - t0      # the loop alone
        if handle_sigint:
            signal.signal(signal.SIGINT, previous)
        if bar is not None:
            bar.close()
        if rerun is not None:
            rerun.close()
    if writer is not None:
        writer.close({"interrupted": str(interrupted).lower(), "seconds": f"{seconds:.3f}",
                      "refine_seconds": f"{refine_seconds:.3f}"})
    return LiveResult(fan.steps, steps, seconds, interrupted, fan.states or [], np.asarray(fan.trajectory).reshape(-1, 2),
                      fan.collisions, fan.last_metrics, record, writer.bytes_written if writer else 0, rrd, refined,
                      refine_seconds)


def _refine(cfg: DagsConfig, fan: _Fanout, stop: dict[str, bool], progress: bool) -> int:
    """Refines the map in ``fan.states`` (DESIGN.md §5) with a progress bar; returns the Adam steps taken (0: none).
    Raises :class:`_Stop` after a Ctrl-C (checked after every Adam step)."""
    from dynactivegs.mapping.stage import refine_iters

    if fan.states is None:
        return 0
    iters = refine_iters(cfg.mapping, fan.states[1])
    if iters == 0:
        return 0

    def check() -> None:
        if stop["asked"]:
            raise _Stop

    fan.states = refine_with_bar(cfg, fan.states, desc="refine", progress=progress, after_iter=check)
    return iters


def refine_with_bar(cfg: DagsConfig, states: list[object], *, desc: str, progress: bool,
                    after_iter: Callable[[], None] | None = None) -> list[object]:
    """:func:`dynactivegs.pipeline.refine_map` with a progress bar of its Adam steps when ``progress``;
    ``after_iter()`` runs after every step (it may raise to stop the refinement)."""
    from dynactivegs.mapping.stage import refine_iters

    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=refine_iters(cfg.mapping, states[1]), desc=desc, unit="it", dynamic_ncols=True)

    def on_iter(k: int) -> None:
        if bar is not None:
            bar.update(1)
        if after_iter is not None:
            after_iter()

    try:
        return pipeline.refine_map(cfg, states, on_iter)
    finally:
        if bar is not None:
            bar.close()


def _bar(total: int, scene: str) -> Any:
    from tqdm import tqdm

    return tqdm(total=total, desc=scene, unit="step", dynamic_ncols=True)
