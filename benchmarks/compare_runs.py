"""The same runs made twice (two machines, two installs): how far apart their metrics and pair outcomes are.

    python benchmarks/compare_runs.py RESULTS_A RESULTS_B [--reference baseline] [--png both.png]

A run is a (preset, scene, seed) with its config (a preset with ``--set`` overrides counts as a preset of its
own); ``dagsbench`` writes one metrics file per run under ``runs/<preset>/``. This reads every metrics file
under each folder (``runs/`` at any depth, so a results folder with preset subfolders works too), keeps the
runs found in both with the same steps and config, and prints two Markdown tables:

- **runs**: per run, Acc cm / C.R. % / PSNR dB (refined, 100 % of the budget) in A and in B, B - A, and
  whether the two were made on one machine (the metrics files' ``machine`` ids; "?" where a file predates
  them). On one machine a run repeats bit for bit, so a difference there means the code or config changed;
  across machines the closed loop goes its own way from a last-bit difference in a float reduction, and the
  difference is a draw of the loop's spread.
- **pairs**: per method and (scene, seed) pair with ``--reference`` in both folders, the metrics it beats the
  reference on in A and in B (as ``wins.md`` counts them), and whether the outcome "beats it on all three"
  is the same; a last line per method gives the pairs won in A and in B and how many outcomes agree.

With ``--png`` it draws B against A per metric (one point per run, coloured by preset, the line y = x).
With ``--ignore-set`` a run's ``--set`` overrides are left out of its label, so a run made with an override that
is the default now matches one made without it (their configs must still agree; a folder holding one preset's run
with two configs is then refused).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dynactivegs.errors import DagsError  # noqa: E402
from dynactivegs.eval.tables import (  # noqa: E402
    METRIC_BY_KEY, PAIR_METRICS, PRESET_ORDER, _ordered, _wins, machine_id_of, short_label,
)
from recorder.bench import config_difference  # noqa: E402

Key = tuple[str, str, int]                          # (preset and its overrides, scene, seed)


def label(run: dict[str, Any], ignore_set: bool = False) -> str:
    """The run's preset, with its ``--set`` overrides if any (variants of one preset kept apart) unless
    ``ignore_set``."""
    return " ".join([str(run["preset"]), *([] if ignore_set else map(str, run.get("overrides") or ()))])


def load_folder(folder: Path, ignore_set: bool = False) -> dict[Key, dict[str, Any]]:
    """Every metrics file under ``folder``'s ``runs`` folders, by (preset, scene, seed); two files of one run
    (the same run copied into two subfolders) must agree, in their config too with ``ignore_set``."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DagsError(f"{folder}: no such results folder; give a dagsbench --out folder")
    out: dict[Key, dict[str, Any]] = {}
    for p in sorted(folder.rglob("runs/**/*.json")):
        try:
            r = json.loads(p.read_text())
            key = (label(r, ignore_set), str(r["scene"]), int(r["seed"]))
            vals = _values(r)
        except (json.JSONDecodeError, KeyError, IndexError, TypeError, ValueError, AttributeError):
            raise DagsError(f"{p}: not a dagsbench metrics file (or a truncated one); remove it or re-run it") from None
        if key in out and (_values(out[key]) != vals or (ignore_set and config_difference(
                out[key].get("config") or {}, r.get("config") or {}))):
            raise DagsError(f"{folder}: two metrics files of {key} differ; keep one"
                            + (" or give a folder holding one config of it" if ignore_set else ""))
        out[key] = r
    if not out:
        raise DagsError(f"{folder}: no metrics files under a runs/ folder; give a dagsbench --out folder")
    return out


def _values(run: dict[str, Any]) -> tuple[float | None, ...]:
    last = run["checkpoints"][-1]
    return tuple(last.get(k) for k in PAIR_METRICS)


def common_runs(a: dict[Key, dict[str, Any]], b: dict[Key, dict[str, Any]]
                ) -> tuple[list[Key], list[Key]]:
    """(runs in both with the same steps and config (:func:`config_difference`), ordered by preset, seed, scene;
    runs in both that differ in steps or config)."""
    both = [k for k in a if k in b]
    same = [k for k in both if a[k]["steps"] == b[k]["steps"]
            and not config_difference(a[k].get("config") or {}, b[k].get("config") or {})]
    other = [k for k in both if k not in same]
    presets = _ordered((k[0] for k in same), PRESET_ORDER)
    same.sort(key=lambda k: (presets.index(k[0]), k[2], k[1]))
    return same, sorted(other)


def _fmt(vals: tuple[float | None, ...]) -> str:
    return " / ".join("n/a" if v is None else f"{v:.{METRIC_BY_KEY[k].digits}f}" for k, v in zip(PAIR_METRICS, vals))


def _diff(va: tuple[float | None, ...], vb: tuple[float | None, ...]) -> str:
    return " / ".join("n/a" if x is None or y is None else f"{y - x:+.{METRIC_BY_KEY[k].digits}f}"
                      for k, x, y in zip(PAIR_METRICS, va, vb))


def runs_table(a: dict[Key, dict[str, Any]], b: dict[Key, dict[str, Any]], keys: list[Key]) -> list[str]:
    """The runs table's Markdown lines, then one line of mean |B - A| per metric."""
    head = " / ".join(short_label(k) for k in PAIR_METRICS)
    lines = [f"| preset | scene | seed | A: {head} | B: {head} | B - A | one machine |",
             "|---|---|---|---|---|---|---|"]
    for k in keys:
        ma, mb = machine_id_of(a[k]), machine_id_of(b[k])
        same = "?" if ma is None or mb is None else ("yes" if ma == mb else "no")
        lines.append(f"| {k[0]} | {k[1]} | {k[2]} | {_fmt(_values(a[k]))} | {_fmt(_values(b[k]))} | "
                     f"{_diff(_values(a[k]), _values(b[k]))} | {same} |")
    d = np.array([[np.nan if x is None or y is None else abs(y - x) for x, y in zip(_values(a[k]), _values(b[k]))]
                  for k in keys], dtype=np.float64).reshape(-1, len(PAIR_METRICS))
    mean = " / ".join(f"{np.nanmean(d[:, i]):.{METRIC_BY_KEY[m].digits}f}" if np.isfinite(d[:, i]).any() else "n/a"
                      for i, m in enumerate(PAIR_METRICS))
    lines.append("")
    lines.append(f"Mean |B - A| over {len(keys)} runs ({head}): {mean}")
    return lines


def pair_outcomes(a: dict[Key, dict[str, Any]], b: dict[Key, dict[str, Any]], keys: list[Key], reference: str
                  ) -> dict[str, list[tuple[str, int, list[bool], list[bool]]]]:
    """Per method: (scene, seed, its wins over ``reference`` per metric in A, in B) for the pairs where the
    method and the reference are both in ``keys``."""
    specs = [METRIC_BY_KEY[k] for k in PAIR_METRICS]
    have = set(keys)
    out: dict[str, list[tuple[str, int, list[bool], list[bool]]]] = {}
    for k in keys:
        p, s, seed = k
        ref = (reference, s, seed)
        if p == reference or ref not in have:
            continue
        out.setdefault(p, []).append((s, seed, _wins(list(_values(a[k])), list(_values(a[ref])), specs),
                                      _wins(list(_values(b[k])), list(_values(b[ref])), specs)))
    return out


def _won(w: list[bool]) -> str:
    return "all" if all(w) else (", ".join(short_label(k) for k, x in zip(PAIR_METRICS, w) if x) or "none")


def pairs_lines(outcomes: dict[str, list[tuple[str, int, list[bool], list[bool]]]], reference: str) -> list[str]:
    lines = [f"| method | scene | seed | beats {reference} on, A | on, B | same outcome |", "|---|---|---|---|---|---|"]
    summary = []
    for m, rows in outcomes.items():
        for s, seed, wa, wb in rows:
            lines.append(f"| {m} | {s} | {seed} | {_won(wa)} | {_won(wb)} | {'yes' if all(wa) == all(wb) else 'no'} |")
        n_a, n_b = sum(all(wa) for *_, wa, _ in rows), sum(all(wb) for *_, wb in rows)
        agree = sum(all(wa) == all(wb) for *_, wa, wb in rows)
        per = ", ".join(f"{short_label(key)} {sum(wa[i] == wb[i] for *_, wa, wb in rows)}"
                        for i, key in enumerate(PAIR_METRICS))
        summary.append(f"{m}: beats {reference} on all three in {n_a} of {len(rows)} pairs in A, {n_b} in B; the "
                       f"outcome agrees in {agree} of {len(rows)} (per metric: {per})")
    return lines + [""] + summary


def plot(a: dict[Key, dict[str, Any]], b: dict[Key, dict[str, Any]], keys: list[Key], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    presets = _ordered((k[0] for k in keys), PRESET_ORDER)
    fig, axes = plt.subplots(1, len(PAIR_METRICS), figsize=(4.2 * len(PAIR_METRICS), 4.0))
    for i, (ax, key) in enumerate(zip(axes, PAIR_METRICS)):
        pts = []
        for j, p in enumerate(presets):
            xy = np.array([(_values(a[k])[i], _values(b[k])[i]) for k in keys if k[0] == p
                           and None not in (_values(a[k])[i], _values(b[k])[i])], dtype=np.float64).reshape(-1, 2)
            ax.scatter(xy[:, 0], xy[:, 1], s=28, color=f"C{j}", label=p)
            pts.append(xy)
        allp = np.concatenate(pts)
        if len(allp):
            lo, hi = float(allp.min()), float(allp.max())
            pad = 0.05 * (hi - lo or 1.0)
            ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.6", lw=1, zorder=0)
        label = METRIC_BY_KEY[key].label
        ax.set_xlabel(f"A: {label}")
        ax.set_ylabel(f"B: {label}")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("The same runs twice (one point per preset, scene, seed; y = x: the same value)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", type=Path, help="a dagsbench results folder")
    ap.add_argument("b", type=Path, help="another one holding some of the same runs")
    ap.add_argument("--reference", default="baseline", help="the preset the others are put against pair by pair")
    ap.add_argument("--png", type=Path, default=None, help="draw B against A per metric into this PNG")
    ap.add_argument("--ignore-set", action="store_true",
                    help="match runs by preset, scene, seed and config, not by their --set overrides")
    args = ap.parse_args(argv)
    try:
        a, b = load_folder(args.a, args.ignore_set), load_folder(args.b, args.ignore_set)
        keys, other = common_runs(a, b)
        if not keys:
            raise DagsError(f"{args.a} and {args.b} hold no run in common (same preset, scene, seed, steps and "
                            f"config)")
    except DagsError as e:
        print(f"compare_runs: error: {e}", file=sys.stderr)
        return 2
    print(f"A: {args.a}\nB: {args.b}\n")
    print("\n".join(runs_table(a, b, keys)))
    if other:
        left = ", ".join(f"{p} {s} seed {k}" for p, s, k in other)
        print(f"\nLeft out, in both but with other steps or config: {left}")
    outcomes = pair_outcomes(a, b, keys, args.reference)
    if outcomes:
        print()
        print("\n".join(pairs_lines(outcomes, args.reference)))
    if args.png is not None:
        print(f"\n{plot(a, b, keys, args.png)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
