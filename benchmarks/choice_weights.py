"""What other eq. (7) weights would have chosen at each of a run's new targets, from the logged candidates.

    python benchmarks/choice_weights.py runs/full/apartment-01-seed1.mcap --l-r 0,10,30

At every step where the selection chose a new target, the log holds each candidate view's gain I_s (eq. 8), motion
risk R_m (eq. 9) and travel cost C (for ``full`` the eq. (11) path cost from the robot, plus the turning). This
re-scores those candidates as eq. (7) ``I_s - l_r R_m - l_c C`` with each ``--l-r`` and with C either as logged
or as the plain path length (the graph's edge lengths from the robot's start node, plus the same turning: what
``gain_cost`` uses), and takes the best view where the run took its own: among all candidates, or, for ``full``
with the subregion rule, among those of the subregion the target lay in (the rule chose the subregion, eq. (7)
the view in it). Per run and setting it prints the share of choices that differ from the logged one and the
chosen views' mean I_s, R_m and graph distance from the robot; with several runs, last the same over all their
choices together (runs with different logged weights pool by setting).

It is open loop, one step at a time: the robot would have gone elsewhere after a changed choice, so this says how
much each term moves the choices the run made, not what a run with other weights would do (that needs the run).
The first setting of each run is the run's own weights, which must give back every logged choice.

A second table asks of ``full``'s choices in its own subregion before step ``--first-steps`` (the first quarter of
a 1000-step run by default) how far the subregion rule held the robot back by gain: the best I_s of the robot's
subregion over the best I_s anywhere in reach (quartiles; how many are under a half and under 0.3, what a rule
leaving the subregion below that share of the best gain would change), and how many of those choices the best
eq. (7) score anywhere (gain + cost with ``full``'s terms, no subregion) would have made otherwise, with the mean I_s
and graph distance of both.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)


@dataclass
class Choice:
    """One logged new-target choice: the candidates it was made among and their terms."""

    step: int
    pool: np.ndarray          # bool (C,): the candidates the run chose among (finite score, the target's subregion)
    chosen: int               # index of the logged choice among the candidates
    gain: np.ndarray          # (C,) I_s
    risk: np.ndarray          # (C,) R_m
    cost: np.ndarray          # (C,) C as logged
    plain: np.ndarray         # (C,) C with the plain path length
    dist_m: np.ndarray        # (C,) graph distance from the robot's start node
    mode: str = ""            # how the run chose it: local, global, ...
    finite: np.ndarray | None = None   # bool (C,): every candidate in reach (finite score)
    score: np.ndarray | None = None    # (C,) the logged eq. (7) score


def logged_choice(sel, pool: np.ndarray) -> int | None:
    """The index of the logged target view (node and yaw) among ``sel``'s candidates in ``pool`` (bool (C,)), or
    None when it is none of them (not a scored choice)."""
    yaw_off = np.abs(np.angle(np.exp(1j * (sel.cand_yaw_rad - sel.target_yaw_rad))))
    hit = np.nonzero(pool & (sel.cand_node == sel.target_node) & (yaw_off < 1e-6))[0]
    return int(hit[0]) if len(hit) else None


def read_choices(mcap: Path) -> tuple[str, object, list[Choice]]:
    """The run's label, its config and every new-target choice with logged candidates."""
    from dynactivegs.records import robot_pose_of
    from dynactivegs.selection.stage import _path_lengths, _turning_rad
    from dynactivegs.selection.voronoi import edge_list_arrays, nearest_clear_node
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    sel_cfg = cfg.selection
    by_region = sel_cfg.variant == "full" and sel_cfg.subregion_choice
    out = []
    for st in reader.steps():
        s = st.get("/selection")
        if s is None or len(s.cand_node) == 0 or s.target_node < 0 or s.target_reason == "keep":
            continue
        finite = np.isfinite(s.cand_score)
        pool = finite & (s.node_region[s.cand_node] == s.node_region[s.target_node]) if by_region else finite
        chosen = logged_choice(s, pool)
        if chosen is None:
            continue                                  # not a scored choice (e.g. random, frontier)
        pose = robot_pose_of(st["/frame"])
        robot_xy = np.array([pose.x_m, pose.y_m])
        arrays = edge_list_arrays(len(s.node_xy_m), s.edges, s.edge_length_m)
        dist, _ = _path_lengths(arrays, nearest_clear_node(s.node_xy_m, robot_xy, s.node_leg_clear))
        ny = sel_cfg.visibility.n_yaws            # the candidates are every scored node x every yaw, node-major
        turn = _turning_rad(s.node_xy_m[s.cand_node[::ny]], s.cand_yaw_rad[:ny], robot_xy, pose.yaw_rad,
                            sel_cfg.reach_tol_m).ravel()
        out.append(Choice(st.step, pool, chosen, s.cand_gain, s.cand_risk, s.cand_cost,
                          dist[s.cand_node] + sel_cfg.turn_cost_m * turn, dist[s.cand_node], s.mode, finite,
                          s.cand_score))
    label = f"{reader.metadata.get('preset', '?')} {cfg.sim.scene} seed {cfg.seed}"
    metrics = Path(mcap).with_suffix(".json")              # dagsbench's metrics file: the run's --set overrides
    if metrics.is_file():
        overrides = json.loads(metrics.read_text()).get("overrides") or []
        label += "".join(f" {o}" for o in overrides)
    return label, cfg, out


def rescore(choices: list[Choice], l_r: float, l_c: float, plain: bool) -> dict[str, float]:
    """The views eq. (7) picks with these weights: differing choices (count, %) and their mean I_s, R_m, distance."""
    picks = []
    for c in choices:
        score = c.gain - l_r * c.risk - l_c * (c.plain if plain else c.cost)
        picks.append(int(np.argmax(np.where(c.pool, score, -np.inf))))
    n = len(choices)
    differ = sum(p != c.chosen for p, c in zip(picks, choices))
    mean = (lambda f: float(np.mean([f(c, p) for c, p in zip(choices, picks)])) if n else float("nan"))
    return {"n": n, "differ": differ, "differ_pct": 100.0 * differ / n if n else float("nan"),
            "gain": mean(lambda c, p: c.gain[p]), "risk": mean(lambda c, p: c.risk[p]),
            "dist_m": mean(lambda c, p: c.dist_m[p])}


def local_gain_share(choices: list[Choice], before: int) -> dict[str, float]:
    """Of the choices made in the robot's own subregion (mode ``local``) before step ``before``: the ratio of the
    subregion's best I_s to the best I_s anywhere in reach (quartiles, counts under 0.5 and 0.3), and how many
    the best eq. (7) score anywhere would change, with the mean I_s and graph distance of the logged choice and
    of that one."""
    local = [c for c in choices if c.mode == "local" and c.step < before and c.finite is not None]
    if not local:
        return {"n": 0}
    best = np.array([c.gain[c.finite].max() for c in local])          # the best I_s anywhere in reach
    own = np.array([c.gain[c.pool].max() for c in local])             # ... and in the robot's subregion
    ratio = np.where(best > 0.0, own / np.where(best > 0.0, best, 1.0), 1.0)
    anywhere = [int(np.argmax(np.where(c.finite, c.score, -np.inf))) for c in local]
    q25, q50 = np.percentile(ratio, [25, 50])
    return {"n": len(local), "q25": float(q25), "median": float(q50), "under_half": int((ratio < 0.5).sum()),
            "under_03": int((ratio < 0.3).sum()), "differ": sum(a != c.chosen for a, c in zip(anywhere, local)),
            "gain": float(np.mean([c.gain[c.chosen] for c in local])),
            "gain_any": float(np.mean([c.gain[a] for a, c in zip(anywhere, local)])),
            "dist_m": float(np.mean([c.dist_m[c.chosen] for c in local])),
            "dist_any_m": float(np.mean([c.dist_m[a] for a, c in zip(anywhere, local)]))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--l-r", default="0,10,30", help="comma list of eq. (7) risk weights to re-score with")
    ap.add_argument("--first-steps", type=int, default=250,
                    help="the second table reads full's choices in its own subregion before this step")
    args = ap.parse_args(argv)
    try:
        l_rs = [float(x) for x in args.l_r.split(",")]
    except ValueError:
        sys.exit(f"error: bad --l-r {args.l_r!r}: give numbers separated by commas, e.g. 0,10,30")
    if any(not np.isfinite(x) or x < 0 for x in l_rs):
        sys.exit(f"error: bad --l-r {args.l_r!r}: weights must be finite and >= 0")
    from dynactivegs.errors import DagsError

    print("| run | choices | l_r | C | differ | I_s | R_m | graph m |\n|---|---|---|---|---|---|---|---|", flush=True)

    def row(label: str, r: dict[str, float], lr: float, plain: bool, tag: str) -> None:
        print(f"| {label} | {r['n']} | {lr:g}{tag} | {'plain' if plain else 'logged'} | {r['differ']} "
              f"({r['differ_pct']:.0f} %) | {r['gain']:.2f} | {r['risk']:.4f} | {r['dist_m']:.2f} |", flush=True)

    if args.first_steps < 1:
        sys.exit(f"error: bad --first-steps {args.first_steps}: give a step count >= 1, e.g. 250")
    pooled: dict[tuple[float, bool, float, str], list[Choice]] = {}
    local_rows: list[tuple[str, list[Choice]]] = []
    for path in args.mcap:
        try:
            label, cfg, choices = read_choices(path)
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        sel = cfg.selection
        own = (sel.l_r if sel.variant == "full" else 0.0, False)
        settings = [own] + [(lr, plain) for plain in (False, True) for lr in l_rs if (lr, plain) != own]
        for lr, plain in settings:
            tag = " (logged)" if (lr, plain) == own else ""
            row(label, rescore(choices, lr, sel.l_c, plain), lr, plain, tag)
            pooled.setdefault((lr, plain, sel.l_c, tag), []).extend(choices)
        if sel.variant == "full" and sel.subregion_choice:
            local_rows.append((label, choices))
    if len(args.mcap) > 1:                          # every choice of the runs together, per setting
        for (lr, plain, l_c, tag), choices in pooled.items():
            row(f"all {len(args.mcap)} runs", rescore(choices, lr, l_c, plain), lr, plain, tag)
    if local_rows:
        print(f"\n| run | own-subregion choices before step {args.first_steps} | its best I_s / best anywhere: q25 / "
              "median | under 0.5 / 0.3 | eq. (7) anywhere differs | I_s: logged / anywhere | graph m: logged / "
              "anywhere |\n|---|---|---|---|---|---|---|")
        if len(local_rows) > 1:
            local_rows.append((f"all {len(local_rows)} runs", [c for _, cs in local_rows for c in cs]))
        for label, choices in local_rows:
            r = local_gain_share(choices, args.first_steps)
            if r["n"] == 0:
                print(f"| {label} | 0 | - | - | - | - | - |")
                continue
            print(f"| {label} | {r['n']} | {r['q25']:.2f} / {r['median']:.2f} | {r['under_half']} / {r['under_03']} | "
                  f"{r['differ']} | {r['gain']:.1f} / {r['gain_any']:.1f} | "
                  f"{r['dist_m']:.2f} / {r['dist_any_m']:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
