"""``dagsbench``: presets x scenes x seeds, each run measured at 25/50/75/100 % of its step budget.

Every run is independent: it builds its config (preset, scene, seed, ``--set`` overrides),
runs the closed loop with an MCAP sink (unless ``--no-mcap``), snapshots the Gaussian map at
the checkpoints of :func:`dynactivegs.eval.progress.checkpoint_steps`, measures a cheap
coverage every few steps, refines the map after the last step (``mapping.refine_passes``, the
method's offline refinement; the log keeps it on ``/map_refined``), and evaluates the
snapshots with :class:`dynactivegs.eval.metrics.SceneEvaluator`. The 25/50/75 % rows measure
the map as the loop left it at that step; the 100 % row measures the refined map, the
method's output, and keeps the unrefined map's metrics under ``online``. The held-out views
avoid the run's whole trajectory, so every checkpoint of a run is measured on the same views.

Layout of ``--out``::

    runs/<preset>/<scene>-seed<k>.json    metrics at the checkpoints, coverage curve, timing, config, machine
    runs/<preset>/<scene>-seed<k>.mcap    the run's log (dagsreplay reads it)
    main.md / main.csv                    methods x metrics, scenes + mean (best in bold)
    ablation_components.md/.csv           Table 3 layout (which components are on)
    ablation_selection.md/.csv            Table 4 layout (view-selection variants)
    ablation_planner.md/.csv              Table 5 layout (planner variants at 25-100 % path ratio)
    progress.png, coverage.png            PSNR and C.R. over steps; coverage over steps, per method

A run whose metrics file exists is skipped, so an interrupted sweep resumes where it stopped.
Each metrics file records the machine it was made on (:func:`recorder.mcap_log.machine_info`): the closed loop
repeats bit for bit on one machine only, so a sweep that mixes machines is warned about.
``--reevaluate`` measures finished runs again from the map snapshots in their MCAP logs (the
runs log the map at every checkpoint) with the current evaluation settings.
Runs go to a local process pool (``--workers``) or to Ray tasks (``--ray ADDRESS``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator

from dynactivegs.config import DagsConfig, PRESETS, preset, to_json, with_overrides
from dynactivegs.errors import DagsError

SUITES: dict[str, tuple[str, ...]] = {
    "tiny": ("tiny-00", "tiny-01"),
    "apartment": tuple(f"apartment-{i:02d}" for i in range(4)),
    "house": tuple(f"house-{i:02d}" for i in range(4)),
    "loop": tuple(f"loop-{i:02d}" for i in range(4)),
}
"""Named scene suites of ``--suite``."""

COVERAGE_POINTS_PER_RUN = 50
"""The cheap coverage is measured about this many times per run (every ``steps // 50`` steps, and the last)."""

RESULT_VERSION = 1
"""Version of the per-run metrics file."""


@dataclass(frozen=True, slots=True)
class RunSpec:
    """One run of the sweep: what to run and where its files go."""

    preset: str
    scene: str
    seed: int
    steps: int
    overrides: tuple[str, ...]          # DagsConfig key=value, applied after preset, scene and seed
    eval_overrides: tuple[str, ...]     # EvalConfig key=value (given as eval.key=value on the command line)
    out_dir: str
    mcap: bool = True
    device: str | None = None           # mapping.device; None: the preset's

    @property
    def name(self) -> str:
        return f"{self.preset}/{self.scene}/seed{self.seed}"

    @property
    def stem(self) -> Path:
        return Path(self.out_dir) / "runs" / self.preset / f"{self.scene}-seed{self.seed}"

    @property
    def metrics_path(self) -> Path:
        return self.stem.with_suffix(".json")

    @property
    def mcap_path(self) -> Path:
        return self.stem.with_suffix(".mcap")

    def config(self) -> DagsConfig:
        cfg = with_overrides(preset(self.preset), [f"sim.scene={self.scene}", f"seed={self.seed}"])
        if self.device is not None:
            cfg = with_overrides(cfg, [f"mapping.device={self.device}"])
        return with_overrides(cfg, list(self.overrides))

    def eval_config(self) -> Any:
        from dynactivegs.eval.config import EvalConfig

        return with_overrides(EvalConfig(), list(self.eval_overrides))


def parse_list(text: str, what: str) -> list[str]:
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise DagsError(f"bad value for --{what}: {text!r} is empty")
    return items


def resolve_scenes(suite: str) -> list[str]:
    """A suite name (tiny, apartment, house, loop) or a comma list of scene names; unknown scenes fail in one line."""
    from dynactivegs.sim.config import SimConfig
    from dynactivegs.sim.scenes import load_scene

    scenes = list(SUITES[suite]) if suite in SUITES else parse_list(suite, "suite")
    for s in scenes:
        if s in SUITES:
            raise DagsError(f"bad --suite {suite!r}: a suite name ({', '.join(SUITES)}) cannot be in a list")
        load_scene(SimConfig(scene=s))   # one-line SceneError for an unknown name or missing file
    return scenes


def plan_runs(presets: list[str], scenes: list[str], seeds: list[int], steps: int, overrides: list[str],
              out_dir: Path, *, mcap: bool = True, device: str | None = None) -> list[RunSpec]:
    """Every (preset, scene, seed) run, configs checked up front (bad names and overrides fail in one line).

    Ordered seed, then scene, then preset: a sweep stopped part way has every preset of the
    (scene, seed) pairs it finished, so its tables still compare like with like."""
    if steps < 1:
        raise DagsError(f"bad value --steps {steps}: must be >= 1")
    for p in presets:
        preset(p)
    dags_ov = tuple(kv for kv in overrides if not kv.startswith("eval."))
    eval_ov = tuple(kv[len("eval."):] for kv in overrides if kv.startswith("eval."))
    specs = [RunSpec(p, s, k, steps, dags_ov, eval_ov, str(out_dir), mcap, device)
             for k in seeds for s in scenes for p in presets]
    for spec in specs[:1]:
        spec.config()
        spec.eval_config()
    return specs


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, dict):
        return {prefix: d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


# Options added with a default that changed the behaviour before them: the value a config without the key
# (made by older code) stands for.
BEFORE_OPTION: dict[str, Any] = {
    "selection.local_people_steps": 0,
}


def config_difference(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The keys (dotted) two configs as JSON have with different values. A key only one has is an option added
    between the two versions of the code; most options come with a default that keeps the behaviour before them,
    so such a key is no difference, but one of ``BEFORE_OPTION`` counts as that value where it is missing."""
    fa, fb = _flat(a), _flat(b)
    for f, g in ((fa, fb), (fb, fa)):
        f.update({k: v for k, v in BEFORE_OPTION.items() if k not in f and k in g})
    return sorted(k for k in fa.keys() & fb.keys() if fa[k] != fb[k])


def check_finished(spec: RunSpec) -> bool:
    """True when the run's metrics file exists; a one-line error when it was made with other settings (steps, or
    a config value: :func:`config_difference`)."""
    if not spec.metrics_path.is_file():
        return False
    done = json.loads(spec.metrics_path.read_text())
    if done.get("steps") != spec.steps:
        raise DagsError(f"{spec.metrics_path} was run with {done.get('steps')} steps, not {spec.steps}; "
                        f"use another --out")
    differ = config_difference(done.get("config") or {}, json.loads(to_json(spec.config())))
    if differ:
        shown = ", ".join(differ[:3]) + (f" and {len(differ) - 3} more" if len(differ) > 3 else "")
        raise DagsError(f"{spec.metrics_path} was run with other settings ({shown}); use another --out")
    return True


def other_machine_line(finished: list[dict[str, Any]], here: str) -> str | None:
    """A warning when some of the ``finished`` runs a sweep resumes were made on another machine than ``here``
    (a machine id); else None."""
    from dynactivegs.eval.tables import machine_id_of

    other = [r for r in finished if machine_id_of(r) not in (None, here)]
    if not other:
        return None
    return (f"dagsbench: warning: {len(other)} of the {len(finished)} finished runs in this folder were made on "
            f"another machine than this one ({here}); runs do not repeat across machines, so the new runs will "
            f"not pair with them as runs of one machine do (use another --out to keep machines apart)")


# ---------------------------------------------------------------------------------------- one run
class _ProgressSink:
    """Snapshots the map at the checkpoint step counts, measures coverage every ``every`` steps and the
    observed surface (of the coverage probe's points) at every step."""

    def __init__(self, checkpoints: tuple[int, ...], probe: Any, observed: Any, every: int, last: int) -> None:
        self.checkpoints = set(checkpoints)
        self.probe = probe
        self.every = every
        self.last = last
        self.snapshots: dict[int, Any] = {}
        self.coverage: list[tuple[int, float]] = []
        self.observed = observed                      # an empty ObservedSurface of the probe's points
        self.seen_at: dict[int, Any] = {}             # checkpoint step count -> the points seen by then
        self.last_stamp_ns = 0

    def on_step(self, rec: Any, truth: Any, states: list[object], metrics: dict[str, float]) -> None:
        done = rec.frame.step + 1                     # steps taken so far
        self.last_stamp_ns = rec.frame.stamp_ns
        self.observed.update(rec.frame.depth_m, rec.frame.K, rec.frame.T_world_cam)
        g = states[1].gaussians
        if done in self.checkpoints:
            from dynactivegs.splat.gaussians import Gaussians

            self.snapshots[done] = Gaussians(*(t.detach().clone() for t in g.tensors()))
            self.seen_at[done] = self.observed.seen.copy()
        if done % self.every == 0 or done == self.last or done == 1:
            self.coverage.append((done, self.probe.of_gaussians(g)))


@dataclass
class _Fanout:
    sinks: list[Any]

    def on_step(self, rec: Any, truth: Any, states: list[object], metrics: dict[str, float]) -> None:
        for s in self.sinks:
            s.on_step(rec, truth, states, metrics)


ONLINE_KEYS = ("acc_cm", "comp_cm", "cr_pct", "psnr_db", "ssim", "depth_l1_cm", "lpips", "psnr_right_db")
"""Metrics of the unrefined final map kept in the 100 % row under ``online``."""


def evaluate_row(evaluator: Any, fraction: float, step: int, g: Any, trajectory_xy_m: Any, refined: Any,
                 iters: int, **extra: Any) -> dict[str, Any]:
    """One checkpoint row: the metrics of ``refined`` (with ``online``: those of ``g``) or, when it is None, of ``g``.
    ``refine_iters`` says which (0: ``g``, the map as the loop left it)."""
    m = evaluator.evaluate(g, step=step, trajectory_xy_m=trajectory_xy_m)
    if refined is None:
        return {"fraction": fraction, "n_gaussians": len(g), **extra, "refine_iters": 0, **dataclasses.asdict(m)}
    r = evaluator.evaluate(refined, step=step, trajectory_xy_m=trajectory_xy_m)
    online = {"n_gaussians": len(g), **{k: getattr(m, k) for k in ONLINE_KEYS}}
    return {"fraction": fraction, "n_gaussians": len(refined), **extra, "refine_iters": iters,
            **dataclasses.asdict(r), "online": online}


def observed_note(n_points: int) -> str:
    """What a checkpoint row's ``observed_pct`` and ``observed_view_pct`` are (the metrics file says it beside
    the numbers)."""
    from dynactivegs.eval.progress import OBSERVED_TOL_M

    return (f"observed_pct: % of the {n_points} coverage probe points the camera "
            f"saw by the step (depth return within {OBSERVED_TOL_M * 100:g} cm of the point); observed_view_pct: "
            "% of the held-out views' pixels showing surface it saw (the probe points each view sees, each "
            "weighted by the pixels its patch of surface fills)")


def observed_extra(evaluator: Any, observed: Any, seen: Any, trajectory_xy_m: Any) -> dict[str, float]:
    """A checkpoint row's ``observed_pct`` and ``observed_view_pct`` (:func:`observed_note`) from the mask
    ``seen`` of ``observed``'s points."""
    return {"observed_pct": float(seen.mean() * 100.0) if len(seen) else 0.0,
            "observed_view_pct": evaluator.observed_view_pct(observed, trajectory_xy_m, seen)}


def run_one(spec: RunSpec, torch_threads: int | None = None) -> dict[str, Any]:
    """Run ``spec``, evaluate it at its checkpoints and write its metrics file (atomically); returns its contents."""
    from dynactivegs import pipeline
    from dynactivegs.eval.metrics import SceneEvaluator
    from dynactivegs.eval.progress import CHECKPOINT_FRACTIONS, checkpoint_steps
    from dynactivegs.mapping.stage import refine_iters
    from recorder.mcap_log import machine_info

    if torch_threads is not None:
        import torch

        torch.set_num_threads(torch_threads)
    cfg, ecfg = spec.config(), spec.eval_config()
    spec.stem.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    evaluator = SceneEvaluator(cfg.sim, ecfg)
    t_setup = time.perf_counter() - t0
    checkpoints = checkpoint_steps(spec.steps)
    probe = evaluator.coverage_probe()
    progress = _ProgressSink(checkpoints, probe, evaluator.observed_surface(probe),
                             max(1, spec.steps // COVERAGE_POINTS_PER_RUN), spec.steps)
    sinks: list[Any] = [progress]
    writer = None
    if spec.mcap:
        from recorder.live import McapSink
        from recorder.mcap_log import LogWriter, run_metadata

        writer = LogWriter(spec.mcap_path, run_metadata(cfg, cfg.seed, steps_requested=str(spec.steps),
                                                        preset=spec.preset))
        sinks.append(McapSink(writer, last_step=spec.steps - 1, also_at=tuple(c - 1 for c in checkpoints)))
    t1 = time.perf_counter()
    try:
        res = pipeline.run(cfg, spec.steps, sink=_Fanout(sinks))
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    t_run = time.perf_counter() - t1
    t_ref = time.perf_counter()
    iters = refine_iters(cfg.mapping, res.states[1])
    refined = None
    try:
        if iters > 0:
            refined = pipeline.refine_map(cfg, res.states)[1].gaussians
            if writer is not None:
                writer.write_refined_map(refined, progress.last_stamp_ns + 1)
    except BaseException:
        if writer is not None:
            writer.abort()
        raise
    t_ref = time.perf_counter() - t_ref
    if writer is not None:
        writer.close({"interrupted": "false", "seconds": f"{t_run:.3f}", "refine_seconds": f"{t_ref:.3f}"})
    t2 = time.perf_counter()
    rows = [evaluate_row(evaluator, frac, step, progress.snapshots[step], res.trajectory_xy_m,
                         refined if step == spec.steps else None, iters,
                         **observed_extra(evaluator, progress.observed, progress.seen_at[step], res.trajectory_xy_m))
            for frac, step in zip(CHECKPOINT_FRACTIONS, checkpoints)]
    result = {
        "version": RESULT_VERSION, "preset": spec.preset, "scene": spec.scene, "seed": spec.seed,
        "steps": spec.steps, "overrides": list(spec.overrides), "eval_overrides": list(spec.eval_overrides),
        "config": json.loads(to_json(cfg)), "eval_config": json.loads(to_json(ecfg)),
        "checkpoints": rows, "coverage": [[s, c] for s, c in progress.coverage],
        "coverage_note": f"% of {len(probe.points_m)} ground-truth points within "
                         f"{ecfg.cr_threshold_cm:g} cm of an opaque Gaussian centre",
        "observed_note": observed_note(len(probe.points_m)),
        "seconds_per_step": res.seconds_per_step, "seconds_run": t_run, "seconds_refine": t_ref,
        "seconds_eval": time.perf_counter() - t2,
        "seconds_setup": t_setup, "collisions": res.collisions,
        "mcap": spec.mcap_path.name if spec.mcap else None,
        "machine": machine_info(),          # runs are promised to repeat bit for bit only on one id
    }
    tmp = spec.metrics_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(result, indent=1))
    os.replace(tmp, spec.metrics_path)
    return result


def _logged_maps(mcap_path: Path, steps: list[int], observed: Any
                 ) -> tuple[dict[int, tuple[int, Any]], Any, Any, dict[int, Any]]:
    """From a run's log: for each wanted step index, (the logged step used, its map snapshot), the
    trajectory (T, 2) from ``/truth``, the refined map (None if the log has none) and the points of
    ``observed`` (an :class:`~dynactivegs.eval.progress.ObservedSurface`, updated with every logged frame) seen
    after each wanted step (a bool mask). The snapshot at the step itself is used when logged, else the nearest
    later one (logs written before checkpoint snapshots were added have them every 50 steps)."""
    import numpy as np

    from replay.source import LogReader
    from recorder.mcap_log import MAP_TOPIC

    reader = LogReader(mcap_path)
    logged: dict[int, Any] = {}
    traj = []
    seen_at: dict[int, Any] = {}
    wanted = set(steps)
    for st in reader.steps():
        traj.append((st["/truth"].robot.x_m, st["/truth"].robot.y_m))
        f = st["/frame"]
        observed.update(f.depth_m, f.K, f.T_world_cam)
        if st.step in wanted:
            seen_at[st.step] = observed.seen.copy()
        if MAP_TOPIC in st:
            logged[st.step] = st
    maps: dict[int, tuple[int, Any]] = {}
    for want in steps:
        later = [k for k in logged if k >= want]
        if not later:
            raise DagsError(f"{mcap_path}: no map snapshot at or after step {want} (the log ends at step "
                            f"{reader.end.last_step if reader.end else '?'}); re-run it instead")
        k = min(later)
        maps[want] = (k, logged[k][MAP_TOPIC])
    return maps, np.asarray(traj, np.float64).reshape(-1, 2), reader.refined_map(), seen_at


def reevaluate_one(metrics_path: Path, eval_overrides: tuple[str, ...] = ()) -> dict[str, Any]:
    """Measure a finished run again from its MCAP log with the current evaluation (``eval_overrides``:
    EvalConfig key=value); the exploration is not re-run. Rewrites the metrics file (atomically) with
    the new checkpoint rows; each row's ``map_step`` says which logged map it measured."""
    from dynactivegs.config import config_from_json
    from dynactivegs.eval.config import EvalConfig
    from dynactivegs.eval.metrics import SceneEvaluator

    done = json.loads(metrics_path.read_text())
    if not done.get("mcap"):
        raise DagsError(f"{metrics_path}: the run kept no MCAP log (--no-mcap), so it cannot be re-evaluated; "
                        "re-run it")
    mcap_path = metrics_path.with_name(done["mcap"])
    if not mcap_path.is_file():
        raise DagsError(f"{mcap_path}: missing; the run's log is needed to re-evaluate it (or re-run it)")
    cfg = config_from_json(json.dumps(done["config"]))
    ecfg = with_overrides(EvalConfig(), list(eval_overrides))
    t0 = time.perf_counter()
    evaluator = SceneEvaluator(cfg.sim, ecfg)
    old_rows = done["checkpoints"]
    observed = evaluator.observed_surface()
    maps, traj, refined, seen_at = _logged_maps(mcap_path, [r["step"] - 1 for r in old_rows], observed)
    last = max(r["step"] for r in old_rows)
    rows = []
    for r in old_rows:
        used, g = maps[r["step"] - 1]
        final = refined if r["step"] == last else None
        rows.append(evaluate_row(evaluator, r["fraction"], r["step"], g, traj, final,
                                 r.get("refine_iters", 0) if final is not None else 0, map_step=used + 1,
                                 **observed_extra(evaluator, observed, seen_at[r["step"] - 1], traj)))
    done.update(checkpoints=rows, observed_note=observed_note(len(observed.points_m)), eval_overrides=list(eval_overrides),
                eval_config=json.loads(to_json(ecfg)),
                seconds_eval=time.perf_counter() - t0, reevaluated=time.strftime("%Y-%m-%d"))
    tmp = metrics_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(done, indent=1))
    os.replace(tmp, metrics_path)
    return done


def _reeval_worker(path: str, eval_overrides: tuple[str, ...]) -> dict[str, Any]:
    import torch

    torch.set_num_threads(1)
    return reevaluate_one(Path(path), eval_overrides)


def reevaluate(specs: list[RunSpec], *, workers: int = 1, progress: bool = True) -> list[dict[str, Any]]:
    """:func:`reevaluate_one` for every finished run of ``specs`` (unfinished ones are left alone)."""
    from tqdm import tqdm

    paths = [str(s.metrics_path) for s in specs if s.metrics_path.is_file()]
    if not paths:
        return []
    ov = specs[0].eval_overrides
    if workers > 1:
        from dynactivegs.config import config_from_json

        prepare_scenes((config_from_json(json.dumps(json.loads(Path(p).read_text())["config"])).sim,
                        specs[0].eval_config()) for p in paths)
    bar = tqdm(total=len(paths), desc="re-evaluate", unit="run", disable=not progress, dynamic_ncols=True)
    out = []
    try:
        if workers <= 1:
            for p in paths:
                out.append(reevaluate_one(Path(p), ov))
                bar.update(1)
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed

            with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                     initializer=_die_with_parent, initargs=(os.getpid(),)) as pool:
                for f in as_completed([pool.submit(_reeval_worker, p, ov) for p in paths]):
                    out.append(f.result())
                    bar.update(1)
    finally:
        bar.close()
    return out


def _worker(spec: RunSpec, torch_threads: int | None) -> dict[str, Any]:
    return run_one(spec, torch_threads)


# ---------------------------------------------------------------------------------------- the sweep
def _die_with_parent(parent_pid: int) -> None:
    """Pool initializer: on Linux the worker is sent SIGTERM when the dagsbench process dies, so a
    killed sweep leaves no workers running; elsewhere a no-op. A worker whose parent died before
    this ran (while the worker was still importing) is no longer its child and exits at once."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent_pid:
        os._exit(1)


def run_local(specs: list[RunSpec], workers: int) -> Iterator[dict[str, Any]]:
    """Results of ``specs`` as they finish, on ``workers`` processes (in this process when 1)."""
    if workers <= 1:
        for spec in specs:
            yield run_one(spec)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                             initializer=_die_with_parent, initargs=(os.getpid(),)) as pool:
        futures = [pool.submit(_worker, spec, 1) for spec in specs]
        for f in as_completed(futures):
            yield f.result()


def run_ray(specs: list[RunSpec], address: str, gpu: bool) -> Iterator[dict[str, Any]]:
    """Results of ``specs`` as they finish, as Ray tasks of one CPU (or one GPU) each on the cluster at ``address``.

    ``address``: ``local`` starts a local instance; ``auto`` or ``host:port`` joins a running
    cluster. Ray schedules the tasks; each sets torch to one thread.
    """
    try:
        import ray
    except ImportError as e:
        raise DagsError(f"--ray needs Ray: pip install 'dynactivegs[ray]' ({e})") from None
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        task = ray.remote(_worker).options(num_gpus=1) if gpu else ray.remote(_worker).options(num_cpus=1)
        pending = [task.remote(spec, 1) for spec in specs]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


def prepare_scenes(setups: Iterable[tuple[Any, Any]]) -> None:
    """Compute (or find cached) the ground-truth points and, for the renders reconstruction, the survey
    views of each distinct (SimConfig, EvalConfig) once, before parallel workers all would."""
    from dynactivegs.eval.geometry import ground_truth_points, survey

    seen = set()
    for sim, ecfg in setups:
        key = (to_json(sim), to_json(ecfg))
        if key not in seen:
            seen.add(key)
            gt = ground_truth_points(sim, ecfg)
            if ecfg.recon_method == "renders":
                survey(sim, ecfg, gt)


def prepare_ground_truth(specs: list[RunSpec]) -> None:
    """:func:`prepare_scenes` for the runs of ``specs``."""
    prepare_scenes((spec.config().sim, spec.eval_config()) for spec in specs)


def sweep(specs: list[RunSpec], *, workers: int = 1, ray_address: str | None = None, gpu: bool = False,
          progress: bool = True) -> tuple[list[RunSpec], list[dict[str, Any]]]:
    """Run the unfinished ``specs``; returns (the skipped ones, the new results)."""
    todo = [s for s in specs if not check_finished(s)]
    skipped = [s for s in specs if s not in todo]
    results: list[dict[str, Any]] = []
    if not todo:
        return skipped, results
    if skipped:
        from recorder.mcap_log import machine_info

        line = other_machine_line([json.loads(sp.metrics_path.read_text()) for sp in skipped], machine_info()["id"])
        if line:
            print(line, flush=True)
    from tqdm import tqdm

    if not ray_address and workers > 1:
        prepare_ground_truth(todo)
    bar = tqdm(total=len(todo), desc="runs", unit="run", disable=not progress, dynamic_ncols=True)
    stream = run_ray(todo, ray_address, gpu) if ray_address else run_local(todo, workers)
    try:
        for r in stream:
            results.append(r)
            last = r["checkpoints"][-1]
            bar.set_postfix_str(f"{r['preset']}/{r['scene']}/seed{r['seed']}: C.R. {last['cr_pct']:.1f} %, "
                                f"PSNR {last['psnr_db']:.2f} dB", refresh=False)
            bar.update(1)
    finally:
        bar.close()
    return skipped, results


def load_results(out_dir: Path) -> list[dict[str, Any]]:
    """Every finished run's metrics under ``out_dir/runs``."""
    return [json.loads(p.read_text()) for p in sorted((out_dir / "runs").glob("*/*.json"))]


# ---------------------------------------------------------------------------------------- CLI
def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dagsbench", description="Run presets x scenes x seeds, measure every run at "
                                "25/50/75/100 %% of its budget, write the paper-style tables and plots.")
    p.add_argument("--presets", default="baseline,weighted,motion_view,full,frontier",
                   help=f"comma list of {', '.join(PRESETS)} (default: baseline,weighted,motion_view,full,frontier)")
    p.add_argument("--suite", default="apartment",
                   help=f"{', '.join(f'{k} ({v[0]}..{v[-1]})' for k, v in SUITES.items())} or a comma list of scenes")
    p.add_argument("--seeds", default="0,1,2", help="comma list of master seeds (default: 0,1,2)")
    p.add_argument("--steps", type=int, default=1000, help="step budget of every run (default: 1000)")
    p.add_argument("--out", type=Path, required=True, help="results directory, e.g. benchmarks/results/apartment")
    p.add_argument("--workers", type=int, help="local processes (default: 1, or half the cores when there are 4+)")
    p.add_argument("--ray", metavar="ADDRESS", help="run on Ray: 'local' starts one, 'auto' or host:port joins one")
    p.add_argument("--device", choices=("cpu", "cuda"), help="where mapping runs (sets mapping.device); with --ray "
                   "cuda, each task asks for one GPU")
    p.add_argument("--set", dest="overrides", action="append", default=[], nargs="+", metavar="KEY=VALUE",
                   help="config overrides for every run, e.g. sim.camera.width_px=64; eval.KEY=VALUE sets the "
                   "evaluation (e.g. eval.n_views=20)")
    p.add_argument("--no-mcap", dest="mcap", action="store_false", help="do not save the runs' MCAP logs")
    p.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar")
    p.add_argument("--reevaluate", action="store_true", help="measure the finished runs again from their MCAP logs "
                   "with the current evaluation settings (and --set eval.KEY=VALUE), without re-running them; "
                   "unfinished runs are not started")
    p.add_argument("--wins-against", default="baseline", metavar="PRESET",
                   help="the preset every other is put against, pair by pair, in wins.md / wins.png and the summary "
                        "printed at the end; only runs this command names count, so list it in --presets too "
                        "(default: baseline)")
    return p


def default_workers() -> int:
    cores = os.cpu_count() or 1
    return max(1, cores // 2) if cores >= 4 else 1


def run(args: argparse.Namespace) -> int:
    presets = parse_list(args.presets, "presets")
    for p in (*presets, args.wins_against):
        preset(p)                           # an unknown name fails before any scene is built
    try:
        seeds = [int(s) for s in parse_list(args.seeds, "seeds")]
    except ValueError:
        raise DagsError(f"bad value for --seeds: {args.seeds!r}; write integers, e.g. 0,1,2") from None
    scenes = resolve_scenes(args.suite)
    workers = args.workers if args.workers is not None else default_workers()
    if workers < 1:
        raise DagsError(f"bad value --workers {workers}: must be >= 1")
    if args.device == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise DagsError(f"--device cuda: no CUDA device available to torch {torch.__version__}; use --device cpu")
    overrides = [kv for group in args.overrides for kv in group]
    specs = plan_runs(presets, scenes, seeds, args.steps, overrides, args.out, mcap=args.mcap, device=args.device)
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if args.reevaluate:
        results = reevaluate(specs, workers=workers, progress=args.progress)
        print(f"dagsbench: {len(results)} finished run{'s' if len(results) != 1 else ''} re-evaluated in "
              f"{time.perf_counter() - t0:.1f} s, {len(specs) - len(results)} not run yet (left alone)")
    else:
        skipped, results = sweep(specs, workers=workers, ray_address=args.ray, gpu=args.device == "cuda",
                                 progress=args.progress)
        where = f"Ray ({args.ray})" if args.ray else f"{workers} local worker{'s' if workers > 1 else ''}"
        print(f"dagsbench: {len(results)} run{'s' if len(results) != 1 else ''} in {time.perf_counter() - t0:.1f} s "
              f"on {where}, {len(skipped)} already finished (skipped)")
    from dynactivegs.eval.tables import write_reports

    wanted = {(s.preset, s.scene, s.seed) for s in specs}
    finished = [r for r in load_results(args.out) if (r["preset"], r["scene"], r["seed"]) in wanted]
    for path in write_reports(finished, args.out, reference=args.wins_against):
        print(f"  {path}")
    for line in pair_lines(finished, args.wins_against):
        print(line)
    line = machines_line(finished)
    if line:
        print(line)
    return 0


def machines_line(runs: list[dict[str, Any]]) -> str | None:
    """A warning when ``runs`` were made on more than one machine (their ``machine`` ids differ); else None."""
    from dynactivegs.eval.tables import machines

    ids = machines(runs)
    if len(ids) < 2:
        return None
    each = ", ".join(f"{n} on {mid}" for mid, n in sorted(ids.items(), key=lambda t: -t[1]))
    return (f"dagsbench: warning: these runs come from {len(ids)} machines ({each}); runs do not repeat across "
            f"machines, so compare presets on the runs of one machine (wins.md counts the mixed pairs)")


def pair_lines(runs: list[dict[str, Any]], reference: str = "baseline") -> list[str]:
    """One line per method: the (scene, seed) pairs where it beats ``reference`` on Acc, C.R. and PSNR, with the
    exact 95 % interval of that share."""
    from dynactivegs.eval.tables import PAIR_METRICS, short_label, win_counts, win_share_interval

    lines = []
    for m, (n_all, each, n) in win_counts(runs, reference).items():
        per_metric = ", ".join(f"{short_label(k)} {c}" for k, c in zip(PAIR_METRICS, each))
        lo, hi = win_share_interval(n_all, n)
        lines.append(f"dagsbench: {m} beats {reference} on all of Acc, C.R. and PSNR in {n_all} of {n} "
                     f"(scene, seed) pairs, 95 % CI {lo:.0f}-{hi:.0f} % ({per_metric}; wins.md)")
    return lines


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return run(args)
    except DagsError as e:
        print(f"dagsbench: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
