"""The short report ``dagsrun`` prints at the end of a run: timing, the map's metrics, what was written."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dynactivegs.config import DagsConfig
from dynactivegs.errors import DagsError


def evaluate_map(cfg: DagsConfig, res: Any) -> Any | None:
    """Acc / Comp / C.R. / PSNR of the final map against the scene (:mod:`dynactivegs.eval`), or None if unavailable."""
    try:
        from dynactivegs.eval.config import EvalConfig
        from dynactivegs.eval.metrics import SceneEvaluator
    except ImportError:
        return None
    ev = SceneEvaluator(cfg.sim, EvalConfig())
    try:
        return ev.evaluate(res.states[1].gaussians, step=res.steps - 1, trajectory_xy_m=res.trajectory_xy_m)
    except DagsError:
        raise
    except (ValueError, RuntimeError) as e:       # e.g. an empty map: report the run's own numbers instead
        print(f"map metrics not available: {str(e).splitlines()[0]}")
        return None


def print_summary(cfg: DagsConfig, res: Any, metrics: Any | None, summary_path: Path) -> None:
    m = res.last_metrics
    stop = f" (stopped by Ctrl-C after {res.steps} of {res.requested})" if res.interrupted else ""
    print(f"{cfg.sim.scene}: {res.steps} steps{stop} in {res.seconds:.1f} s ({res.seconds_per_step:.3f} s/step), "
          f"{int(m.get('n_gaussians', 0))} Gaussians, {m.get('known_area_m2', 0.0):.1f} m^2 of floor known, "
          f"{res.collisions} blocked move{'' if res.collisions == 1 else 's'}")
    if metrics is not None:
        which = (f"after {res.refine_iters} refinement steps, {res.refine_seconds:.1f} s" if res.refine_iters
                 else "as the last step left it")
        print(f"map ({which}): Acc {metrics.acc_cm:.2f} cm, Comp {metrics.comp_cm:.2f} cm, C.R. {metrics.cr_pct:.1f} % "
              f"(<{metrics.cr_threshold_cm:g} cm), PSNR {metrics.psnr_db:.2f} dB on {metrics.n_views} held-out views")
    if res.log_path is not None:
        print(f"log:     {res.log_path} ({res.log_bytes / 1e6:.1f} MB, {res.log_bytes / max(res.steps, 1) / 1e3:.0f} "
              f"kB/step); replay: dagsreplay {res.log_path} --from-stage planning")
    if res.rrd_path is not None:
        print(f"rerun:   {res.rrd_path}; view: rerun {res.rrd_path}")
    print(f"summary: {summary_path}")
