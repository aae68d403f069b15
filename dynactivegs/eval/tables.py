"""Benchmark tables (Markdown + CSV) and progress plots (PNG) from per-run metrics.

Pure functions of the runs' metrics dicts as ``dagsbench`` writes them (one per run)::

    {"preset": "full", "scene": "apartment-00", "seed": 0, "steps": 300,
     "config": {...DagsConfig as JSON...},
     "checkpoints": [{"fraction": 0.25, "step": 75, "acc_cm": ..., "comp_cm": ..., "cr_pct": ...,
                      "psnr_db": ..., "ssim": ..., "depth_l1_cm": ..., "lpips": None, ...}, ...],
     "coverage": [[step, percent], ...]}

Aggregation: a cell is the mean +- sample standard deviation over seeds (std shown only
with two or more seeds). A "Mean" column averages each seed's values over the scenes
first, then gives mean +- std over seeds. "Best" compares the means of a column (lowest
for Acc, Comp, depth L1, LPIPS; highest for C.R., PSNR, SSIM, Obs.); ties are all best. Obs. (%) is the
surface the path let the camera see (:class:`dynactivegs.eval.progress.ObservedSurface`), what the map had
to be built from; Obs. views (%) the same weighed as the held-out views see the surface (the share of their
pixels showing surface the camera saw: what PSNR can reach). Runs measured before they existed show "n/a"
until ``dagsbench --reevaluate``.

The ablation tables follow the paper's Tables 3-5. Their rows are chosen by what a run's
config switches on (weighted mapping, selection variant, planner variant), not by preset
name, so e.g. ``motion_view`` and ``plan_shortest`` (the same config) fill the same row.

The pairs table puts each method against ``baseline`` run against run: on which of Acc, C.R. and PSNR it is
better in each (scene, seed) pair, how many pairs it wins on all three (with the exact binomial 95 % interval of
that share), the two-sided sign test per metric, and the paired mean differences.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np


@dataclass(frozen=True)
class MetricSpec:
    key: str              # field of a checkpoint in the run's metrics
    label: str
    higher_is_better: bool
    digits: int


METRICS: tuple[MetricSpec, ...] = (
    MetricSpec("acc_cm", "Acc (cm)", False, 2),
    MetricSpec("comp_cm", "Comp (cm)", False, 2),
    MetricSpec("cr_pct", "C.R. (%)", True, 1),
    MetricSpec("psnr_db", "PSNR (dB)", True, 2),
    MetricSpec("ssim", "SSIM", True, 3),
    MetricSpec("lpips", "LPIPS", False, 3),
    MetricSpec("depth_l1_cm", "Depth L1 (cm)", False, 2),
    MetricSpec("observed_pct", "Obs. (%)", True, 1),      # of the path, not the map: progress.ObservedSurface
    MetricSpec("observed_view_pct", "Obs. views (%)", True, 1),   # ... weighed as the held-out views see it
)
METRIC_BY_KEY = {m.key: m for m in METRICS}
FRACTIONS = (0.25, 0.5, 0.75, 1.0)


@dataclass(frozen=True)
class Cell:
    """mean +- std over ``n`` seeds (``mean`` None: not available, e.g. LPIPS without weights)."""

    mean: float | None
    std: float
    n: int

    def text(self, digits: int) -> str:
        if self.mean is None:
            return "n/a"
        return f"{self.mean:.{digits}f}" + (f" ± {self.std:.{digits}f}" if self.n >= 2 else "")


@dataclass(frozen=True)
class Table:
    """A table with a title; ``best[i][j]`` marks cells to set in bold; ``cells`` hold the numbers for CSV."""

    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    best: tuple[tuple[bool, ...], ...]
    records: tuple[dict[str, Any], ...]         # one per numeric cell: the CSV rows
    note: str = ""
    n_lead: int = 1                             # leading text columns (left-aligned)


def _checkpoint(run: dict[str, Any], fraction: float) -> dict[str, Any]:
    for c in run["checkpoints"]:
        if math.isclose(c["fraction"], fraction):
            return c
    raise KeyError(f"run {run['preset']}/{run['scene']}/seed{run['seed']} has no checkpoint at {fraction:g}")


def _value(run: dict[str, Any], key: str, fraction: float) -> float | None:
    v = _checkpoint(run, fraction).get(key)
    return None if v is None else float(v)


def mean_std(values: Sequence[float]) -> Cell:
    """Mean and sample standard deviation (ddof 1; 0 for a single value)."""
    a = np.asarray(values, dtype=np.float64)
    if a.size == 0:
        return Cell(None, 0.0, 0)
    return Cell(float(a.mean()), float(a.std(ddof=1)) if a.size >= 2 else 0.0, int(a.size))


def cell(runs: Iterable[dict[str, Any]], key: str, fraction: float = 1.0) -> Cell:
    """Mean +- std over the seeds of ``runs`` (one scene), of metric ``key`` at ``fraction`` of the budget."""
    vals = [_value(r, key, fraction) for r in runs]
    if any(v is None for v in vals):
        return Cell(None, 0.0, len(vals))
    return mean_std(vals)


def mean_cell(runs: Iterable[dict[str, Any]], key: str, fraction: float = 1.0) -> Cell:
    """Over scenes and seeds: each seed's mean over its scenes, then mean +- std over seeds."""
    by_seed: dict[int, list[float | None]] = {}
    for r in runs:
        by_seed.setdefault(r["seed"], []).append(_value(r, key, fraction))
    if not by_seed or any(v is None for vs in by_seed.values() for v in vs):
        return Cell(None, 0.0, len(by_seed))
    return mean_std([float(np.mean(vs)) for vs in by_seed.values()])   # type: ignore[arg-type]


def _best_flags(cells: Sequence[Cell], higher: bool, digits: int) -> list[bool]:
    """Best by the means as printed (rounded to ``digits``), so that equal-looking cells are all bold."""
    means = [None if c.mean is None else round(c.mean, digits) for c in cells]
    valid = [m for m in means if m is not None]
    if len(valid) < 2:
        return [False] * len(cells)
    target = max(valid) if higher else min(valid)
    return [m is not None and m == target for m in means]


def _ordered(values: Iterable[str], order: Sequence[str] = ()) -> list[str]:
    vs = list(dict.fromkeys(values))
    return [v for v in order if v in vs] + sorted(v for v in vs if v not in order)


def _dedupe(runs: Iterable[dict[str, Any]], key: Any) -> list[dict[str, Any]]:
    """One run per (key(run), scene, seed): the first, so identical configs under two names count once."""
    seen: set[Any] = set()
    out = []
    for r in runs:
        k = (key(r), r["scene"], r["seed"])
        if k not in seen:
            seen.add(k)
            out.append(r)
    return out


# ---------------------------------------------------------------------------------------- main table
PRESET_ORDER = ("frontier", "baseline", "weighted", "motion_view", "full")


def main_table(runs: Sequence[dict[str, Any]], metrics: Sequence[str] = ("acc_cm", "comp_cm", "cr_pct", "psnr_db",
               "ssim", "lpips", "depth_l1_cm", "observed_pct", "observed_view_pct"), fraction: float = 1.0) -> Table:
    """Rows = method x metric, columns = scenes + Mean; the best method per (metric, column) in bold."""
    methods = _ordered((r["preset"] for r in runs), PRESET_ORDER)
    scenes = _ordered(r["scene"] for r in runs)
    header = ("Method", "Metric", *scenes, "Mean")
    rows, best, records = [], [], []
    for key in metrics:
        spec = METRIC_BY_KEY[key]
        grid = []                                   # [method][column] -> Cell
        for m in methods:
            mr = [r for r in runs if r["preset"] == m]
            grid.append([cell([r for r in mr if r["scene"] == s], key, fraction) for s in scenes]
                        + [mean_cell(mr, key, fraction)])
        flags = [_best_flags([grid[i][j] for i in range(len(methods))], spec.higher_is_better, spec.digits)
                 for j in range(len(scenes) + 1)]
        for i, m in enumerate(methods):
            rows.append((m, spec.label, *(c.text(spec.digits) for c in grid[i])))
            best.append((False, False, *(flags[j][i] for j in range(len(scenes) + 1))))
            for j, col in enumerate((*scenes, "mean")):
                c = grid[i][j]
                records.append({"method": m, "metric": key, "scene": col, "mean": c.mean, "std": c.std,
                                "n_seeds": c.n, "best": flags[j][i]})
    n_seeds = len({r["seed"] for r in runs})
    steps = sorted({r["steps"] for r in runs})
    refined = sorted({_checkpoint(r, fraction).get("refine_iters", 0) > 0 for r in runs})
    which = {(True,): "; the map after the offline refinement",
             (False, True): "; refined maps and unrefined ones (runs without refinement)"}.get(tuple(refined), "")
    note = (f"{len(runs)} runs; {n_seeds} seed(s); metrics at {fraction:.0%} of a budget of "
            f"{'/'.join(map(str, steps))} steps{which}; mean ± std over seeds; best in bold.")
    return Table(f"Main results ({fraction:.0%} of the budget)", header, tuple(rows), tuple(best), tuple(records), note,
                 n_lead=2)


# ---------------------------------------------------------------------------------------- ablations
def switches(run: dict[str, Any]) -> tuple[bool, str, str]:
    """(weighted mapping, selection variant, planner variant) of a run's config."""
    c = run["config"]
    return bool(c["mapping"]["weighted"]), str(c["selection"]["variant"]), str(c["planning"]["path"]["variant"])


COMPONENT_ROWS: tuple[tuple[str, tuple[bool, str, str]], ...] = (
    ("baseline", (False, "gain_cost", "shortest")),
    ("weighted", (True, "gain_cost", "shortest")),
    ("motion_view", (True, "full", "shortest")),
    ("full", (True, "full", "dyn_edge_temporal")),
)
SELECTION_ROWS: tuple[tuple[str, tuple[bool, str, str]], ...] = (
    ("random", (True, "random", "dyn_edge_temporal")),
    ("static gain", (True, "static_gain", "dyn_edge_temporal")),
    ("gain + cost", (True, "gain_cost", "dyn_edge_temporal")),
    ("full (motion-aware)", (True, "full", "dyn_edge_temporal")),
)
PLANNER_ROWS: tuple[tuple[str, tuple[bool, str, str]], ...] = (
    ("shortest", (True, "full", "shortest")),
    ("dyn_edge", (True, "full", "dyn_edge")),
    ("dyn_edge_temporal (full)", (True, "full", "dyn_edge_temporal")),
)
ABLATION_METRICS = ("acc_cm", "comp_cm", "cr_pct", "psnr_db", "ssim", "depth_l1_cm", "observed_pct",
                    "observed_view_pct")
PLANNER_METRICS = ("cr_pct", "acc_cm", "psnr_db")


def _ablation(title: str, rows_def: Sequence[tuple[str, tuple[bool, str, str]]], runs: Sequence[dict[str, Any]],
              columns: Sequence[tuple[str, str, float]], lead: tuple[str, ...], lead_of: Any) -> Table | None:
    """Rows present in ``runs`` (by switches); ``columns`` = (header, metric key, fraction); None if < 2 rows."""
    runs = _dedupe(runs, switches)
    present = [(label, sw) for label, sw in rows_def if any(switches(r) == sw for r in runs)]
    if len(present) < 2:
        return None
    grid = [[mean_cell([r for r in runs if switches(r) == sw], key, frac) for _, key, frac in columns]
            for _, sw in present]
    flags = [_best_flags([grid[i][j] for i in range(len(present))], METRIC_BY_KEY[key].higher_is_better,
                         METRIC_BY_KEY[key].digits)
             for j, (_, key, _) in enumerate(columns)]
    rows, best, records = [], [], []
    for i, (label, sw) in enumerate(present):
        rows.append((label, *lead_of(sw), *(grid[i][j].text(METRIC_BY_KEY[key].digits)
                                            for j, (_, key, _) in enumerate(columns))))
        best.append((False,) * (1 + len(lead)) + tuple(flags[j][i] for j in range(len(columns))))
        for j, (_, key, frac) in enumerate(columns):
            c = grid[i][j]
            records.append({"row": label, "metric": key, "fraction": frac, "mean": c.mean, "std": c.std,
                            "n_seeds": c.n, "best": flags[j][i]})
    scenes = sorted({r["scene"] for r in runs if any(switches(r) == sw for _, sw in present)})
    note = f"Mean over scenes ({', '.join(scenes)}), then mean ± std over seeds; best in bold."
    header = ("Variant", *lead, *(h for h, _, _ in columns))
    return Table(title, header, tuple(rows), tuple(best), tuple(records), note, n_lead=1 + len(lead))


def _tick(flag: bool) -> str:
    return "✓" if flag else "✗"


def components_table(runs: Sequence[dict[str, Any]], fraction: float = 1.0) -> Table | None:
    """The paper's Table 3: which of weighted mapping / motion-aware view / motion-aware planning is on."""
    cols = [(METRIC_BY_KEY[k].label, k, fraction) for k in ABLATION_METRICS]
    return _ablation("Ablation: components (Table 3 layout)", COMPONENT_ROWS, runs, cols,
                     ("Weighted mapping", "Motion-aware view", "Motion-aware planning"),
                     lambda sw: (_tick(sw[0]), _tick(sw[1] == "full"), _tick(sw[2] != "shortest")))


def selection_table(runs: Sequence[dict[str, Any]], fraction: float = 1.0) -> Table | None:
    """The paper's Table 4: view-selection variants (weighted mapping, dyn_edge_temporal planner)."""
    cols = [(METRIC_BY_KEY[k].label, k, fraction) for k in ABLATION_METRICS]
    return _ablation("Ablation: view selection (Table 4 layout)", SELECTION_ROWS, runs, cols, (), lambda sw: ())


def planner_table(runs: Sequence[dict[str, Any]]) -> Table | None:
    """The paper's Table 5: planner variants, metrics at 25/50/75/100 % path ratio (fraction of the budget)."""
    cols = [(f"{METRIC_BY_KEY[k].label} @{f:.0%}", k, f) for k in PLANNER_METRICS for f in FRACTIONS]
    return _ablation("Ablation: planner (Table 5 layout)", PLANNER_ROWS, runs, cols, (), lambda sw: ())


# ---------------------------------------------------------------------------------------- pairs
PAIR_METRICS = ("acc_cm", "cr_pct", "psnr_db")


def short_label(key: str) -> str:
    """A metric's label without its unit: "Acc", "C.R.", "PSNR", "Obs. views"."""
    return METRIC_BY_KEY[key].label.split(" (")[0]


def _beats(value: float | None, ref: float | None, higher: bool) -> bool:
    """Strictly better at full precision (a tie is no win); a missing value never wins."""
    if value is None or ref is None:
        return False
    return value > ref if higher else value < ref


def _wins(vals: Sequence[float | None], refs: Sequence[float | None], specs: Sequence[MetricSpec]) -> list[bool]:
    """Per metric: whether ``vals`` beat ``refs`` on it (:func:`_beats`)."""
    return [_beats(v, r, spec.higher_is_better) for v, r, spec in zip(vals, refs, specs)]


def _signed(values: np.ndarray, digits: int) -> str:
    """Mean with its sign, +- the sample std from two values on; "n/a" for none."""
    c = mean_std(values)
    if c.mean is None:
        return "n/a"
    return f"{c.mean:+.{digits}f}" + (f" ± {c.std:.{digits}f}" if c.n >= 2 else "")


Pair = tuple[str, int]                              # (scene, seed)


def paired(runs: Sequence[dict[str, Any]], reference: str = "baseline", metrics: Sequence[str] = PAIR_METRICS,
           fraction: float = 1.0) -> dict[str, dict[Pair, tuple[list[float | None], list[float | None]]]]:
    """Per method other than ``reference`` (in table order), per (scene, seed) pair that both ran (ordered by
    seed, then scene): (its values of ``metrics``, the reference's) at ``fraction`` of the budget. Methods with
    no pair in common are left out; empty without the reference."""
    runs = _dedupe(runs, lambda r: r["preset"])
    by = {(r["preset"], r["scene"], r["seed"]): r for r in runs}
    pairs = sorted({(s, k) for p, s, k in by if p == reference}, key=lambda t: (t[1], t[0]))
    out: dict[str, dict[Pair, tuple[list[float | None], list[float | None]]]] = {}
    for m in _ordered((r["preset"] for r in runs), PRESET_ORDER):
        if m == reference:
            continue
        got = {(s, k): ([_value(by[(m, s, k)], key, fraction) for key in metrics],
                        [_value(by[(reference, s, k)], key, fraction) for key in metrics])
               for s, k in pairs if (m, s, k) in by}
        if got:
            out[m] = got
    return out


def win_counts(runs: Sequence[dict[str, Any]], reference: str = "baseline", metrics: Sequence[str] = PAIR_METRICS,
               fraction: float = 1.0) -> dict[str, tuple[int, tuple[int, ...], int]]:
    """Per method of :func:`paired`: (pairs won on every metric, pairs won on each metric, pairs)."""
    return _counts(paired(runs, reference, metrics, fraction), [METRIC_BY_KEY[k] for k in metrics])


def _counts(per: dict[str, dict[Pair, tuple[list[float | None], list[float | None]]]],
            specs: Sequence[MetricSpec]) -> dict[str, tuple[int, tuple[int, ...], int]]:
    out = {}
    for m, got in per.items():
        ws = [_wins(vals, refs, specs) for vals, refs in got.values()]
        out[m] = (sum(all(w) for w in ws), tuple(sum(w[i] for w in ws) for i in range(len(specs))), len(ws))
    return out


def win_share_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """The exact (Clopper-Pearson) ``level`` interval of the share of pairs won, k of n, in percent.

    Pairs of one benchmark are taken as independent draws; the interval says which true shares of pairs won
    are consistent with k of n (e.g. 4 of 12: 10-65 %)."""
    from scipy.stats import binomtest

    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"win_share_interval needs 0 <= k <= n and n > 0, got k={k}, n={n}")
    ci = binomtest(k, n).proportion_ci(confidence_level=level, method="exact")
    return 100.0 * float(ci.low), 100.0 * float(ci.high)


def sign_test_p(wins: int, losses: int) -> float | None:
    """Two-sided sign test: the chance of a split at least as uneven as wins : losses if each pair were a fair
    coin (ties and missing values are left out before). None without a decided pair."""
    from scipy.stats import binomtest

    if wins + losses == 0:
        return None
    return float(binomtest(wins, wins + losses, 0.5).pvalue)


def _losses(per_method: dict[Pair, tuple[list[float | None], list[float | None]]],
            specs: Sequence[MetricSpec]) -> tuple[int, ...]:
    """Per metric: the pairs where the reference is strictly better (the method's wins with the roles swapped)."""
    swapped = {pair: (refs, vals) for pair, (vals, refs) in per_method.items()}
    return _counts({"": swapped}, specs)[""][1]


def machine_id_of(run: dict[str, Any]) -> str | None:
    """The id of the machine a run was made on (the ``machine`` entry ``dagsbench`` records); None for a run made
    before the entry existed."""
    return (run.get("machine") or {}).get("id")


def machines(runs: Iterable[dict[str, Any]]) -> dict[str, int]:
    """Runs per machine id (:func:`machine_id_of`; runs without one are left out)."""
    out: dict[str, int] = {}
    for r in runs:
        mid = machine_id_of(r)
        if mid:
            out[mid] = out.get(mid, 0) + 1
    return out


def cross_machine_pairs(runs: Sequence[dict[str, Any]], reference: str = "baseline") -> tuple[int, int]:
    """(comparisons of :func:`paired` whose two runs carry different machine ids, all its comparisons)."""
    runs = _dedupe(runs, lambda r: r["preset"])
    by = {(r["preset"], r["scene"], r["seed"]): machine_id_of(r) for r in runs}
    per = paired(runs, reference, PAIR_METRICS[:1])
    mixed = sum(1 for m, got in per.items() for s, k in got
                if by[(m, s, k)] and by[(reference, s, k)] and by[(m, s, k)] != by[(reference, s, k)])
    return mixed, sum(len(got) for got in per.values())


def standardised_effects(diffs: np.ndarray, specs: Sequence[MetricSpec]) -> list[float | None]:
    """Per metric, the paired mean difference over its sample std (method - reference, from two pairs on), signed
    so that positive means the method is better; None with fewer than two pairs or no spread.

    Were a metric's pair differences normal with this mean and spread, the method would win it in Phi(z) of the
    pairs (z 1.0: 84 %, 1.5: 93 %)."""
    out: list[float | None] = []
    for i, spec in enumerate(specs):
        c = mean_std(diffs[:, i])
        if c.n < 2 or c.std <= 0.0:
            out.append(None)
            continue
        z = c.mean / c.std if spec.higher_is_better else -c.mean / c.std
        out.append(z + 0.0)                         # + 0.0: a zero mean reads +0.00, not -0.00
    return out


def normal_share_on_all(effects: Sequence[float | None]) -> float | None:
    """The share of pairs won on every metric (percent) that :func:`standardised_effects` imply if the metrics'
    pair differences were normal and independent: the product of Phi(z) over the metrics; None if any is None."""
    from scipy.stats import norm

    if any(z is None for z in effects):
        return None
    return 100.0 * float(np.prod([norm.cdf(z) for z in effects]))


def correlated_normal_share_on_all(diffs: np.ndarray, specs: Sequence[MetricSpec], points: int = 2 ** 16
                                   ) -> float | None:
    """The share of pairs won on every metric (percent) if the pair differences ``diffs`` (pairs x metrics,
    method - reference) were jointly normal with their sample means, stds and correlations; None with fewer than
    two pairs or a metric without spread. Unlike :func:`normal_share_on_all` it keeps how a pair's metrics move
    together (a run whose path showed more is usually better on all of them), which raises the share won on all
    towards that of the least-won metric. Computed by deterministic quasi-Monte Carlo (``points`` unscrambled
    Sobol points, no random numbers): a guide like the independent model, not a measurement."""
    from scipy.stats import norm, qmc

    d = np.asarray(diffs, np.float64)
    if d.ndim != 2 or d.shape[1] != len(specs):
        return None
    effects = standardised_effects(d, specs)            # the means in SD, + better: None below two pairs or spread
    if any(z is None for z in effects):
        return None
    corr = np.atleast_2d(np.corrcoef(d * np.array([1.0 if spec.higher_is_better else -1.0 for spec in specs]),
                                     rowvar=False))   # of the differences signed as the effects are
    w, v = np.linalg.eigh(corr)                        # a square root that also holds for a singular correlation
    root = v * np.sqrt(np.clip(w, 0.0, None))
    u = qmc.Sobol(d.shape[1], scramble=False).random(points) + 0.5 / points   # off the cube's faces
    x = norm.ppf(u) @ root.T + np.array(effects)
    return 100.0 * float(np.mean(np.all(x > 0.0, axis=1)))


def _p_text(p: float | None) -> str:
    return "n/a" if p is None else (f"{p:.2g}" if p >= 0.001 else "< 0.001")


def pairs_table(runs: Sequence[dict[str, Any]], reference: str = "baseline", metrics: Sequence[str] = PAIR_METRICS,
                fraction: float = 1.0) -> Table | None:
    """Per (scene, seed) pair: which of ``metrics`` each method beats ``reference`` on, run against run.

    The closed loop spreads single runs widely, so a mean can hide that a method wins few pairs; this counts
    them. Rows: the pairs ``reference`` and at least one other method both ran, then per method the number of
    pairs won on every metric and on each, the share won on every metric with its exact 95 % interval
    (:func:`win_share_interval`), wins : losses and the sign test's p per metric (:func:`sign_test_p`), and the
    paired mean difference (method - reference) +- its sample std. A cell reads "all" (beats it on every
    metric, in bold), the short names of the metrics it beats it on, "none", or "" (no such run). None when
    ``reference`` or any other method is missing."""
    per = paired(runs, reference, metrics, fraction)
    if not per:
        return None
    methods = list(per)
    pairs = sorted({pk for got in per.values() for pk in got}, key=lambda t: (t[1], t[0]))
    specs = [METRIC_BY_KEY[k] for k in metrics]
    short = [short_label(k) for k in metrics]
    rows, best, records = [], [], []
    for s, k in pairs:
        cells, flags = [], []
        for m in methods:
            if (s, k) not in per[m]:
                cells.append("")
                flags.append(False)
                continue
            vals, refs = per[m][(s, k)]
            w = _wins(vals, refs, specs)
            cells.append("all" if all(w) else (", ".join(n for n, x in zip(short, w) if x) or "none"))
            flags.append(all(w))
            records.append({"method": m, "scene": s, "seed": k,
                            **{f"beats_{spec.key}": x for spec, x in zip(specs, w)}, "beats_all": all(w)})
        rows.append((s, str(k), *cells))
        best.append((False, False, *flags))
    counts, shares, signs, means, effects = [], [], [], [], []
    won = _counts(per, specs)
    for m in methods:
        n_all, each, n = won[m]
        counts.append(f"{n_all} / {' / '.join(map(str, each))} of {n}")
        lo, hi = win_share_interval(n_all, n)
        shares.append(f"{100.0 * n_all / n:.0f} % ({lo:.0f}-{hi:.0f} %)")
        lost = _losses(per[m], specs)
        signs.append(" / ".join(f"{w}:{l} p {_p_text(sign_test_p(w, l))}" for w, l in zip(each, lost)))
        d = [[v - r for v, r in zip(vals, refs)] for vals, refs in per[m].values()
             if all(x is not None for x in (*vals, *refs))]
        d_arr = np.asarray(d, dtype=np.float64).reshape(-1, len(specs))
        means.append(" / ".join(_signed(d_arr[:, i], spec.digits) for i, spec in enumerate(specs)))
        z = standardised_effects(d_arr, specs)
        share, joint = normal_share_on_all(z), correlated_normal_share_on_all(d_arr, specs)
        effects.append(" / ".join("n/a" if v is None else f"{v:+.2f}" for v in z)
                       + ("" if share is None or joint is None else f" ({share:.0f} %, {joint:.0f} %)"))
    rows.append(("pairs won", "all " + " / ".join(short), *counts))
    rows.append(("won on all", "share (95 % CI)", *shares))
    rows.append(("sign test", " / ".join(short), *signs))
    rows.append(("mean difference", " / ".join(short), *means))
    rows.append(("effect in SD", " / ".join(short) + " (all: independent, correlated)", *effects))
    best += [(False,) * (2 + len(methods))] * 5
    note = (f"Each method against `{reference}`, run against run on the same (scene, seed), metrics at "
            f"{fraction:.0%} of the budget; a win is a strictly better value (lower Acc, Comp, depth L1; higher "
            f"C.R., PSNR, SSIM); \"all\" (bold): better on every metric. Won on all: the share of pairs won on "
            f"every metric, with its exact binomial 95 % interval. Sign test: pairs won : lost per metric (ties "
            f"left out) and the two-sided p of so uneven a split if each pair were a coin toss. Mean difference: "
            f"method - {reference}, ± the sample std over the pairs. Effect in SD: that mean over that std, "
            f"signed so that + is better for the method; a metric whose pair differences were normal would be won "
            f"in Phi(effect) of the pairs (+1.0: 84 %, +1.5: 93 %), and in brackets the share won on all of them "
            f"that this model gives if the metrics were independent, then if they were jointly normal with the "
            f"pairs' own correlations (a pair's metrics tend to move together, which raises the share towards "
            f"that of the least-won metric); guides to how far a share like 80 % is, not measurements: the "
            f"pairs' differences are heavy-tailed where runs fail.")
    mixed, n_cmp = cross_machine_pairs(runs, reference)
    if mixed:
        note += (f" {mixed} of these {n_cmp} comparisons put runs made on different machines against each other "
                 f"(their machine ids differ): runs do not repeat across machines, so such a pair compares two "
                 f"draws of the closed loop, not the methods alone.")
    return Table(f"Pairs against {reference}", ("Scene", "Seed", *methods), tuple(rows), tuple(best),
                 tuple(records), note, n_lead=2)


# ---------------------------------------------------------------------------------------- output
def to_markdown(t: Table) -> str:
    """The table as GitHub Markdown, best cells in bold, with its title and note."""
    def fmt(text: str, bold: bool) -> str:
        return f"**{text}**" if bold else text

    lines = [f"### {t.title}", "", "| " + " | ".join(t.header) + " |",
             "|" + "|".join("---" if i < t.n_lead else "---:" for i in range(len(t.header))) + "|"]
    for row, flags in zip(t.rows, t.best):
        lines.append("| " + " | ".join(fmt(x, b) for x, b in zip(row, flags)) + " |")
    if t.note:
        lines += ["", t.note]
    return "\n".join(lines) + "\n"


def to_csv(t: Table) -> str:
    """One line per numeric cell (long format): the cell's keys, mean, std, seeds, best."""
    if not t.records:
        return ""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(t.records[0]), lineterminator="\n")
    w.writeheader()
    for r in t.records:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()


def progress_series(runs: Sequence[dict[str, Any]], key: str) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per method: (checkpoint steps, mean, std) of metric ``key`` over scenes and seeds (None values dropped)."""
    out = {}
    for m in _ordered((r["preset"] for r in runs), PRESET_ORDER):
        mr = [r for r in runs if r["preset"] == m]
        steps, means, stds = [], [], []
        for f in FRACTIONS:
            vals = [v for r in mr if (v := _value(r, key, f)) is not None]
            if vals:
                steps.append(float(np.mean([_checkpoint(r, f)["step"] for r in mr])))
                means.append(float(np.mean(vals)))
                stds.append(float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0)
        out[m] = (np.array(steps), np.array(means), np.array(stds))
    return out


def coverage_series(runs: Sequence[dict[str, Any]]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method: (steps, mean coverage %) over its runs, on the steps every run of it measured."""
    out = {}
    for m in _ordered((r["preset"] for r in runs), PRESET_ORDER):
        curves = [dict((int(s), float(c)) for s, c in r["coverage"]) for r in runs if r["preset"] == m]
        common = sorted(set.intersection(*(set(c) for c in curves))) if curves else []
        out[m] = (np.array(common, dtype=np.float64), np.array([np.mean([c[s] for c in curves]) for s in common]))
    return out


def plot_progress(runs: Sequence[dict[str, Any]], path: Path) -> Path:
    """PSNR and C.R. over steps (the checkpoints), one line per method, +- std band; saved as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key in zip(axes, ("psnr_db", "cr_pct")):
        for m, (x, y, s) in progress_series(runs, key).items():
            if len(x):
                ax.plot(x, y, marker="o", label=m)
                ax.fill_between(x, y - s, y + s, alpha=0.15)
        ax.set_xlabel("step")
        ax.set_ylabel(METRIC_BY_KEY[key].label)
        ax.grid(alpha=0.3)
    axes[0].legend()
    fig.suptitle("Progress at 25/50/75/100 % of the budget (mean over scenes and seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_coverage(runs: Sequence[dict[str, Any]], path: Path) -> Path:
    """Cheap coverage (% of probe GT points near an opaque Gaussian centre) over steps, per method; PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for m, (x, y) in coverage_series(runs).items():
        if len(x):
            ax.plot(x, y, label=m)
    ax.set_xlabel("step")
    ax.set_ylabel("coverage (%)")
    ax.set_title("Coverage by Gaussian centres (mean over scenes and seeds)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_wins(runs: Sequence[dict[str, Any]], path: Path, reference: str = "baseline") -> Path | None:
    """Per metric of the pairs table, each method's gain over ``reference`` in every (scene, seed) pair, signed
    so that up is better (lower Acc: up); filled where the method wins the pair on all of them. The axis spans
    1.5 x the 90th percentile of the gains' size, so that one run far off does not squash the rest: points past
    it sit on the edge as triangles with their value. Under each method: its pairs won on all and the exact 95 %
    interval of that share. None (nothing written) without pairs."""
    per = paired(runs, reference)
    if not per:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specs = [METRIC_BY_KEY[k] for k in PAIR_METRICS]
    ticks = []                                          # the method, its pairs won on all and that share's interval
    for m, (n_all, _, n) in _counts(per, specs).items():
        lo, hi = win_share_interval(n_all, n)
        ticks.append(f"{m}\n{n_all} of {n} ({lo:.0f}-{hi:.0f} %)")
    fig, axes = plt.subplots(1, len(specs), figsize=(4 * len(specs), 4.4))
    for i, (ax, spec) in enumerate(zip(axes, specs)):
        pts = []                                        # (x, gain, method index, won)
        for j, got in enumerate(per.values()):
            for n, (vals, refs) in enumerate(got.values()):
                if vals[i] is None or refs[i] is None:
                    continue
                won = all(_wins(vals, refs, specs))
                x = j + 0.3 * ((n * 0.618) % 1.0 - 0.5)            # spread a method's pairs across its slot
                pts.append((x, (vals[i] - refs[i]) * (1.0 if spec.higher_is_better else -1.0), j, won))
        size = np.abs([g for _, g, _, _ in pts]) if pts else np.zeros(1)
        lim = max(1.5 * float(np.percentile(size, 90)), 10.0 ** -spec.digits)
        for x, g, j, won in pts:
            off = abs(g) > lim
            y = math.copysign(lim, g) if off else g
            ax.scatter([x], [y], s=40 if off else 30, marker=("^" if g > 0 else "v") if off else "o", color=f"C{j}",
                       facecolors=f"C{j}" if won else "none", zorder=3)
            if off:
                ax.annotate(f"{g:+.{spec.digits}f}", (x, y), xytext=(4, -10 if g > 0 else 4),
                            textcoords="offset points", fontsize=7)
        ax.set_ylim(-1.1 * lim, 1.1 * lim)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xticks(range(len(per)), ticks, rotation=20, fontsize=8)
        ax.set_ylabel(f"{spec.label}: gain over {reference}")
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(f"Each (scene, seed) pair against {reference}: above 0 is better; filled: better on all three "
                 f"(under each: pairs won on all, 95 % CI)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def write_reports(runs: Sequence[dict[str, Any]], out_dir: Path, reference: str = "baseline") -> list[Path]:
    """Write every table that the runs allow (Markdown + CSV) and the plots into ``out_dir``; the paths written.
    ``reference``: the preset the others are put against pair by pair (``wins``)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not runs:
        return []
    tables = {"main": main_table(runs), "ablation_components": components_table(runs),
              "ablation_selection": selection_table(runs), "ablation_planner": planner_table(runs),
              "wins": pairs_table(runs, reference)}
    written = []
    for name, t in tables.items():
        if t is None:
            continue
        for suffix, text in ((".md", to_markdown(t)), (".csv", to_csv(t))):
            p = out_dir / f"{name}{suffix}"
            p.write_text(text)
            written.append(p)
    written.append(plot_progress(runs, out_dir / "progress.png"))
    written.append(plot_coverage(runs, out_dir / "coverage.png"))
    wins = plot_wins(runs, out_dir / "wins.png", reference)
    return written + ([wins] if wins is not None else [])
