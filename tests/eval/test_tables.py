"""Benchmark tables and plots from synthetic per-run metrics: bold on the best, mean ± std over seeds, layouts."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from dynactivegs.config import PRESETS, to_json
from dynactivegs.eval import tables
from dynactivegs.eval.tables import (components_table, main_table, pairs_table, planner_table, selection_table,
                                     to_csv, to_markdown, write_reports)
from recorder.bench import pair_lines


def fake_run(preset: str, scene: str, seed: int, *, acc: float, cr: float, psnr: float, steps: int = 100,
             lpips: float | None = None) -> dict:
    """A run's metrics dict as dagsbench writes it; metrics grow linearly to the given final values."""
    cps = []
    for f in tables.FRACTIONS:
        cps.append({"fraction": f, "step": int(f * steps), "acc_cm": acc / f, "comp_cm": 10.0 / f, "cr_pct": cr * f,
                    "psnr_db": psnr * f, "ssim": 0.5 * f, "lpips": lpips, "depth_l1_cm": 5.0 / f})
    return {"preset": preset, "scene": scene, "seed": seed, "steps": steps,
            "config": json.loads(to_json(PRESETS[preset])), "checkpoints": cps,
            "coverage": [[s, min(100.0, s * cr / steps)] for s in range(0, steps + 1, 10)]}


def runs_two_methods() -> list[dict]:
    # full: C.R. 90 / 92 / 94 on seeds 0-2 on scene a (mean 92, std 2); baseline 80 / 80 / 80
    out = []
    for k, cr in enumerate((90.0, 92.0, 94.0)):
        out.append(fake_run("full", "a", k, acc=2.0, cr=cr, psnr=25.0))
        out.append(fake_run("full", "b", k, acc=3.0, cr=cr - 10, psnr=23.0))
        out.append(fake_run("baseline", "a", k, acc=4.0, cr=80.0, psnr=20.0))
        out.append(fake_run("baseline", "b", k, acc=1.0, cr=70.0, psnr=21.0))
    return out


def row(t, method: str, label: str) -> tuple[tuple[str, ...], tuple[bool, ...]]:
    for r, b in zip(t.rows, t.best):
        if r[0] == method and r[1] == label:
            return r, b
    raise KeyError((method, label))


def test_main_table_mean_std_and_best():
    t = main_table(runs_two_methods())
    assert t.header == ("Method", "Metric", "a", "b", "Mean")
    r, b = row(t, "full", "C.R. (%)")
    assert r[2:] == ("92.0 ± 2.0", "82.0 ± 2.0", "87.0 ± 2.0")     # sample std of 90, 92, 94 is 2
    assert b[2:] == (True, True, True)
    r, b = row(t, "baseline", "C.R. (%)")
    assert r[2:] == ("80.0 ± 0.0", "70.0 ± 0.0", "75.0 ± 0.0") and b[2:] == (False, False, False)
    # Acc: lower is better; baseline wins scene b and the mean (2.5 vs 2.5 -> tie: both bold)
    _, bf = row(t, "full", "Acc (cm)")
    _, bb = row(t, "baseline", "Acc (cm)")
    assert bf[2:] == (True, False, True) and bb[2:] == (False, True, True)
    md = to_markdown(t)
    assert "| full | C.R. (%) | **92.0 ± 2.0** | **82.0 ± 2.0** | **87.0 ± 2.0** |" in md
    assert "| baseline | LPIPS | n/a | n/a | n/a |" in md                 # never a number without weights


def test_mean_column_averages_scenes_per_seed_before_the_std():
    runs = [fake_run("full", "a", 0, acc=1, cr=10.0, psnr=1), fake_run("full", "b", 0, acc=1, cr=30.0, psnr=1),
            fake_run("full", "a", 1, acc=1, cr=20.0, psnr=1), fake_run("full", "b", 1, acc=1, cr=60.0, psnr=1)]
    c = tables.mean_cell(runs, "cr_pct")
    assert c.mean == pytest.approx(30.0) and c.std == pytest.approx(np.std([20.0, 40.0], ddof=1)) and c.n == 2


def test_single_seed_prints_no_std_and_csv_holds_numbers():
    t = main_table([fake_run("full", "a", 0, acc=2.0, cr=90.0, psnr=25.0),
                    fake_run("baseline", "a", 0, acc=3.0, cr=80.0, psnr=20.0)])
    r, _ = row(t, "full", "PSNR (dB)")
    assert r[2:] == ("25.00", "25.00")
    recs = list(csv.DictReader(io.StringIO(to_csv(t))))
    full_cr = [x for x in recs if x["method"] == "full" and x["metric"] == "cr_pct" and x["scene"] == "a"]
    assert len(full_cr) == 1 and float(full_cr[0]["mean"]) == 90.0 and full_cr[0]["best"] == "True"
    lp = [x for x in recs if x["metric"] == "lpips"]
    assert all(x["mean"] == "" for x in lp)


def test_ablation_rows_follow_the_config_switches():
    runs = [fake_run(p, "a", 0, acc=1.0 + i, cr=50.0 + i, psnr=20.0 + i)
            for i, p in enumerate(("baseline", "weighted", "motion_view", "full", "frontier"))]
    t = components_table(runs)
    assert [r[0] for r in t.rows] == ["baseline", "weighted", "motion_view", "full"]     # frontier is no component
    assert [r[1:4] for r in t.rows] == [("✗", "✗", "✗"), ("✓", "✗", "✗"), ("✓", "✓", "✗"), ("✓", "✓", "✓")]
    assert t.best[3][4 + 2] and not any(b[4 + 2] for b in t.best[:3])               # C.R. best: full
    # Table 4 has a single matching row (full) -> not written; Table 5: motion_view is the "shortest" planner row
    assert selection_table(runs) is None
    p = planner_table(runs)
    assert [r[0] for r in p.rows] == ["shortest", "dyn_edge_temporal (full)"]
    assert p.header[1:5] == ("C.R. (%) @25%", "C.R. (%) @50%", "C.R. (%) @75%", "C.R. (%) @100%")
    assert p.rows[1][1:5] == ("13.2", "26.5", "39.8", "53.0")                           # C.R. at each path ratio


def test_identical_configs_under_two_names_count_once():
    runs = [fake_run("motion_view", "a", 0, acc=1, cr=50.0, psnr=20),
            fake_run("plan_shortest", "a", 0, acc=1, cr=50.0, psnr=20),
            fake_run("plan_dyn_edge", "a", 0, acc=1, cr=60.0, psnr=20)]
    p = planner_table(runs)
    assert [r[0] for r in p.rows] == ["shortest", "dyn_edge"]
    assert all(rec["n_seeds"] == 1 for rec in p.records)


def test_write_reports_writes_tables_and_pngs(tmp_path):
    paths = write_reports(runs_two_methods(), tmp_path)
    names = sorted(p.name for p in paths)
    assert names == ["ablation_components.csv", "ablation_components.md", "coverage.png", "main.csv", "main.md",
                     "progress.png", "wins.csv", "wins.md", "wins.png"]
    for p in paths:
        if p.suffix == ".png":
            assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000
    series = tables.progress_series(runs_two_methods(), "psnr_db")
    # the mean of scenes a (25 dB) and b (23 dB) at each checkpoint
    np.testing.assert_allclose(series["full"][1], [24.0 * f for f in tables.FRACTIONS])
    assert write_reports([], tmp_path / "empty") == []


def test_pairs_table_counts_wins_run_against_run():
    runs = runs_two_methods()
    # full on scene a beats baseline on all three (2 < 4 cm, 90-94 > 80 %, 25 > 20 dB); on scene b it loses Acc
    # (3 > 1 cm) and wins C.R. (80-84 > 70 %) and PSNR (23 > 21 dB)
    runs.append(fake_run("weighted", "a", 0, acc=4.0, cr=81.0, psnr=19.0))   # ties Acc: no win
    t = pairs_table(runs)
    assert t.header == ("Scene", "Seed", "weighted", "full")
    by_pair = {(r[0], r[1]): r[2:] for r in t.rows[:-5]}
    assert by_pair[("a", "0")] == ("C.R.", "all") and by_pair[("b", "0")] == ("", "C.R., PSNR")
    assert by_pair[("a", "2")] == ("", "all")
    assert [r[0] for r in t.rows[:6]] == ["a", "b", "a", "b", "a", "b"]                # ordered by seed, then scene
    won = t.rows[-5]
    assert won[:2] == ("pairs won", "all Acc / C.R. / PSNR") and won[2:] == ("0 / 0 / 1 / 0 of 1", "3 / 3 / 6 / 6 of 6")
    # exact binomial 95 % intervals: 0 of 1 is 0-97.5 %, 3 of 6 is 11.8-88.2 %
    assert t.rows[-4] == ("won on all", "share (95 % CI)", "0 % (0-98 %)", "50 % (12-88 %)")
    # wins : losses per metric; weighted ties Acc (no decided pair), full loses Acc on b, and 6 : 0 is 2 / 2^6
    assert t.rows[-3] == ("sign test", "Acc / C.R. / PSNR", "0:0 p n/a / 1:0 p 1 / 0:1 p 1",
                          "3:3 p 1 / 6:0 p 0.031 / 6:0 p 0.031")
    diff = t.rows[-2]
    # full - baseline over the 6 pairs: Acc -2 on a, +2 on b; C.R. 10 / 12 / 14 on both; PSNR 5 on a, 2 on b
    assert diff[2:] == ("+0.00 / +1.0 / -1.00", "+0.00 ± 2.19 / +12.0 ± 1.8 / +3.50 ± 1.64")
    # effect in SD, + = better: Acc 0 / 2.19, C.R. 12 / 1.79, PSNR 3.5 / 1.64; all three 0.5 x 1.0 x Phi(2.13);
    # with Acc and PSNR better together (scene a), at most Acc's 50 %
    assert t.rows[-1] == ("effect in SD", "Acc / C.R. / PSNR (all: independent, correlated)", "n/a / n/a / n/a",
                          "+0.00 / +6.71 / +2.13 (49 %, 50 %)")
    assert [b[3] for b in t.best[:-5]] == [True, False] * 3 and not any(any(b) for b in t.best[-5:])
    md = to_markdown(t)
    assert "| a | 0 | C.R. | **all** |" in md
    recs = list(csv.DictReader(io.StringIO(to_csv(t))))
    assert len(recs) == 7 and sum(r["beats_all"] == "True" for r in recs) == 3
    assert pair_lines(runs) == [
        "dagsbench: weighted beats baseline on all of Acc, C.R. and PSNR in 0 of 1 (scene, seed) pairs, 95 % CI "
        "0-98 % (Acc 0, C.R. 1, PSNR 0; wins.md)",
        "dagsbench: full beats baseline on all of Acc, C.R. and PSNR in 3 of 6 (scene, seed) pairs, 95 % CI "
        "12-88 % (Acc 3, C.R. 6, PSNR 6; wins.md)"]


def test_pairs_table_needs_the_reference_and_a_rival(tmp_path):
    only_full = [fake_run("full", "a", 0, acc=1, cr=50.0, psnr=20)]
    assert pairs_table(only_full) is None and pair_lines(only_full) == []
    assert tables.plot_wins(only_full, tmp_path / "wins.png") is None and not (tmp_path / "wins.png").exists()
    assert pairs_table([fake_run("baseline", "a", 0, acc=1, cr=50.0, psnr=20)]) is None
    # a method with no pair in common with the reference is left out
    t = pairs_table([fake_run("baseline", "a", 0, acc=1, cr=50.0, psnr=20),
                     fake_run("full", "a", 1, acc=1, cr=50.0, psnr=20)])
    assert t is None
    # a missing metric (e.g. PSNR n/a) never counts as a win
    r = fake_run("full", "a", 0, acc=0.5, cr=60.0, psnr=30)
    for c in r["checkpoints"]:
        c["psnr_db"] = None
    t = pairs_table([fake_run("baseline", "a", 0, acc=1, cr=50.0, psnr=20), r])
    assert t.rows[0][2] == "Acc, C.R." and t.rows[-5][2] == "0 / 1 / 1 / 0 of 1"
    assert t.rows[-3][2] == "1:0 p 1 / 1:0 p 1 / 0:0 p n/a"
    assert t.rows[-1][2] == "n/a / n/a / n/a"                      # one pair: no spread, no effect


def test_standardised_effects_and_the_normal_share_on_known_values():
    specs = [tables.METRIC_BY_KEY[k] for k in ("acc_cm", "cr_pct", "psnr_db")]
    # Acc lower is better: a mean difference of -1 cm with std 1 is +1 SD for the method
    d = np.array([[-2.0, 1.0, 0.0], [0.0, 3.0, 1.0], [-1.0, 5.0, -1.0]])
    z = tables.standardised_effects(d, specs)
    np.testing.assert_allclose(z, [1.0, 1.5, 0.0])
    # Phi(1) x Phi(1.5) x Phi(0) = 0.8413 x 0.9332 x 0.5
    assert abs(tables.normal_share_on_all(z) - 100 * 0.841345 * 0.933193 * 0.5) < 1e-3
    # 93 % per metric on three independent metrics is about 80 % on all
    assert abs(tables.normal_share_on_all([1.46] * 3) - 80.0) < 0.5
    assert tables.standardised_effects(d[:1], specs) == [None, None, None]
    assert tables.normal_share_on_all([1.0, None]) is None


def test_correlated_normal_share_keeps_how_the_metrics_move_together():
    """Uncorrelated pair differences give the independent model's share; metrics that move as one give the
    share of one of them; the same input gives the same number (no random numbers); too few pairs: None."""
    from scipy.stats import norm

    specs = [tables.METRIC_BY_KEY[k] for k in ("acc_cm", "cr_pct", "psnr_db")]
    # orthogonal centred columns (a sample correlation of 0), shifted: Acc -1 (better), C.R. +0.5, PSNR +0
    h = np.array([[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]])
    d = h + np.array([-1.0, 0.5, 0.0]) * np.sqrt(4.0 / 3.0)       # sample std of each column: sqrt(4/3)
    z = tables.standardised_effects(d, specs)
    np.testing.assert_allclose(z, [1.0, 0.5, 0.0])
    joint = tables.correlated_normal_share_on_all(d, specs)
    assert abs(joint - tables.normal_share_on_all(z)) < 0.3 and joint == tables.correlated_normal_share_on_all(d, specs)
    # one run quality behind all three: Acc down where C.R. and PSNR go up, by the same standardised amount
    q = np.array([0.3, 1.9, -0.4, 1.2, 0.8, 2.1, -0.7, 1.5])
    same = np.stack([-q, 2.0 * q, 0.5 * q], axis=1)
    z1 = tables.standardised_effects(same, specs)[0]
    assert abs(tables.correlated_normal_share_on_all(same, specs) - 100 * norm.cdf(z1)) < 0.3
    assert tables.correlated_normal_share_on_all(same, specs) > tables.normal_share_on_all([z1] * 3) + 20
    assert tables.correlated_normal_share_on_all(d[:1], specs) is None
    assert tables.correlated_normal_share_on_all(np.zeros((4, 3)), specs) is None


def test_win_share_interval_and_sign_test_on_known_values():
    # Clopper-Pearson: 0 of n has upper bound 1 - 0.025^(1/n), n of n lower bound 0.025^(1/n)
    lo, hi = tables.win_share_interval(0, 12)
    assert lo == 0.0 and abs(hi - 100 * (1 - 0.025 ** (1 / 12))) < 1e-9
    lo, hi = tables.win_share_interval(12, 12)
    assert abs(lo - 100 * 0.025 ** (1 / 12)) < 1e-9 and hi == 100.0
    lo, hi = tables.win_share_interval(4, 12)
    assert 9.9 < lo < 10.0 and 65.0 < hi < 65.2
    # 80 % of 12 pairs won is 10; its interval reaches down to about half
    assert tables.win_share_interval(10, 12)[0] < 55.0
    # sign test, two-sided: 10 : 2 is 2 (1 + 12 + 66) / 2^12
    assert abs(tables.sign_test_p(10, 2) - 2 * 79 / 4096) < 1e-12
    assert tables.sign_test_p(6, 6) == 1.0 and tables.sign_test_p(0, 0) is None
    with pytest.raises(ValueError, match="0 <= k <= n"):
        tables.win_share_interval(3, 2)
