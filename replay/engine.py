"""Re-running stages of a recorded run: the check that a log is reproducible, and what-if runs.

:func:`replay` reads a log written by ``dagsrun --record``, rebuilds the run's config from
the log's metadata (with ``--set`` overrides applied on top) and, for every whole step,
re-runs the chosen stage and every stage after it with :func:`dynactivegs.pipeline.tick`,
the function the live loop runs. Inputs are the recorded ones (open loop): the recorded
frame, the recorded outputs of the stages before the chosen one, and ``prev_mapping``
(perception at step t reads the mapping output of step t-1): the *re-computed* one when
mapping is re-run, the logged one otherwise.

Stage states: every re-run stage starts from ``init_state`` of the config at the log's
first step, and a replay from ``--from-step K`` fast-forwards: it re-runs steps 0..K-1
silently and compares from K. The log holds no state snapshots. Fields, selection and
planning are cheap to fast-forward (a few ms per step), and perception and mapping states
(MLP and optimiser moments, the Gaussian map, keyframe images) would cost far more log
space than re-running them does time. Selection's state also holds a networkx graph,
which has no place in a versioned message schema.

A replay through the log's last step with mapping re-run also re-runs the offline
refinement that follows it (``mapping.refine_passes``) when the log holds its map
(``/map_refined``), and compares the two maps parameter by parameter.

Without overrides every re-run output is compared with the log field by field, exactly
(the stages are deterministic on one machine, DESIGN.md §3); the first difference is
reported as ``step K, topic /x, field f, max abs diff d``. With overrides the run is a
what-if run: :class:`WhatIf` counts the steps where outputs changed and summarises the
planning and selection changes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dynactivegs import pipeline
from dynactivegs.config import DagsConfig, config_from_json, config_value, with_overrides
from dynactivegs.errors import DagsError
from dynactivegs.records import MappingOut, StepRecord
from recorder.live import DEFAULT_MAP_EVERY, known_area_m2, occupancy_of, refine_with_bar, wants_map
from recorder.mcap_log import MAP_TOPIC, REFINED_MAP_TOPIC, STAGE_TOPICS, machine_difference, machine_info
from replay.source import LogEnd, LoggedStep, LogReader


@dataclass(frozen=True)
class Difference:
    """Where a re-run output first differs from the log."""

    step: int
    topic: str
    field: str
    detail: str                  # "max abs diff 0.25", "shape (3, 2) logged, (4, 2) replayed", ...

    def describe(self) -> str:
        return f"step {self.step}, topic {self.topic}, field {self.field}, {self.detail}"


def compare_records(replayed: object, logged: object) -> tuple[str, str] | None:
    """(field, detail) of the first field where two records of one type differ; None when they are identical.

    Arrays must have the same dtype, shape and values (NaN equals NaN); floats likewise.
    """
    assert type(replayed) is type(logged), (type(replayed), type(logged))
    for f in dataclasses.fields(replayed):
        if f.name == "target_reason" and getattr(logged, f.name) == "":
            continue                    # not logged before schema version 6
        detail = compare_values(getattr(replayed, f.name), getattr(logged, f.name))
        if detail is not None:
            return f.name, detail
    return None


def compare_values(a: object, b: object) -> str | None:
    """How a replayed value ``a`` differs from the logged ``b`` (see :func:`compare_records`); None when identical."""
    if isinstance(a, np.ndarray):
        if a.dtype != b.dtype or a.shape != b.shape:
            return f"{b.dtype} {b.shape} logged, {a.dtype} {a.shape} replayed"
        same = np.array_equal(a, b, equal_nan=True) if a.dtype.kind == "f" else np.array_equal(a, b)
        return None if same else f"max abs diff {_max_abs_diff(a, b):.6g}"
    if isinstance(a, float):
        return None if (a == b or (math.isnan(a) and math.isnan(b))) else f"max abs diff {abs(a - b):.6g}"
    if isinstance(a, (bool, int)):
        return None if a == b else f"max abs diff {abs(int(a) - int(b))}"
    return None if a == b else f"{b!r} logged, {a!r} replayed"


def _max_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    x, y = a.astype(np.float64), b.astype(np.float64)
    nan_mismatch = np.isnan(x) != np.isnan(y)
    if nan_mismatch.any():
        return math.nan
    d = np.abs(np.nan_to_num(x - y, nan=0.0))
    return float(d.max()) if d.size else 0.0


def path_length_m(path_xy_m: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path_xy_m, axis=0), axis=1).sum()) if len(path_xy_m) > 1 else 0.0


@dataclass
class WhatIf:
    """How a what-if replay's outputs differ from the log, step by step."""

    steps: int = 0
    differing: dict[str, int] = field(default_factory=dict)          # topic -> steps where it differs
    first: dict[str, Difference] = field(default_factory=dict)       # topic -> its first difference
    target_differs: int = 0
    action_differs: int = 0
    path_m: list[tuple[float, float]] = field(default_factory=list)  # (logged, replayed) path lengths
    n_gaussians: tuple[int, int] | None = None                        # (logged, replayed) at the last step
    compared_topics: tuple[str, ...] = ()                             # the re-run stages' topics
    refined_gaussians: tuple[int, int] | None = None                  # (logged, replayed) after the refinement

    def add(self, step: int, replayed: StepRecord, logged: LoggedStep, topics: list[str]) -> None:
        self.steps += 1
        for stage, topic in STAGE_TOPICS.items():
            if topic not in topics:
                continue
            d = compare_records(getattr(replayed, stage), logged[topic])
            if d is not None:
                self.differing[topic] = self.differing.get(topic, 0) + 1
                self.first.setdefault(topic, Difference(step, topic, *d))
        if "/selection" in topics:
            a, b = replayed.selection, logged["/selection"]
            if compare_records(_target(a), _target(b)) is not None:
                self.target_differs += 1
        if "/planning" in topics:
            a, b = replayed.planning, logged["/planning"]
            self.action_differs += int(a.action != b.action)
            self.path_m.append((path_length_m(b.path_xy_m), path_length_m(a.path_xy_m)))
        if "/mapping" in topics:
            self.n_gaussians = (logged["/mapping"].n_gaussians, replayed.mapping.n_gaussians)

    def lines(self) -> list[str]:
        out = []
        for topic in (t for t in STAGE_TOPICS.values() if t in self.differing or t in self.compared_topics):
            n = self.differing.get(topic, 0)
            first = f" (first: step {self.first[topic].step}, field {self.first[topic].field})" if n else ""
            out.append(f"{topic} differs at {n} of {self.steps} steps{first}")
        if "/selection" in self.compared_topics:
            out.append(f"selection target differs at {self.target_differs} of {self.steps} steps")
        if self.path_m:
            logged, replayed = (float(np.mean(v)) for v in zip(*self.path_m))
            rel = f" {100.0 * (replayed - logged) / logged:+.1f} %" if logged > 0 else ""
            out.append(f"planned path length{rel} (mean {logged:.2f} m logged, {replayed:.2f} m replayed)")
            out.append(f"actions differ at {self.action_differs} of {self.steps} steps")
        if self.n_gaussians is not None:
            out.append(f"Gaussians at the last step: {self.n_gaussians[0]} logged, {self.n_gaussians[1]} replayed")
        if self.refined_gaussians is not None:
            out.append(f"Gaussians after the refinement: {self.refined_gaussians[0]} logged, "
                       f"{self.refined_gaussians[1]} replayed")
        return out


@dataclass(frozen=True)
class _Target:
    """The chosen target of a SelectionOut (what "the target differs" compares)."""

    target_xy_m: np.ndarray
    target_yaw_rad: float
    target_node: int
    mode: str


def _target(s: Any) -> _Target:
    return _Target(s.target_xy_m, s.target_yaw_rad, s.target_node, s.mode)


@dataclass
class ReplayResult:
    """What :func:`replay` found."""

    config: DagsConfig
    from_stage: str
    steps_run: int                     # steps re-run, fast-forwarded ones included
    steps_compared: int
    first_difference: Difference | None
    whatif: WhatIf | None
    end: LogEnd | None
    refined_checked: bool = False      # the refinement was re-run and its map matched the log's /map_refined

    @property
    def exit_code(self) -> int:
        return 1 if self.whatif is None and self.first_difference is not None else 0


def _override_changes(cfg: DagsConfig, overrides: list[str]) -> list[str]:
    """``key=new (was old)`` for each override (keys already checked by ``with_overrides``)."""
    out = []
    for kv in overrides:
        out.append(f"{kv} (was {config_value(cfg, kv.split('=', 1)[0].strip())})")
    return out


def replay(path: str | Path, *, from_stage: str = "perception", from_step: int = 0, to_step: int | None = None,
           overrides: list[str] | tuple[str, ...] = (), rrd: str | Path | None = None,
           record: str | Path | None = None, say: Callable[[str], None] = print,
           progress: bool = False) -> ReplayResult:
    """Re-run ``from_stage`` and the stages after it on the log's steps ``from_step..to_step`` (inclusive).

    Compares with the log (no ``overrides``) or reports a what-if run (``overrides``); see the
    module docstring. ``say`` receives the report's lines.
    """
    first_stage = pipeline.stage_index(from_stage)
    if from_step < 0:
        raise DagsError(f"bad value --from-step {from_step}: must be >= 0")
    if to_step is not None and to_step < from_step:
        raise DagsError(f"bad value --to-step {to_step}: must be >= --from-step ({from_step})")
    reader = LogReader(path)
    if reader.config_json is None:
        raise DagsError(f"log {reader.path} has no config in its metadata; it was not written by dagsrun --record")
    logged_cfg = config_from_json(reader.config_json)
    overrides = list(overrides)
    cfg = with_overrides(logged_cfg, overrides)
    whatif = WhatIf(compared_topics=tuple(STAGE_TOPICS[s.name] for s in pipeline.STAGES[first_stage:])) if overrides else None
    rerun_topics = [STAGE_TOPICS[s.name] for s in pipeline.STAGES[first_stage:]]

    writer = rr_sink = None
    if record is not None:
        from recorder.mcap_log import LogWriter, run_metadata

        meta = {k: v for k, v in reader.metadata.items() if k not in ("config", "seed", "schema_version",
                                                                         "message_encoding") and
                not k.startswith(("version.", "machine."))}
        writer = LogWriter(record, run_metadata(cfg, cfg.seed, **meta, replayed_from=str(reader.path),
                                                replayed_from_stage=from_stage, overrides=" ".join(overrides)))
    if rrd is not None:
        from recorder.rerun_sink import RerunSink, recording_id_for

        rr_sink = RerunSink(rrd, recording_id=recording_id_for(rrd))

    states = pipeline.init_states(cfg)
    prev_logged: MappingOut | None = None
    prev_replayed: MappingOut | None = None
    steps_run = compared = 0
    first_diff: Difference | None = None
    refined_checked = False
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(desc=f"replay from {from_stage}", unit="step", dynamic_ncols=True)
    try:
        stop = None if to_step is None else to_step + 1
        for expected, ls in enumerate(reader.steps(0, stop)):
            if ls.step != expected:
                raise DagsError(f"log {reader.path} skips from step {expected - 1} to {ls.step}; replay needs every step "
                                "from 0")
            prev = prev_replayed if first_stage <= 1 else prev_logged
            logged_rec = ls.step_record(prev)
            missing = [t for t in ("/frame", *STAGE_TOPICS.values()) if t not in ls]
            if missing:
                raise DagsError(f"log {reader.path} step {ls.step} has no {', '.join(missing)}; replay needs the frame "
                                "and every stage output")
            rec_in = replace(logged_rec, **{s.name: None for s in pipeline.STAGES[first_stage:]})
            timings: dict[str, float] = {}
            states, out = pipeline.tick(cfg, rec_in, states, first_stage, timings)
            steps_run += 1
            prev_logged, prev_replayed = logged_rec.mapping, out.mapping
            if bar is not None:
                bar.update(1)
            if writer is not None:
                _write_step(writer, ls, out, states, timings, first_stage)
            if ls.step < from_step:
                continue
            compared += 1
            if rr_sink is not None:
                _log_rerun(rr_sink, ls, out, states, first_stage)
            if whatif is not None:
                whatif.add(ls.step, out, ls, rerun_topics)
            else:
                for stage in pipeline.STAGES[first_stage:]:
                    d = compare_records(getattr(out, stage.name), ls[STAGE_TOPICS[stage.name]])
                    if d is not None:
                        first_diff = Difference(ls.step, STAGE_TOPICS[stage.name], *d)
                        break
                if first_diff is not None:
                    break
        if first_diff is None and compared and _reached_end(reader, to_step):
            first_diff, refined_checked = _replay_refinement(cfg, reader, states, first_stage, whatif, writer,
                                                             ls.stamp_ns, ls.step, progress)
    finally:
        if bar is not None:
            bar.close()
        if rr_sink is not None:
            rr_sink.close()
        if writer is not None:
            writer.close()
    if compared == 0 and first_diff is None:
        last = "no whole step" if reader.end is None or reader.end.last_step is None else \
            f"steps 0..{reader.end.last_step}"
        raise DagsError(f"nothing to replay: log {reader.path} has {last}, --from-step is {from_step}")
    res = ReplayResult(cfg, from_stage, steps_run, compared, first_diff, whatif, reader.end, refined_checked)
    _report(res, reader, from_step, overrides, logged_cfg, say, record, rrd)
    return res


def _reached_end(reader: LogReader, to_step: int | None) -> bool:
    """Whether the replay ran through the log's last whole step (the refined map comes after it)."""
    end = reader.end
    return end is not None and end.last_step is not None and (to_step is None or to_step >= end.last_step)


def _replay_refinement(cfg: DagsConfig, reader: LogReader, states: list[object], first_stage: int,
                       whatif: WhatIf | None, writer: Any, last_stamp_ns: int,
                       last_step: int, progress: bool) -> tuple[Difference | None, bool]:
    """The offline refinement after the last step, when the log has its map (``/map_refined``).

    With mapping re-run (and perception, where the refinement reads it: ``mapping.refine_beta=final``),
    the refinement is re-run from the replayed map and keyframes and its map compared with the logged
    one, parameter by parameter (or, in a what-if run, its size reported); otherwise the logged
    refined map is copied to a new log.
    Returns the first difference and whether the refined maps were compared and matched.
    """
    logged = reader.refined_map()
    if logged is None:
        return None, False
    # a refinement that reads the perception state needs its final MLP, which only a replay that
    # re-runs perception has
    if first_stage > 1 or (first_stage == 1 and pipeline.refine_reads_perception(cfg)):
        if writer is not None:
            writer.write_refined_map(logged, last_stamp_ns + 1)
        return None, False
    replayed = refine_with_bar(cfg, states, desc="replay refinement", progress=progress)[1].gaussians
    if writer is not None:
        writer.write_refined_map(replayed, last_stamp_ns + 1)
    if whatif is not None:
        whatif.refined_gaussians = (len(logged), len(replayed))
        return None, False
    for f in dataclasses.fields(replayed):
        a, b = (getattr(g, f.name).detach().cpu().numpy() for g in (replayed, logged))
        detail = compare_values(a, b)
        if detail is not None:
            return Difference(last_step, REFINED_MAP_TOPIC, f.name, detail), False
    return None, True


def _write_step(writer: Any, ls: LoggedStep, out: StepRecord, states: list[object], timings: dict[str, float],
                first_stage: int) -> None:
    t = ls.stamp_ns
    writer.write_step_record(out, t)
    if "/truth" in ls:
        writer.write_raw("/truth", "SimTruth", ls.raw["/truth"], t)
    metrics = {**pipeline.step_metrics(out, timings), "known_area_m2": known_area_m2(states[3])}
    writer.write_metrics(ls.step, metrics, t)
    if MAP_TOPIC in ls:
        if first_stage <= 1:
            writer.write_map(states[1].gaussians, t)
        else:
            writer.write_raw(MAP_TOPIC, "state", ls.raw[MAP_TOPIC], t)
    writer.end_step(ls.step, t)


def _log_rerun(sink: Any, ls: LoggedStep, out: StepRecord, states: list[object], first_stage: int) -> None:
    g = None
    if first_stage <= 1:
        if MAP_TOPIC in ls or wants_map(ls.step, -1, DEFAULT_MAP_EVERY):
            g = states[1].gaussians
    elif MAP_TOPIC in ls:
        g = ls[MAP_TOPIC]
    metrics = ls.get("/metrics")
    sink.log_step(out.frame, truth=ls.get("/truth"), perception=out.perception, mapping=out.mapping, fields=out.fields,
                  selection=out.selection, planning=out.planning, gaussians=g, occupancy=occupancy_of(states[3]),
                  metrics=metrics.values if metrics is not None and first_stage > 1 else None)


def logged_on_other_machine(metadata: dict[str, str]) -> str | None:
    """How the machine in a log's ``machine.*`` metadata differs from this one; None if it is this one (or the
    log is older than that metadata)."""
    logged = {k.removeprefix("machine."): v for k, v in metadata.items() if k.startswith("machine.")}
    return machine_difference(logged, machine_info())


def _report(res: ReplayResult, reader: LogReader, from_step: int, overrides: list[str], logged_cfg: DagsConfig,
            say: Callable[[str], None], record: Any, rrd: Any) -> None:
    end = reader.end
    last = from_step + res.steps_compared - 1
    span = f"steps {from_step}..{last}" + (f" (steps 0..{from_step - 1} fast-forwarded)" if from_step > 0 else "")
    if res.whatif is not None:
        say(f"what-if: {'; '.join(_override_changes(logged_cfg, overrides))}")
        say(f"replayed {res.from_stage} and after on {span}, open loop on the recorded frames")
        for line in res.whatif.lines():
            say(f"  {line}")
    elif res.first_difference is not None:
        say(f"replay of {res.from_stage} and after differs from the log at {res.first_difference.describe()}")
        other = logged_on_other_machine(reader.metadata)
        if other:
            say(f"note: the log was recorded on another machine ({other}); the stages repeat bit for bit on one "
                f"machine only, so replay it where it was recorded to look for a real change")
    else:
        topics = ", ".join(STAGE_TOPICS[s.name] for s in pipeline.STAGES[pipeline.stage_index(res.from_stage):])
        if res.refined_checked:
            topics += f" and {REFINED_MAP_TOPIC} (the refinement re-run after step {last})"
        say(f"replayed {res.from_stage} and after on {span}: {topics} identical to the log")
    if end is not None and not end.complete:
        say(f"note: {end.describe()}; its {end.steps} whole steps were read")
    if record is not None:
        say(f"log:   {record}")
    if rrd is not None:
        say(f"rerun: {rrd}")
