"""``dagsbench`` end to end on a tiny setting: runs, metrics files, MCAP logs, tables, plots, resume, Ray."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dynactivegs.eval.progress import checkpoint_steps
from recorder import bench
from recorder.mcap_log import machine_difference, machine_id, machine_info

TINY = ["--suite", "tiny-00", "--seeds", "0", "--steps", "6", "--no-progress",
        "--set", "sim.camera.width_px=64", "sim.camera.height_px=40", "eval.n_gt_points=5000", "eval.n_views=4",
        "eval.coverage_points=500"]


def tiny_args(out, cache, presets="baseline,full", *extra: str) -> list[str]:
    return ["--presets", presets, "--out", str(out), *TINY, f"eval.cache_dir={cache}", *extra]


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """One two-run sweep (baseline and full on tiny-00, 6 steps) on a pool of two processes, shared below."""
    out, cache = tmp_path_factory.mktemp("bench"), tmp_path_factory.mktemp("cache")
    assert bench.main(tiny_args(out, cache, "baseline,full", "--workers", "2")) == 0
    assert len(list((cache / "gt_points").glob("tiny-00*.npz"))) == 1     # computed once, before the workers
    assert len(list((cache / "survey").glob("tiny-00*.npz"))) == 1
    return out, cache


def test_runs_write_metrics_at_every_checkpoint_and_a_log(finished):
    out, _ = finished
    for p in ("baseline", "full"):
        r = json.loads((out / "runs" / p / "tiny-00-seed0.json").read_text())
        assert (r["preset"], r["scene"], r["seed"], r["steps"]) == (p, "tiny-00", 0, 6)
        assert [c["step"] for c in r["checkpoints"]] == list(checkpoint_steps(6)) == [2, 3, 5, 6]
        assert [c["fraction"] for c in r["checkpoints"]] == [0.25, 0.5, 0.75, 1.0]
        for c in r["checkpoints"]:
            assert 0.0 <= c["cr_pct"] <= 100.0 and c["acc_cm"] > 0 and c["psnr_db"] > 0 and c["n_views"] == 4
            assert c["lpips"] is None and "n/a" in f"{c['lpips_note']} n/a"
            assert len(c["psnr_views_db"]) == 4 and sum(c["psnr_views_db"]) / 4 == pytest.approx(c["psnr_db"])
            assert all(0.0 <= c[k] <= 100.0 for k in ("hole_err_pct", "front_err_pct", "behind_err_pct"))
        # the 100 % row measures the refined map (3 passes over the keyframes of steps 0 and 3) and keeps the
        # unrefined one's metrics; the others measure the map as the loop left it
        assert [c["refine_iters"] for c in r["checkpoints"]] == [0, 0, 0, 6]
        assert set(r["checkpoints"][-1]["online"]) >= {"acc_cm", "cr_pct", "psnr_db", "n_gaussians"}
        assert all("online" not in c for c in r["checkpoints"][:-1]) and r["seconds_refine"] > 0
        assert r["coverage"][0][0] == 1 and r["coverage"][-1][0] == 6
        # the camera has seen some of the probe points after its first frames, and never unsees one
        seen = [c["observed_pct"] for c in r["checkpoints"]]
        assert 0.0 < seen[0] and seen == sorted(seen) and seen[-1] <= 100.0 and "observed_pct" in r["observed_note"]
        # ... and some of what the held-out views show (the views are the same at every checkpoint here)
        views = [c["observed_view_pct"] for c in r["checkpoints"]]
        assert 0.0 < views[0] and views == sorted(views) and views[-1] <= 100.0
        assert "observed_view_pct" in r["observed_note"]
        assert r["config"]["sim"]["camera"]["width_px"] == 64
        assert r["machine"] == machine_info() and len(r["machine"]["id"]) == 10
        assert r["config"]["mapping"]["weighted"] is (p == "full")
        log = out / "runs" / p / "tiny-00-seed0.mcap"
        assert r["mcap"] == log.name and log.stat().st_size > 0
    # the map grows, so the last checkpoint covers no less than the first
    full = json.loads((out / "runs" / "full" / "tiny-00-seed0.json").read_text())
    assert full["checkpoints"][-1]["n_gaussians"] >= full["checkpoints"][0]["n_gaussians"] > 0


def test_log_replays_as_whole_steps(finished):
    from replay.source import LogReader

    out, _ = finished
    reader = LogReader(out / "runs" / "full" / "tiny-00-seed0.mcap")
    assert [s.step for s in reader.steps()] == list(range(6))
    assert reader.metadata["preset"] == "full" and reader.metadata["steps_requested"] == "6"
    assert {k: v for k, v in reader.metadata.items() if k.startswith("machine.")} == {
        f"machine.{k}": v for k, v in machine_info().items()}
    last = json.loads((out / "runs" / "full" / "tiny-00-seed0.json").read_text())["checkpoints"][-1]
    assert len(reader.refined_map()) == last["n_gaussians"]


def test_tables_and_plots_are_written(finished):
    out, _ = finished
    for name in ("main.md", "main.csv", "ablation_components.md", "ablation_components.csv", "wins.md", "wins.csv",
                 "progress.png", "coverage.png"):
        assert (out / name).stat().st_size > 0, name
    md = (out / "main.md").read_text()
    assert "| Method | Metric | tiny-00 | Mean |" in md and "| full | C.R. (%) |" in md and "**" in md
    assert "| full | LPIPS | n/a | n/a |" in md
    assert not (out / "ablation_selection.md").exists()      # only full of Table 4's variants was run


def test_second_invocation_skips_finished_runs(finished, capsys):
    out, cache = finished
    stamp = (out / "runs" / "full" / "tiny-00-seed0.json").stat().st_mtime_ns
    assert bench.main(tiny_args(out, cache)) == 0
    printed = capsys.readouterr().out
    assert "0 runs in" in printed and "2 already finished (skipped)" in printed
    # the (scene, seed) pairs full won against baseline, as wins.md counts them
    wins = (out / "wins.md").read_text()
    assert "| tiny-00 | 0 |" in wins and "| pairs won | all Acc / C.R. / PSNR |" in wins
    assert "dagsbench: full beats baseline on all of Acc, C.R. and PSNR in " in printed and " of 1 (scene, seed)" in printed
    # ... or against another preset
    assert bench.main(tiny_args(out, cache, "baseline,full", "--wins-against", "full")) == 0
    assert "dagsbench: baseline beats full on all of" in capsys.readouterr().out
    assert "### Pairs against full" in (out / "wins.md").read_text()
    assert bench.main(tiny_args(out, cache)) == 0           # the tables as before, for the tests after this one
    assert (out / "runs" / "full" / "tiny-00-seed0.json").stat().st_mtime_ns == stamp


def test_resume_refuses_other_settings(finished, capsys):
    out, cache = finished
    assert bench.main(tiny_args(out, cache, "full", "mapping.weighted=false")) == 2
    err = capsys.readouterr().err
    assert err.startswith("dagsbench: error:") and "other settings (mapping.weighted)" in err and err.count("\n") == 1


def test_resume_takes_runs_from_before_an_option_and_warns_of_another_machine(finished, tmp_path, capsys):
    """A finished run whose config lacks an option added since (its default keeps the behaviour before) is
    still finished; resuming a folder whose runs were made on another machine says so before running."""
    out, cache = finished
    copy = tmp_path / "copy"
    shutil.copytree(out / "runs", copy / "runs", ignore=shutil.ignore_patterns("*.mcap"))
    f = copy / "runs" / "baseline" / "tiny-00-seed0.json"
    r = json.loads(f.read_text())
    del r["config"]["selection"]["local_share"]
    r["machine"] = {**r["machine"], "id": "elsewhere0"}
    f.write_text(json.dumps(r))
    (copy / "runs" / "full" / "tiny-00-seed0.json").unlink()
    assert bench.main(tiny_args(copy, cache, "baseline,full", "--no-mcap")) == 0
    printed = capsys.readouterr().out
    assert "1 run in" in printed and "1 already finished (skipped)" in printed
    assert (f"dagsbench: warning: 1 of the 1 finished runs in this folder were made on another machine than this "
            f"one ({machine_info()['id']})") in printed
    assert "dagsbench: warning: these runs come from 2 machines (1 on " in printed
    assert "1 of these 1 comparisons put runs made on different machines" in (copy / "wins.md").read_text()
    assert bench.other_machine_line([r], r["machine"]["id"]) is None
    assert bench.other_machine_line([{"preset": "full"}], "x") is None     # a run from before the machine entry


def test_reevaluate_measures_finished_runs_again_from_their_logs(finished, tmp_path, capsys):
    out, cache = finished
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    path = copy / "runs" / "full" / "tiny-00-seed0.json"
    before = json.loads(path.read_text())
    # weighted was never run: it is left alone, not started
    assert bench.main(tiny_args(copy, cache, "baseline,weighted,full", "eval.n_views=3", "--reevaluate",
                                "--workers", "2")) == 0
    assert "2 finished runs re-evaluated" in capsys.readouterr().out
    assert not (copy / "runs" / "weighted").exists()
    after = json.loads(path.read_text())
    assert after["eval_overrides"][-1] == "n_views=3" and after["eval_config"]["n_views"] == 3
    assert after["coverage"] == before["coverage"] and after["config"] == before["config"]
    for b, a in zip(before["checkpoints"], after["checkpoints"]):
        # the log holds the map of every checkpoint, so the geometry is measured on the very same map
        assert a["map_step"] == a["step"] == b["step"] and a["n_gaussians"] == b["n_gaussians"]
        assert (a["acc_cm"], a["comp_cm"], a["cr_pct"]) == (b["acc_cm"], b["comp_cm"], b["cr_pct"])
        assert a["refine_iters"] == b["refine_iters"] and a.get("online", {}).get("cr_pct") == b.get("online", {}).get("cr_pct")
        assert a["n_views"] == 3 and b["n_views"] == 4
        # the frames of the log give the observed surface the run measured online
        assert a["observed_pct"] == b["observed_pct"]
        assert 0.0 < a["observed_view_pct"] <= 100.0          # on the 3 views now
    (copy / "runs" / "full" / "tiny-00-seed0.mcap").unlink()
    assert bench.main(tiny_args(copy, cache, "full", "--reevaluate")) == 2
    err = capsys.readouterr().err
    assert err.startswith("dagsbench: error:") and "tiny-00-seed0.mcap: missing" in err and err.count("\n") == 1


@pytest.mark.parametrize("argv, words", [
    (["--presets", "baseline,nope"], "unknown preset 'nope'"),
    (["--wins-against", "nope"], "unknown preset 'nope'"),
    (["--suite", "mansion"], "mansion"),
    (["--seeds", "0,x"], "--seeds"),
    (["--set", "mapping.nope=1"], "unknown config key 'mapping.nope'"),
    (["--set", "eval.n_views=0"], "eval.n_views"),
    (["--set", "sim.scene"], "key=value"),
    (["--steps", "0"], "--steps"),
])
def test_bad_input_is_one_line(tmp_path, capsys, argv, words):
    assert bench.main(["--out", str(tmp_path / "o"), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dagsbench: error:") and words in err and err.count("\n") == 1, err
    assert not (tmp_path / "o" / "runs").exists()


def test_console_script_help():
    r = subprocess.run([sys.executable, "-m", "recorder.bench", "--help"], capture_output=True, text=True, check=True)
    assert "--ray ADDRESS" in r.stdout and "--presets" in r.stdout


def test_two_runs_through_a_local_ray_instance(finished, tmp_path, capsys):
    ray = pytest.importorskip("ray", reason="Ray is not installed: pip install 'dynactivegs[ray]'")
    cache = finished[1]                     # the ground truth of tiny-00 is cached there already
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        assert ray.cluster_resources().get("CPU") == 2
        out = tmp_path / "out"
        assert bench.main(tiny_args(out, cache, "baseline,full", "--ray", "local", "--no-mcap")) == 0
        assert "2 runs in" in capsys.readouterr().out
    finally:
        ray.shutdown()
    for p in ("baseline", "full"):
        r = json.loads((out / "runs" / p / "tiny-00-seed0.json").read_text())
        assert r["mcap"] is None and len(r["checkpoints"]) == 4
        assert not (out / "runs" / p / "tiny-00-seed0.mcap").exists()
    assert (out / "main.md").is_file()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux-only")
def test_killing_dagsbench_leaves_no_pool_workers(tmp_path):
    cmd = [sys.executable, "-m", "recorder.bench", "--presets", "baseline", "--suite", "tiny-00", "--seeds", "0,1",
           "--steps", "2000", "--workers", "2", "--out", str(tmp_path / "out"), "--no-mcap", "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def children() -> list[int]:
        out = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout
        return [int(x) for x in out.split()]

    deadline = time.monotonic() + 60
    while len(children()) < 2 and time.monotonic() < deadline:
        time.sleep(0.5)
    workers = children()
    assert len(workers) >= 2, "the pool did not start"
    time.sleep(3)                                           # let the workers run their initializer
    proc.terminate()
    proc.wait(timeout=30)
    def alive(pid: int) -> bool:                            # a zombie waiting to be reaped is not running
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except (FileNotFoundError, ProcessLookupError):
            return False

    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(alive(w) for w in workers):
        time.sleep(0.2)
    assert not any(alive(w) for w in workers)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="parent-death signal is Linux-only")
def test_a_pool_worker_whose_parent_died_while_it_started_exits():
    # the parent-death signal only covers a parent that dies after the initializer ran
    code = "import sys; from recorder.bench import _die_with_parent; _die_with_parent(int(sys.argv[1])); print('alive')"
    orphan = subprocess.run([sys.executable, "-c", code, "1"], capture_output=True, text=True, timeout=120)
    assert orphan.returncode == 1 and "alive" not in orphan.stdout
    child = subprocess.run([sys.executable, "-c", code, str(os.getpid())], capture_output=True, text=True, timeout=120)
    assert child.returncode == 0 and "alive" in child.stdout



def test_ghost_occluders_finds_surface_over_the_free_floor():
    """A made-up truth map: 2 x 3 m of floor at 0.1 m cells with a wall along x = 0; surface voxels in the open at a
    person's height are ghosts, the floor's, those by the wall, above 2.1 m or off the map are not."""
    from types import SimpleNamespace as NS

    from scipy.ndimage import distance_transform_edt

    mod = _benchmark_module("ghost_occluders")
    free = np.ones((20, 30), bool)                                  # rows along y, columns along x
    free[:, 0] = False                                              # the wall: x in [0, 0.1)
    fs = NS(origin_xy_m=np.array([0.0, 0.0]), res_m=0.1, shape=free.shape)
    clear_m = distance_transform_edt(free) * 0.1
    ijk = np.array([[20, 10, 20],      # x 1.025, y 0.525, z 1.025: in the open, a person's height -> ghost
                    [20, 10, 1],       # z 0.075: the floor's own voxel
                    [3, 10, 20],       # x 0.175: within 0.15 m of the wall
                    [20, 10, 60],      # z 3.025: above a person
                    [200, 10, 20],     # x 10.025: off the map
                    [-3, 10, 20]], np.int32)
    assert mod.ghost_voxels(ijk, 0.05, fs, clear_m, 0.15).tolist() == [True, False, False, False, False, False]
    assert mod.ghost_voxels(ijk, 0.05, fs, clear_m, 0.0)[2]         # no margin: by the wall counts too


def test_ghost_occluders_re_runs_each_choice_without_the_ghosts(finished, capsys, monkeypatch):
    """benchmarks/ghost_occluders.py on the sweep's runs: the re-run selection gives back every logged target; with
    every surface voxel taken for a ghost, each logged new target is chosen again without the map's occluders."""
    from replay.source import LogReader

    out, _ = finished
    mod = _benchmark_module("ghost_occluders")
    log = out / "runs" / "baseline" / "tiny-00-seed0.mcap"
    steps = list(LogReader(log).steps())
    label, preset, rec = mod.ghost_record(log, 0.15)
    assert label == "baseline tiny-00 seed 0" and preset == "baseline" and len(rec.ghosts) == len(steps) == 6
    assert rec.replayed == 6 and rec.choices <= sum(mod._new_target(st["/selection"]) for st in steps)
    monkeypatch.setattr(mod, "ghost_voxels", lambda ijk, *a: np.ones(len(ijk), bool))
    _, _, every = mod.ghost_record(log, 0.15)
    new_targets = sum(mod._new_target(st["/selection"]) for st in steps)
    assert every.ghosts == [len(st["/mapping"].surface_ijk) for st in steps] and every.replayed == 6
    assert every.choices == new_targets >= 1 and 0 <= every.changed <= every.choices
    assert every.gain_free > 0 and every.corridor_logged == every.corridor_free == 0     # tiny-00: no corridor
    assert mod.main([str(log)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | steps | ghost voxels")
    assert printed[2].startswith("| baseline tiny-00 seed 0 | 6 |")
    assert printed[2] == mod.row(label, every)          # main takes the record ghost_record makes
    assert printed[4].startswith("| preset (runs) |") and printed[6].startswith("| baseline (1) | 6 |")
    for argv, words in (([str(out / "missing.mcap")], "missing.mcap"), ([str(log), "--margin", "-1"], "--margin")):
        with pytest.raises(SystemExit, match=f"error: .*{words}"):
            mod.main(argv)

def test_blocked_episodes_tells_a_person_ahead_from_a_wall():
    """A made-up step: the forward step blocked by a person (their pixels in the truth mask), by the room's wall, by
    nothing in view (a remembered block), a turn-away (no re-plan), and a step that was not blocked."""
    from types import SimpleNamespace as NS

    from dynactivegs.planning.actions import ActionConfig
    from tests.selection.scenes import intrinsics, render_depth, view

    mod = _benchmark_module("blocked_episodes")
    acfg, K = ActionConfig(), intrinsics(64, 36)
    plan = NS(blocked=True, replanned=True)

    def step(x, boxes=()):
        T = view(x, 1.5, 0.0)
        depth, which = render_depth(T, K, 64, 36, (4.0, 3.0), list(boxes))
        return NS(depth_m=depth, K=K, T_world_cam=T), NS(people_mask=which == 0)

    person = (2.3, 1.35, 2.6, 1.65, 1.75)
    assert mod.step_cause(plan, *step(2.0, [person]), acfg) == "person"           # 0.3 m ahead
    assert mod.step_cause(plan, *step(3.7), acfg) == "static"                     # the wall 0.3 m ahead
    assert mod.step_cause(plan, *step(1.0), acfg) == "remembered"                 # nothing within a step
    assert mod.step_cause(NS(blocked=True, replanned=False), *step(2.0, [person]), acfg) == "evade"
    assert mod.step_cause(NS(blocked=False, replanned=True), *step(3.7), acfg) is None
    assert mod.step_cause(None, *step(3.7), acfg) is None


def test_blocked_episodes_groups_steps_and_finds_what_became_of_the_target(monkeypatch):
    """Made-up steps: two hold-ups (a person, then a wall with a remembered step), each with the selection's next
    new target as its outcome; steps near a person from the truth; the corridor from the scene's rooms; the people
    pixels let into the grid by their beta; a close person in the open held by the grid or not."""
    from types import SimpleNamespace as NS

    from dynactivegs.sim.procedural import Room

    mod = _benchmark_module("blocked_episodes")
    causes = [None, "person", None, "person", None, None, None, None, None, None, "static", "remembered", None, None]
    reasons = ["keep"] * 14
    reasons[5], reasons[13] = "reached", "unreachable"
    monkeypatch.setattr(mod, "step_cause", lambda plan, frame, truth, acfg: plan)
    rooms = [Room("c", "corridor", 0.0, 0.0, 1.0, 3.0), Room("r", "living", 1.0, 0.0, 4.0, 3.0)]
    fs = NS(origin_xy_m=np.zeros(2), res_m=0.1, shape=(30, 40))
    clear_m = np.full((30, 40), 1.0)
    clear_m[:, 35:] = 0.2                                          # near a wall: x >= 3.5 is not in the open
    setting = mod.Setting(rooms, None, 0.75, fs, clear_m, 0.3)
    mask = np.zeros((2, 2), bool)
    mask[0] = True                                                 # two people pixels per frame
    perception = NS(beta=np.array([[0.5, 0.9], [0.1, 0.1]], np.float32))   # one of them let in (beta <= 0.75)
    window = np.full((3, 3), 0.6, np.float32)
    window[1, 2] = 0.1                                             # an obstacle held 0.5 m ahead of the robot
    steps = []
    for k, (c, r) in enumerate(zip(causes, reasons)):
        x = 0.5 if k < 8 else 2.0                                   # in the corridor, then in the room
        people = np.array([[x + 0.5, 1.0]]) if k % 2 else np.zeros((0, 2))   # 0.5 m ahead on odd steps
        truth = NS(robot=NS(x_m=x, y_m=1.0), people_xy_m=people, people_mask=mask)
        sel = NS(target_reason=r, local_clear_m=window, local_origin_xy_m=np.array([x - 0.75, 0.25]),
                 local_cell_m=0.5)
        steps.append((None, truth, perception, c, sel))
    rec = mod.record_of(steps, setting, gap=5)
    assert rec.steps == 14 and rec.near == 7 and rec.causes == ["person", "person", "static", "remembered"]
    assert rec.episodes == [("person", 2, True, "reached"), ("static", 2, False, "unreachable")]
    s = rec.summary()
    assert s["ep_person"] == s["ep_static"] == 1 and s["ep_other"] == 0 and s["per_episode"] == 2.0
    assert s["corridor_pct"] == s["given_up_pct"] == s["reached_pct"] == 50.0
    assert s["person_rate"] == pytest.approx(100.0 / 7) and s["let_in_pct"] == 50.0
    assert rec.close == 7 and rec.in_grid == 7                      # every odd step's person, held
    ahead = NS(robot=NS(x_m=2.0, y_m=1.0), people_xy_m=np.array([[2.5, 1.0], [1.5, 1.0], [2.6, 2.6]]))
    sel = NS(local_clear_m=window, local_origin_xy_m=np.array([1.25, 0.25]), local_cell_m=0.5)
    assert mod.close_people(sel, ahead, setting) == (2, 1)          # ahead: held; behind: not; off the window
    wall = NS(robot=NS(x_m=3.2, y_m=1.0), people_xy_m=np.array([[3.7, 1.0]]))
    assert mod.close_people(NS(local_clear_m=window, local_origin_xy_m=np.array([2.45, 0.25]), local_cell_m=0.5),
                            wall, setting) == (0, 0)                # by the wall: not in the open
    assert mod.close_people(NS(local_clear_m=np.zeros((0, 0))), ahead, setting) == (0, 0)
    assert mod.record_of(steps[:1], setting).episodes == []                         # nothing blocked


def test_blocked_episodes_reads_every_blocked_step_of_a_log(finished, capsys):
    """benchmarks/blocked_episodes.py on the sweep's runs: one cause per logged blocked step, pooled per preset; a
    missing log is one line."""
    from replay.source import LogReader

    out, logs = _sweep_logs(finished)
    mod = _benchmark_module("blocked_episodes")
    for log in logs:
        label, preset, rec = mod.blocked_record(log)
        steps = list(LogReader(log).steps())
        assert label == f"{preset} tiny-00 seed 0" and rec.steps == len(steps) == 6
        assert len(rec.causes) == sum(bool(st["/planning"].blocked) for st in steps)
        assert set(rec.causes) <= set(mod.STEP_CAUSES) and len(rec.episodes) <= len(rec.causes)
    assert mod.main([str(log) for log in logs]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | steps | blocked: person") and printed[2].startswith("| baseline tiny-00")
    assert printed[5].startswith("| preset (runs) |") and printed[7].startswith("| baseline (1) | 6 |")
    assert printed[-1].startswith("rank correlation") and "all runs - (p -, " in printed[-1]   # too few runs
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])


def test_blocked_episodes_correlates_letting_people_in_with_hold_ups_over_runs_and_within_presets():
    """Over all runs a preset that lets more people in and is held up less gives a negative rho; within each preset
    its own runs' order decides; fewer than 3 runs, or an undefined rate, give nan."""
    mod = _benchmark_module("blocked_episodes")
    run = (lambda preset, let_in, rate: (preset, {"let_in_pct": let_in, "person_rate": rate}))
    runs = [run("a", 10.0, 1.0), run("a", 11.0, 1.1), run("a", 12.0, 1.2),
            run("b", 1.0, 3.0), run("b", 2.0, 3.1), run("b", 3.0, 3.2), run("c", 5.0, float("nan"))]
    out = mod.let_in_correlations(runs)
    assert out["all runs"][0] < -0.5 and out["all runs"][2] == 6
    assert out["a"][0] == pytest.approx(1.0) and out["b"][0] == pytest.approx(1.0) and out["a"][2] == 3
    assert np.isnan(out["c"][0]) and out["c"][2] == 0


def _sweep_logs(finished):
    """The sweep's folder and its two tiny-00 seed-0 run logs, of `baseline` and `full`."""
    out, _ = finished
    return out, [out / "runs" / p / "tiny-00-seed0.mcap" for p in ("baseline", "full")]


def _benchmark_module(name: str):
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod                       # as an import would: dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_psnr_ceiling_reads_a_logged_run(finished):
    """benchmarks/psnr_ceiling.py on the sweep's full run: its held-out PSNR is dagsbench's, the map fits the
    views it was trained on far better than the held-out ones after 6 steps, fitting one view alone raises
    that view's PSNR, and box-filtered renders differ from the point-sampled ones."""
    from dynactivegs.eval.config import EvalConfig

    out, cache = finished
    mod = _benchmark_module("psnr_ceiling")
    ecfg = EvalConfig(n_views=4, cache_dir=str(cache))
    label, r = mod.run_ceiling(out / "runs" / "full" / "tiny-00-seed0.mcap", False, 2, 50, 2, ecfg)
    metrics = json.loads((out / "runs" / "full" / "tiny-00-seed0.json").read_text())["checkpoints"][-1]
    assert label.startswith("tiny-00 seed 0")
    assert r["heldout"] == pytest.approx(metrics["psnr_db"], abs=0.05)
    assert r["train"] > r["heldout"] + 10.0
    assert r["overfit_after"] > r["overfit_before"]
    assert 15.0 < r["floor"] < 60.0


def test_refine_passes_reproduces_the_runs_refinement_and_goes_on(finished):
    """benchmarks/refine_passes.py on the sweep's full run: re-running mapping over the log and refining with the
    run's 3 passes gives the run's refined map (the same metrics as dagsbench's 100 % row); 1 and 6 passes differ."""
    from dynactivegs.eval.config import EvalConfig

    out, cache = finished
    mod = _benchmark_module("refine_passes")
    label, rows = mod.sweep_run(out / "runs" / "full" / "tiny-00-seed0.mcap", [1, 3, 6],
                                EvalConfig(n_views=4, n_gt_points=5000, coverage_points=500, cache_dir=str(cache)))
    r = dict(rows)
    metrics = json.loads((out / "runs" / "full" / "tiny-00-seed0.json").read_text())["checkpoints"][-1]
    assert label.startswith("tiny-00 seed 0") and list(r) == ["logged", "1 passes", "3 passes", "6 passes"]
    for k in ("n_gaussians", "acc_cm", "cr_pct", "psnr_db"):
        assert r["3 passes"][k] == r["logged"][k] == pytest.approx(metrics[k])
    assert r["1 passes"]["psnr_db"] != r["3 passes"]["psnr_db"] != r["6 passes"]["psnr_db"]
    assert r["1 passes"]["seconds"] <= r["3 passes"]["seconds"] <= r["6 passes"]["seconds"]


def test_refine_passes_set_re_runs_mapping_with_a_what_if(finished):
    """refine_passes.py --set: the mapping re-run takes mapping.* overrides (seeding every 4th pixel instead of
    every 2nd leaves a smaller map than the run's) and refuses any other key in one line."""
    from dynactivegs.errors import DagsError
    from dynactivegs.eval.config import EvalConfig

    out, cache = finished
    mod = _benchmark_module("refine_passes")
    log = out / "runs" / "full" / "tiny-00-seed0.mcap"
    ev = EvalConfig(n_views=4, n_gt_points=5000, coverage_points=500, cache_dir=str(cache))
    _, rows = mod.sweep_run(log, [3], ev, overrides=("mapping.densify_stride=4",))
    r = dict(rows)
    assert r["3 passes"]["n_gaussians"] < r["logged"]["n_gaussians"]
    with pytest.raises(DagsError, match="only mapping"):
        mod.sweep_run(log, [3], ev, overrides=("selection.variant=random",))


def test_occupancy_errors_counts_a_false_obstacle_and_a_cleared_wall():
    """benchmarks/occupancy_errors.py's measure on a constructed case: a 2 m room with a 0.3 m thick wall
    across it; the grid holds one cell of open floor occupied and one cell inside the wall free."""
    from scipy.ndimage import distance_transform_edt

    from dynactivegs.selection.occupancy import OccupancyConfig, OccupancyGrid
    from dynactivegs.sim.freespace import FreeSpace

    mod = _benchmark_module("occupancy_errors")
    occ = np.zeros((40, 40), bool)
    occ[:, 20:26] = True                                      # x in [1.0, 1.3): a wall 6 cells thick
    fs = FreeSpace.from_grid(occ, 0.05)
    free = fs.floor & ~fs.occupied
    clear_m, inside_m = distance_transform_edt(free) * 0.05, distance_transform_edt(~free) * 0.05
    cfg = OccupancyConfig()
    logodds = np.full((40, 40), -1.0, np.float32)
    logodds[occ] = 2.0
    perfect = OccupancyGrid((0, 0), 0.05, logodds.copy())
    e = mod.grid_errors(perfect, cfg, fs, clear_m, inside_m, 0.15)
    assert e["false_occ_m2"] == 0 and e["false_free_m2"] == 0 and e["known_free_pct"] == pytest.approx(100.0)
    logodds[10, 5] = 2.0                                      # open floor, 0.75 m from the wall
    logodds[10, 19] = 2.0                                     # next to the wall face: not counted
    logodds[30, 22] = -1.0                                    # inside the wall, two cells in
    logodds[30, 20] = -1.0                                    # the wall's face cell: not counted
    e = mod.grid_errors(OccupancyGrid((0, 0), 0.05, logodds), cfg, fs, clear_m, inside_m, 0.15)
    assert e["false_occ_m2"] == pytest.approx(0.0025) and e["false_free_m2"] == pytest.approx(0.0025)
    assert e["known_free_pct"] == pytest.approx(100.0 * (free.sum() - 2) / free.sum())


def test_occupancy_errors_measures_floor_a_held_door_cuts_off():
    """cut_off_m2 on a constructed case: a 2 m room parted by a wall with a 0.6 m door; the robot in the left
    part. With the door free or unseen nothing is cut off; with a person's cells held occupied in it, the right
    part's floor that the planner's 0.22 m disc can travel (columns 30-35 x rows 4-35 of 5 cm cells, 0.48 m2) is;
    behind a door too narrow for the disc in truth nothing is."""
    from scipy.ndimage import distance_transform_edt

    from dynactivegs.selection.occupancy import OccupancyConfig, OccupancyGrid
    from dynactivegs.sim.freespace import FreeSpace

    mod = _benchmark_module("occupancy_errors")
    occ = np.zeros((40, 40), bool)
    occ[:, 20:26] = True
    occ[15:27, 20:26] = False                                 # the door, y in [0.75, 1.35)
    fs = FreeSpace.from_grid(occ, 0.05)
    clear_m = distance_transform_edt(fs.floor & ~fs.occupied) * 0.05
    cfg = OccupancyConfig()
    logodds = np.where(occ, np.float32(2.0), np.float32(-1.0)).astype(np.float32)
    robot, truth = np.array([0.5, 1.0]), mod.truth_pieces(clear_m, 0.22)
    assert mod.cut_off_m2(OccupancyGrid((0, 0), 0.05, logodds.copy()), cfg, fs, truth, robot, 0.22) == 0.0
    unseen = logodds.copy()
    unseen[15:27, 20:26] = 0.0                                # the door's floor not seen yet: not shut
    assert mod.cut_off_m2(OccupancyGrid((0, 0), 0.05, unseen), cfg, fs, truth, robot, 0.22) == 0.0
    logodds[18:24, 20:26] = 2.0                               # someone stood in the door
    held = OccupancyGrid((0, 0), 0.05, logodds)
    assert mod.cut_off_m2(held, cfg, fs, truth, robot, 0.22) == pytest.approx(0.48)
    assert mod.cut_off_m2(held, cfg, fs, truth, np.array([1.7, 1.0]), 0.22) == pytest.approx(
        0.0025 * 12 * 32)                                       # from the right: the left part, cols 4-15 x rows 4-35
    narrow = occ.copy()
    narrow[15:21, 20:26] = True                               # a 0.3 m door: the disc is parted in truth too
    fs_narrow = FreeSpace.from_grid(narrow, 0.05)
    clear_narrow = distance_transform_edt(fs_narrow.floor & ~fs_narrow.occupied) * 0.05
    shut = OccupancyGrid((0, 0), 0.05, np.where(narrow, np.float32(2.0), np.float32(-1.0)).astype(np.float32))
    assert mod.cut_off_m2(shut, cfg, fs_narrow, mod.truth_pieces(clear_narrow, 0.22), robot, 0.22) == 0.0


def test_occupancy_errors_sees_a_let_go_through_a_grown_grid():
    """let_go_any: a cell's obstacle top dropping back to 0 is a let-go, also where the grid grew in between."""
    from dynactivegs.selection.occupancy import OccupancyGrid

    mod = _benchmark_module("occupancy_errors")
    top = np.zeros((4, 4), np.float32)
    top[1, 1] = 1.5
    before = OccupancyGrid((0, 0), 0.05, np.zeros((4, 4), np.float32), top_m=top)
    grown_top = np.zeros((6, 6), np.float32)
    grown_top[3, 2] = 1.5                                     # the same cell, the origin moved by (-2, -1) cells
    grown = OccupancyGrid((-2, -1), 0.05, np.zeros((6, 6), np.float32), top_m=grown_top)
    assert not mod.let_go_any(before, before) and not mod.let_go_any(before, grown)
    assert mod.let_go_any(before, OccupancyGrid((-2, -1), 0.05, np.zeros((6, 6), np.float32)))


def test_let_go_events_tells_a_piece_on_the_floor_from_one_in_a_wall_and_reads_people_returns():
    """benchmarks/let_go_events.py's pieces on a constructed case: the grid grew between the two updates; one
    piece on open floor with people returns next to it, one in a wall with none; a cell that kept its top is
    not a let-go."""
    from scipy.ndimage import distance_transform_edt

    from dynactivegs.selection.occupancy import OccupancyGrid
    from dynactivegs.sim.freespace import FreeSpace

    mod = _benchmark_module("let_go_events")
    occ = np.zeros((40, 40), bool)
    occ[:, 20:26] = True
    fs = FreeSpace.from_grid(occ, 0.05)
    clear_m = distance_transform_edt(fs.floor & ~fs.occupied) * 0.05
    top = np.zeros((40, 40), np.float32)
    top[10:12, 5:7], top[30, 22:24], top[5, 5] = 1.5, 0.9, 1.0
    before = OccupancyGrid((0, 0), 0.05, np.zeros((40, 40), np.float32), top_m=top)
    assert mod.pieces_let_go(before, before, fs, clear_m, 3) == []
    after_top, people = np.zeros((42, 41), np.float32), np.zeros((42, 41), np.int32)
    after_top[7, 6] = 1.0                                     # cell (5, 5), origin moved by (-2, -1): kept
    people[14, 7], people[32, 27] = 4, 9                      # (12, 6): by the floor piece; (30, 26): 3 off the wall's
    after = OccupancyGrid((-2, -1), 0.05, np.zeros((42, 41), np.float32), top_m=after_top, people=people)
    floor, wall = mod.pieces_let_go(before, after, fs, clear_m, 3)
    assert floor == {"cells": 4, "free": 4, "top_m": 1.5, "people": 4, "own": 0}
    assert wall == {"cells": 2, "free": 0, "top_m": pytest.approx(0.9), "people": 9, "own": 0}
    assert mod.pieces_let_go(before, after, fs, clear_m, 2)[1]["people"] == 0


def test_let_go_events_reads_a_log(finished, capsys, monkeypatch):
    """let_go_events.py on the sweep's full run: 6 frames let nothing go (50 quiet frames cannot pass); the
    table and the counts are printed."""
    _, logs = _sweep_logs(finished)
    mod = _benchmark_module("let_go_events")
    assert mod.run_events(logs[1], []) == ("tiny-00 seed 0", [])
    monkeypatch.setattr(sys, "argv", ["let_go_events.py", str(logs[1])])
    mod.main()
    out = capsys.readouterr().out
    assert "pieces let go: 0 on free floor (people), 0 in furniture or walls" in out
    assert "transient_people_frames 10: would keep 0 of 0 people pieces" in out


def test_evade_steps_tells_a_bump_the_map_check_refuses_from_a_step_that_moved():
    """benchmarks/evade_steps.py on constructed steps: a turn-away step toward a known obstacle 0.3 m ahead that
    bumped, one away from it that moved, a path's forward step (not a turn-away), and a last turn-away step
    with no next step (left out)."""
    from types import SimpleNamespace as NS

    from scipy.ndimage import distance_transform_edt

    from dynactivegs.planning.actions import ActionConfig

    mod = _benchmark_module("evade_steps")
    cell, size = 0.05, 41
    occ = np.zeros((size, size), bool)
    occ[20, 26] = True                                        # 0.3 m along +x from the window's centre (1, 1)
    sel = NS(local_clear_m=(distance_transform_edt(~occ) * cell).astype(np.float32),
             local_origin_xy_m=np.array([1.0, 1.0]) - 0.5 * size * cell, local_cell_m=cell)

    class Step:
        def __init__(self, i, x, yaw, evade, path=0):
            self.step, self._d = i, {"/truth": NS(robot=NS(x_m=x, y_m=1.0, yaw_rad=yaw)), "/selection": sel,
                                     "/planning": NS(action=0, blocked=evade, replanned=path > 0,
                                                     path_xy_m=np.zeros((path, 2)))}

        def get(self, topic):
            return self._d[topic]

    steps = [Step(0, 1.0, 0.0, True), Step(1, 1.0, math.pi, True), Step(2, 0.75, math.pi, False, path=3),
             Step(3, 0.5, math.pi, True)]
    got = mod.evade_steps(steps, ActionConfig(), 0.05)
    assert got == [{"step": 0, "map_ok": False, "moved": False}, {"step": 1, "map_ok": True, "moved": True}]
    assert mod.counts(got) == (1, 0, 0, 1)


def test_evade_steps_reads_a_log(finished, capsys):
    """evade_steps.py on the sweep's full run: every step it finds is a blocked forward step with no re-plan and
    no path in the log; the table and the sum are printed; a missing log is one line."""
    from replay.source import LogReader

    out, _ = finished
    log = out / "runs" / "full" / "tiny-00-seed0.mcap"
    mod = _benchmark_module("evade_steps")
    label, steps = mod.run_steps(log)
    assert label == "tiny-00 seed 0"
    logged = {st.step: st["/planning"] for st in LogReader(log).steps()}
    for s in steps:
        pl = logged[s["step"]]
        assert pl.action == 0 and pl.blocked and not pl.replanned and len(pl.path_xy_m) == 0
    assert mod.main([str(log)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("| run | turn-away steps") and f"| tiny-00 seed 0 (full) | {len(steps)} |" in printed
    assert f"{len(steps)} turn-away steps in 1 runs" in printed
    with pytest.raises(SystemExit, match="not found"):
        mod.main([str(out / "missing.mcap")])


def test_path_stats_counts_the_logged_path(finished, capsys, tmp_path):
    """benchmarks/path_stats.py on the sweep's two runs: one action per step, the collisions dagsbench counted,
    the robot's distance driven and cells from its logged poses, the people near it from the logged truth; a
    missing log is one line."""
    from dynactivegs.records import robot_pose_of
    from replay.source import LogReader

    out, _ = finished
    mod = _benchmark_module("path_stats")
    for p in ("baseline", "full"):
        log = out / "runs" / p / "tiny-00-seed0.mcap"
        label, scene, s = mod.path_stats(log, 0.5)
        assert label == f"{p} tiny-00 seed 0" and scene == "tiny-00" and s["steps"] == 6
        assert s["forward"] + s["turn"] + s["stop"] == 6
        assert s["collisions"] == json.loads((out / "runs" / p / "tiny-00-seed0.json").read_text())["collisions"]
        xy = np.array([(q.x_m, q.y_m) for q in (robot_pose_of(st["/frame"]) for st in LogReader(log).steps())])
        assert s["path_m"] == pytest.approx(np.hypot(*np.diff(xy, axis=0).T).sum())
        assert s["cells"] == len({tuple(c) for c in np.floor(xy / 0.5).astype(int)}) >= 1
        assert s["local"] + s["global"] >= 1 and 0.0 <= s["people_pct"] <= 100.0
        steps = list(LogReader(log).steps())
        near = [np.sum(np.hypot(*(st["/truth"].people_xy_m - [st["/truth"].robot.x_m, st["/truth"].robot.y_m]).T)
                       < mod.NEAR_M) for st in steps]
        assert s["people_near"] == pytest.approx(np.mean(near))
        assert s["blocked"] == sum(bool(st["/planning"].blocked) for st in steps) and s["episodes"] <= s["blocked"]
        assert 0.0 <= s["detour_pct"] <= 100.0 and s["loops"] >= 0.0
    assert mod.main([str(out / "runs" / "full" / "tiny-00-seed0.mcap")]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | path m") and printed[2].startswith("| full tiny-00 seed 0 |")
    with pytest.raises(SystemExit, match="log not found"):
        mod.main([str(out / "missing.mcap")])
    capsys.readouterr()
    # --metrics: each run's refined C.R. and PSNR from dagsbench's metrics file beside the log
    logs = [str(out / "runs" / p / "tiny-00-seed0.mcap") for p in ("baseline", "full")]
    assert mod.main(["--metrics", *logs]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].endswith("| C.R. % | PSNR dB | Obs. % | Obs. views % |")
    last = json.loads((out / "runs" / "full" / "tiny-00-seed0.json").read_text())["checkpoints"][-1]
    assert printed[3].endswith(f"| {last['cr_pct']:.1f} | {last['psnr_db']:.2f} | {last['observed_pct']:.1f} |"
                               f" {last['observed_view_pct']:.1f} |")
    assert printed[-1].endswith("needs 3 runs or more in scenes with 2 or more")     # two runs of one scene
    # a metrics file from before the observed surface was recorded: measured from the log's frames, the same
    old = tmp_path / "old"
    shutil.copytree(out / "runs" / "full", old)
    done = json.loads((old / "tiny-00-seed0.json").read_text())
    for c in done["checkpoints"]:
        del c["observed_pct"], c["observed_view_pct"]
    (old / "tiny-00-seed0.json").write_text(json.dumps(done))
    cr, psnr, seen, views, observed, evaluator = mod.run_metrics(old / "tiny-00-seed0.mcap")
    assert (cr, psnr, seen, views) == (last["cr_pct"], last["psnr_db"], None, None)
    measured = mod.path_stats(old / "tiny-00-seed0.mcap", 0.5, observed, evaluator)[2]
    assert measured["observed_pct"] == last["observed_pct"]
    assert measured["observed_view_pct"] == pytest.approx(last["observed_view_pct"], abs=1e-9)


def test_unseen_surface_finds_the_held_out_pixels_the_camera_never_saw(finished, capsys, tmp_path):
    """benchmarks/unseen_surface.py on the sweep's runs: the observed surface and its share of the held-out
    views are the ones dagsbench recorded, the rooms' losses are parts of what was lost, and the floor plans
    are drawn; bad arguments are one line."""
    out, _ = finished
    mod = _benchmark_module("unseen_surface")
    logs = [out / "runs" / p / "tiny-00-seed0.mcap" for p in ("baseline", "full")]
    png = tmp_path / "unseen.png"
    assert mod.main([*map(str, logs), "--out", str(png)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | Obs. % | Obs. views % |") and png.stat().st_size > 0
    for log, line in zip(logs, printed[2:4]):
        last = json.loads(log.with_suffix(".json").read_text())["checkpoints"][-1]
        assert line.startswith(f"| {log.parent.name} tiny-00 seed 0 | {last['observed_pct']:.1f} | "
                               f"{last['observed_view_pct']:.1f} |")
    run = mod.unseen_of_run(logs[1])
    o, w = run["observed"], run["weights"]
    share = 100.0 * w[o.seen].sum() / w.sum()
    last = json.loads(logs[1].with_suffix(".json").read_text())["checkpoints"][-1]
    assert share == pytest.approx(last["observed_view_pct"], abs=1e-9) and w.min() >= 0.0
    rooms = mod.room_losses(run, top=100)
    assert rooms and all(pct >= 0.0 for _, pct in rooms)
    assert sum(pct for _, pct in rooms) <= 100.0 - share + 1e-6        # a point lies in one room at most
    with pytest.raises(SystemExit, match="give a .png path"):
        mod.main([str(logs[0]), "--out", str(tmp_path / "unseen.jpg")])
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])


def test_psnr_breakdown_splits_the_held_out_error_by_what_the_path_saw(finished, capsys):
    """benchmarks/psnr_breakdown.py on the sweep's runs: its PSNR is dagsbench's, and the share of the held-out
    pixels showing surface the camera never saw, counted pixel by pixel, is what Obs. views estimates from the
    probe points."""
    out, _ = finished
    mod = _benchmark_module("psnr_breakdown")
    logs = [out / "runs" / p / "tiny-00-seed0.mcap" for p in ("baseline", "full")]
    assert mod.main([str(log) for log in logs]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert "| unseen px / err | PSNR seen / all px |" in printed[0] and len(printed) == 4
    from dynactivegs.eval.rendering import SeenSplit
    for log, line in zip(logs, printed[2:]):
        last = json.loads(log.with_suffix(".json").read_text())["checkpoints"][-1]
        _, rows = mod.run_breakdown(log, online=False)
        assert np.mean([r["psnr_db"] for r in rows]) == pytest.approx(last["psnr_db"], abs=1e-6)
        unseen_px, unseen_err, seen_psnr, _ = SeenSplit.pooled([r["seen"] for r in rows])
        assert 100 * unseen_px == pytest.approx(100.0 - last["observed_view_pct"], abs=2.0)
        assert 0.0 < unseen_px < 1.0 and 0.0 < unseen_err < 1.0 and np.isfinite(seen_psnr)
        assert line.startswith(f"| tiny-00 seed 0, {log.parent.name} | {last['psnr_db']:.2f} |")
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])


def test_path_stats_counts_a_wait_with_turns_between_tries_as_one_episode():
    """Blocked steps a few turns apart are one hold-up; a longer gap starts another."""
    mod = _benchmark_module("path_stats")
    flags = np.zeros(30, bool)
    flags[[2, 3, 6, 12]] = True                 # 2 and 3 steps between: one episode with gap 5
    flags[[19, 20, 29]] = True                  # 6 steps after 12, 8 after 20: two more (5 runs in all)
    assert mod.blocked_episodes(flags) == 3
    assert mod.blocked_episodes(flags, gap=0) == 5 and mod.blocked_episodes(flags, gap=10) == 1
    assert mod.blocked_episodes(np.zeros(5, bool)) == 0


def test_path_stats_finds_detours_and_counts_the_graphs_loops():
    """A path round the long side of a loop is a detour by its length over the short side's; a path on a tree,
    or one with fewer than two nodes on it, is not; a square with a tail has one loop, two trees none."""
    mod = _benchmark_module("path_stats")
    node_xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [2.0, 0.0]])
    edges = np.array([[0, 1], [1, 2], [2, 3], [0, 3], [1, 4]])
    length = np.array([1.0, 1.0, 1.0, 1.0, 1.0])
    robot, target = np.array([[-0.3, 0.1]]), np.array([[1.0, 0.05]])
    short = np.concatenate([robot, node_xy[[0, 1]], target])
    long = np.concatenate([robot, node_xy[[0, 3, 2, 1]], target])
    assert mod.detour_ratio(node_xy, edges, length, short) == pytest.approx(1.0)
    assert mod.detour_ratio(node_xy, edges, length, long) == pytest.approx(3.0)
    assert mod.detour_ratio(node_xy, edges, length, np.concatenate([robot, target])) == 1.0
    assert mod.cycle_rank(5, edges) == 1
    assert mod.cycle_rank(5, edges[[0, 1, 4]]) == 0 and mod.cycle_rank(0, edges[:0]) == 0    # two components


def test_path_stats_correlates_path_traits_with_psnr_within_each_scene(tmp_path):
    """Scenes differ in how high PSNR goes: the correlation is taken relative to each scene's mean, so a scene
    with more cells and less PSNR than another does not hide more cells going with more PSNR within both."""
    mod = _benchmark_module("path_stats")
    stats = lambda cells, reached: {"path_m": 2.0 * cells, "cells": cells, "reached": reached}
    runs = [("a", stats(10, 5), 20.0), ("a", stats(20, 3), 21.0), ("a", stats(30, 4), 22.0),
            ("b", stats(110, 3), 10.0), ("b", stats(120, 5), 11.0), ("b", stats(130, 4), 12.0),
            ("c", stats(500, 9), 0.0)]                                            # one run: no mean to compare with
    corr, n = mod.within_scene_correlations(runs)
    assert n == 6 and corr["cells"][0] == pytest.approx(1.0) and corr["path_m"][0] == pytest.approx(1.0)
    assert abs(corr["reached"][0]) < 0.5
    from scipy.stats import spearmanr
    assert spearmanr([r[1]["cells"] for r in runs], [r[2] for r in runs])[0] < 0   # pooled raw values: the other way
    assert mod.within_scene_correlations(runs[:2] + runs[-1:]) is None
    log = tmp_path / "run.mcap"
    log.with_suffix(".json").write_text("{}")
    with pytest.raises(ValueError, match="is not dagsbench's"):
        mod.run_metrics(log)
    with pytest.raises(ValueError, match="no metrics file"):
        mod.run_metrics(tmp_path / "other.mcap")


def test_choice_weights_gives_back_the_logged_choices(finished, capsys):
    """benchmarks/choice_weights.py on the sweep's runs: the run's own eq. (7) weights pick every logged target
    again; for baseline (gain + cost) the logged travel cost is the plain path length it rebuilds; bad
    arguments are one line."""
    out, _ = finished
    mod = _benchmark_module("choice_weights")
    logs = [out / "runs" / p / "tiny-00-seed0.mcap" for p in ("baseline", "full")]
    for log in logs:
        label, cfg, choices = mod.read_choices(log)
        assert label.startswith(f"{log.parent.name} tiny-00 seed 0") and choices
        own_l_r = cfg.selection.l_r if cfg.selection.variant == "full" else 0.0
        assert mod.rescore(choices, own_l_r, cfg.selection.l_c, plain=False)["differ"] == 0
        for c in choices:
            assert c.pool[c.chosen] and np.all(c.dist_m[c.pool] >= 0.0)
            if cfg.selection.variant == "gain_cost":
                np.testing.assert_allclose(c.plain, c.cost, rtol=0, atol=1e-9)
    _, _, choices = mod.read_choices(logs[1])
    local = [c for c in choices if c.mode == "local"]
    r = mod.local_gain_share(choices, 10 ** 6)
    assert r["n"] == len(local) > 0 and 0.0 < r["q25"] <= r["median"] <= 1.0 and r["under_03"] <= r["under_half"]
    assert r["differ"] > 0 or (r["gain"], r["dist_m"]) == (r["gain_any"], r["dist_any_m"])   # the same choices
    assert mod.local_gain_share(choices, 0)["n"] == 0
    assert mod.main([str(logs[1]), "--l-r", "0,30", "--first-steps", str(10 ** 6)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | choices | l_r | C |") and "30 (logged) | logged | 0 (0 %)" in printed[2]
    assert printed[6] == "" and "own-subregion choices before step 1000000" in printed[7]   # logged, l_r 0 logged,
    assert printed[9].startswith("| full tiny-00 seed 0") and f" | {r['n']} | " in printed[9]   # 0 and 30 plain
    assert len(printed) == 10
    with pytest.raises(SystemExit, match="bad --l-r"):
        mod.main([str(logs[0]), "--l-r", "0,x"])
    with pytest.raises(SystemExit, match="bad --first-steps"):
        mod.main([str(logs[0]), "--first-steps", "0"])
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])


def test_people_in_view_splits_the_logged_people_pixels(finished, capsys):
    """benchmarks/people_in_view.py on the sweep's runs: people px over every logged step, split by blocked steps;
    R_m ranks of scored choices in [0, 1]; pooled per preset; a missing log is one line."""
    from replay.source import LogReader

    out, logs = _sweep_logs(finished)
    mod = _benchmark_module("people_in_view")
    for log in logs:
        label, preset, rec = mod.people_in_view(log)
        steps = list(LogReader(log).steps())
        s = rec.summary()
        assert label == f"{preset} tiny-00 seed 0" and preset == log.parent.name and s["steps"] == len(steps) == 6
        assert s["px_pct"] == pytest.approx(100.0 * np.mean([st["/truth"].people_mask.mean() for st in steps]))
        assert rec.blocked == [bool(st["/planning"].blocked) for st in steps] and s["corridor_pct"] == 0.0
        assert s["choices"] >= 1 and all(0.0 <= r <= 1.0 for r in rec.rank)
    assert mod.main([str(log) for log in logs]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[0].startswith("| run | people px % |") and printed[2].startswith("| baseline tiny-00 seed 0 |")
    assert printed[5].startswith("| preset (runs) |") and printed[7].startswith("| baseline (1) |")
    assert printed[10].startswith("| preset (runs) | median steps to arrival |")
    assert printed[12].startswith("| baseline")
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])


def test_people_in_view_ranks_the_chosen_risk_and_pairs_it_with_the_arrival_frame():
    """A made-up run: a choice of the riskiest of three views reached with a person in half the frame, then one of
    the least risky reached with none; the corridor steps and targets by the scene's rooms."""
    from types import SimpleNamespace as NS

    from dynactivegs.sim.procedural import Room

    mod = _benchmark_module("people_in_view")
    assert mod.risk_rank(np.array([1.0, 2.0, 3.0]), 2) == 1.0 and mod.risk_rank(np.array([1.0, 2.0, 3.0]), 0) == 0.0
    assert mod.risk_rank(np.array([2.0, 2.0, 1.0]), 0) == 0.75 and mod.risk_rank(np.array([5.0]), 0) == 0.5
    rooms = (Room("corridor-0", "corridor", 0.0, 0.0, 4.0, 1.0), Room("living-1", "living", 0.0, 1.0, 4.0, 5.0))

    def truth(x, y, px):
        mask = np.zeros((2, 4), bool)
        mask.flat[:px] = True
        return NS(people_mask=mask, robot=NS(x_m=x, y_m=y))

    def sel(reason, node, yaw=0.0):
        return NS(target_reason=reason, target_node=node, target_yaw_rad=yaw,
                  target_xy_m=np.array([1.0, 3.0 - 2 * node]), cand_node=np.array([0, 1, 2]),
                  cand_yaw_rad=np.array([0.0, 0.0, 0.0]), cand_score=np.array([1.0, 2.0, 3.0]),
                  cand_risk=np.array([0.1, 0.5, 0.9]))

    plan = lambda blocked: NS(blocked=blocked)
    steps = [(truth(1.0, 0.5, 0), plan(False), sel("none", 2)),          # chooses the riskiest view
             (truth(1.5, 0.5, 8), plan(True), sel("keep", 2)),           # blocked, everything a person
             (truth(2.0, 3.0, 4), plan(False), sel("reached", 0)),       # there: half a person; then the safest
             (truth(2.5, 3.0, 2), plan(False), None),                    # selection did not run
             (truth(3.0, 3.0, 0), plan(False), sel("reached", 1, 1.0)),  # there: nobody; no candidate at yaw 1
             (truth(3.0, 3.0, 0), plan(False), sel("stuck", 1))]         # given up: not an arrival
    rec = mod.record_of(steps, rooms)
    s = rec.summary()
    assert rec.rank == [1.0, 0.0, 0.5] and rec.arrival == [(1.0, 0.5, 2), (0.0, 0.0, 2)]
    assert s["choices"] == 3 and s["arrivals"] == 2 and s["arrival_steps"] == 2.0
    assert s["px_arrival_pct"] == pytest.approx(25.0)
    assert s["px_blocked_pct"] == 100.0 and s["px_other_pct"] == pytest.approx(100.0 * (0.5 + 0.25) / 5)
    assert s["corridor_pct"] == pytest.approx(100.0 * 2 / 6) and s["px_corridor_pct"] == pytest.approx(50.0)
    assert rec.target_corridor == [False, False, True, True] and s["target_corridor_pct"] == 50.0
    assert np.isnan(s["rho"]) and np.isnan(s["rho_p"])                     # two arrivals: no correlation
    median, (sooner, later) = mod.by_delay([(0.0, 0.0, 5), (0.5, 0.1, 10), (1.0, 0.2, 15), (0.2, 0.3, 30),
                                            (0.4, 0.2, 40), (0.9, 0.1, 50)])
    assert median == 22.5 and sooner["n"] == later["n"] == 3 and sooner["rho"] == pytest.approx(1.0)
    assert later["rho"] == pytest.approx(-1.0) and sooner["px_pct"] == pytest.approx(10.0)
    assert mod.row("made-up", s).endswith("| 100.0 / 15.0 | 33 / 50 | 50.0 / 18.8 | 3 | 0.50 | 2 (2) | 25.0 |"
                                          " - (p -) |")                    # undefined: a dash


def test_machine_id_follows_the_cpu_and_the_libraries():
    info = {"cpu": "AMD EPYC", "isa": "AVX512", "llvm_cpu": "znver4", "cores": "2"}
    versions = {"python": "3.12.1", "torch": "2.13.0", "numpy": "2.4.6"}
    mid = machine_id(info, versions)
    assert len(mid) == 10 and mid == machine_id({**info, "cores": "64"}, dict(reversed(versions.items())))
    others = (machine_id({**info, "isa": "AVX2"}, versions), machine_id({**info, "llvm_cpu": "znver3"}, versions),
              machine_id(info, {**versions, "torch": "2.12.0"}))
    assert len({mid, *others}) == 4
    here = {**info, "id": mid}
    assert machine_difference(here, here) is None
    assert machine_difference({}, here) is None                         # a log older than the machine metadata
    assert machine_difference({**info, "isa": "AVX2", "llvm_cpu": "znver3", "id": "x"}, here) == (
        "isa AVX2 there, AVX512 here; llvm_cpu znver3 there, znver4 here")
    assert machine_difference({**info, "id": "x"}, here) == "the numeric libraries' versions differ"


def test_runs_from_two_machines_are_warned_about_and_counted_in_wins():
    from dynactivegs.eval.tables import cross_machine_pairs, machines, pairs_table
    from tests.eval.test_tables import fake_run

    runs = [fake_run(p, s, 0, acc=1.0, cr=50.0, psnr=20.0) for p in ("baseline", "full") for s in ("a", "b")]
    assert bench.machines_line(runs) is None and machines(runs) == {}     # files from before the machine entry
    for r in runs:
        r["machine"] = {"id": "m1"}
    assert bench.machines_line(runs) is None and cross_machine_pairs(runs) == (0, 2)
    assert "different machines" not in pairs_table(runs).note
    runs[3]["machine"] = {"id": "m2"}                                     # full on scene b made elsewhere
    assert machines(runs) == {"m1": 3, "m2": 1} and cross_machine_pairs(runs) == (1, 2)
    assert bench.machines_line(runs).startswith(
        "dagsbench: warning: these runs come from 2 machines (3 on m1, 1 on m2)")
    assert "1 of these 2 comparisons put runs made on different machines" in pairs_table(runs).note


def test_compare_runs_sets_the_same_runs_side_by_side(tmp_path, capsys):
    """benchmarks/compare_runs.py on two constructed results folders: per-run differences, which runs share a
    machine, and whether each pair's outcome against baseline is the same in both."""
    from tests.eval.test_tables import fake_run

    mod = _benchmark_module("compare_runs")
    values = {"a": {("baseline", "s0"): (3.0, 90.0, 23.0), ("full", "s0"): (2.0, 91.0, 24.0),
                    ("baseline", "s1"): (3.0, 90.0, 23.0), ("full", "s1"): (2.0, 89.0, 24.0)},
              "b": {("baseline", "s0"): (3.0, 92.0, 23.5), ("full", "s0"): (2.5, 91.0, 24.0),   # loses C.R. in B
                    ("baseline", "s1"): (3.0, 90.0, 23.0), ("full", "s1"): (2.0, 89.0, 24.0)}}
    for folder, runs in values.items():
        for (p, s), (acc, cr, psnr) in runs.items():
            r = fake_run(p, s, 0, acc=acc, cr=cr, psnr=psnr)
            r["machine"] = {"id": "m1" if folder == "a" or s == "s1" else "m2"}
            d = tmp_path / folder / ("runs" if p == "baseline" else f"{p}/runs") / p   # both layouts
            d.mkdir(parents=True, exist_ok=True)
            (d / f"{s}-seed0.json").write_text(json.dumps(r))
    only_a = fake_run("weighted", "s0", 0, acc=1.0, cr=1.0, psnr=1.0)
    (tmp_path / "a" / "runs" / "weighted").mkdir()
    (tmp_path / "a" / "runs" / "weighted" / "s0-seed0.json").write_text(json.dumps(only_a))
    png = tmp_path / "ab.png"
    assert mod.main([str(tmp_path / "a"), str(tmp_path / "b"), "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "| baseline | s0 | 0 | 3.00 / 90.0 / 23.00 | 3.00 / 92.0 / 23.50 | +0.00 / +2.0 / +0.50 | no |" in out
    assert "| full | s1 | 0 | 2.00 / 89.0 / 24.00 | 2.00 / 89.0 / 24.00 | +0.00 / +0.0 / +0.00 | yes |" in out
    assert "Mean |B - A| over 4 runs (Acc / C.R. / PSNR): 0.12 / 0.5 / 0.12" in out
    assert "| full | s0 | 0 | all | Acc, PSNR | no |" in out
    assert "| full | s1 | 0 | Acc, PSNR | Acc, PSNR | yes |" in out
    assert ("full: beats baseline on all three in 1 of 2 pairs in A, 0 in B; the outcome agrees in 1 of 2 "
            "(per metric: Acc 2, C.R. 1, PSNR 2)") in out
    assert "weighted" not in out                                          # only in A
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a config that differs leaves the run out; an option only one side has does not
    cfg = mod.config_difference({"m": {"x": 1, "new": 0}}, {"m": {"x": 1}})
    assert cfg == [] and mod.config_difference({"m": {"x": 1}}, {"m": {"x": 2}}) == ["m.x"]
    # an option whose default changed the behaviour: missing means its value before it existed
    assert mod.config_difference({"selection": {"l_r": 1}}, {"selection": {"l_r": 1, "local_people_steps": 3}}) == \
        ["selection.local_people_steps"]
    assert mod.config_difference({"selection": {"local_people_steps": 0}}, {"selection": {"l_r": 1}}) == []
    # --ignore-set: a run made with an override that is the default now matches one made without it
    for folder, overrides, steps in (("c", ["selection.local_people_steps=3"], 3), ("d", [], 3), ("e", [], 0)):
        r = fake_run("full", "s0", 0, acc=2.0, cr=90.0, psnr=24.0)
        r["overrides"], r["config"] = overrides, {"selection": {"local_people_steps": steps}}
        (tmp_path / folder / "runs" / "full").mkdir(parents=True)
        (tmp_path / folder / "runs" / "full" / "s0-seed0.json").write_text(json.dumps(r))
    capsys.readouterr()
    assert mod.main([str(tmp_path / "c"), str(tmp_path / "d")]) == 2          # labels differ: nothing in common
    assert mod.main([str(tmp_path / "c"), str(tmp_path / "d"), "--ignore-set"]) == 0
    assert "| full | s0 | 0 |" in capsys.readouterr().out
    assert mod.main([str(tmp_path / "c"), str(tmp_path / "e"), "--ignore-set"]) == 2   # the configs differ
    (tmp_path / "c" / "more" / "runs" / "full").mkdir(parents=True)
    (tmp_path / "c" / "more" / "runs" / "full" / "s0-seed0.json").write_text(
        (tmp_path / "e" / "runs" / "full" / "s0-seed0.json").read_text())
    assert mod.main([str(tmp_path / "c"), str(tmp_path / "d"), "--ignore-set"]) == 2
    assert "give a folder holding one config of it" in capsys.readouterr().err
    # bad input: one line, exit 2
    assert mod.main([str(tmp_path / "a"), str(tmp_path / "nowhere")]) == 2
    assert "no such results folder" in capsys.readouterr().err
    (tmp_path / "b" / "runs" / "baseline" / "s1-seed0.json").write_text("{\"preset\": ")
    assert mod.main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2
    assert "not a dagsbench metrics file" in capsys.readouterr().err


def test_bench_occupancy_rules_times_three_grids_on_a_log(finished):
    """benchmarks/bench_occupancy_rules.py on the sweep's full run (6 steps): three configs, each timed over
    every frame but the first, none letting a cell go (50 quiet frames cannot pass in 6 steps)."""
    _, logs = _sweep_logs(finished)
    mod = _benchmark_module("bench_occupancy_rules")
    label, out = mod.time_rules(logs[1], 1000, 50)
    assert label == "tiny-00 seed 0" and len(out) == 3 and list(out)[0] == "logged"
    for r in out.values():
        assert r["frames"] == 5 and r["let_go"] == 0 and 0.0 < r["median_ms"] <= r["max_ms"]
    assert all(r["frames"] == 2 for r in mod.time_rules(logs[1], 3, 50)[1].values())


def test_room_gain_splits_a_room_into_its_walls_band_and_interior():
    """benchmarks/room_gain.py's voxel split on a constructed grid: a 2 x 3 m room, 0.1 m voxels; the band is
    every room voxel within 0.3 m of an inner wall face, each given to its nearest wall, the rest interior, all
    0.1 m over the floor to 0.3 m under the walls' top."""
    from dynactivegs.records import FieldsOut
    from dynactivegs.sim.procedural import WALL_T_M, Room

    mod = _benchmark_module("room_gain")
    shape, origin = (30, 40, 30), np.array([-0.503, -0.517, 0.0])     # no centre on a face or a diagonal
    z = np.zeros(shape, np.float32)
    f = FieldsOut(origin, 0.1, z, z, z, np.zeros(shape, np.bool_))
    band, interior, side = mod.voxel_masks(f, Room("r", "bedroom", 0.0, 0.0, 2.0, 3.0), 2.7, 0.3)
    x, y, h = (origin[i] + (np.arange(n) + 0.5) * 0.1 for i, n in enumerate(shape))
    X, Y, H = np.meshgrid(x, y, h, indexing="ij")
    half = WALL_T_M / 2
    gaps = np.stack([Y - half, 3.0 - half - Y, X - half, 2.0 - half - X])          # south, north, west, east
    in_room = (gaps > 0).all(axis=0) & (H > 0.1) & (H < 2.4)
    assert not (band & interior).any() and np.array_equal(band | interior, in_room)
    assert np.array_equal(interior, in_room & (gaps > 0.3).all(axis=0)) and interior.sum() > 0
    nearest = np.take_along_axis(gaps, side[None].astype(np.int64), axis=0)[0]
    assert np.all(nearest[band] <= 0.3) and np.array_equal(nearest[band], gaps.min(axis=0)[band])
    assert all((band & (side == k)).sum() > 0 for k in range(4))


def test_room_gain_reads_the_fields_and_candidates_of_a_log(finished, capsys):
    """benchmarks/room_gain.py on the sweep's full run: the shares and sums are those of the logged /fields grid,
    the gains those of the latest logged scoring, every target lies in tiny-00's one room, entered where the
    logged robot first stands 0.3 m inside its walls; the room has no door, so its whole band is "other walls" and
    it is not counted as seen through its door; bad input is one line."""
    from replay.source import LogReader

    out, logs = _sweep_logs(finished)
    mod = _benchmark_module("room_gain")
    label, rows, runs = mod.room_gains(logs[1], [5, 2])
    assert label == "full tiny-00 seed 0" and [r.step for r in rows] == [2, 5] and rows[0].room == "kitchen-0"
    fields, sels, new_targets, robot = {}, {}, 0, []
    for st in LogReader(logs[1]).steps():
        fields[st.step] = st["/fields"]
        robot.append((st["/truth"].robot.x_m, st["/truth"].robot.y_m))
        s = st.get("/selection")
        new_targets += int(s is not None and s.target_node >= 0 and s.target_reason != "keep")
        if s is not None and len(s.cand_node):
            sels[st.step] = s
    from dynactivegs.sim.scenes import load_scene
    from psnr_breakdown import logged_config

    cfg = logged_config(LogReader(logs[1]), logs[1])
    scene = load_scene(cfg.sim)
    x0, y0, x1, y1 = scene.rooms[0].inner(0.3)
    inside = [k for k, (x, y) in enumerate(robot) if x0 < x < x1 and y0 < y < y1]
    assert list(runs) == ["kitchen-0"] and runs["kitchen-0"].targets == new_targets > 0
    assert runs["kitchen-0"].entered_step == (inside[0] if inside else -1)
    for r in rows:
        f = fields[r.step]
        band, interior, _ = mod.voxel_masks(f, scene.rooms[0], scene.wall_height_m, 0.3)
        assert r.interior_seen_pct == pytest.approx(100.0 * (f.n_obs[interior] > 0).mean())
        assert r.band_us == pytest.approx(float(f.u_s[band].sum()) * f.voxel_m ** 3)
        at = max(k for k in sels if k <= r.step)
        assert r.selection_step == at and r.best_gain_any == float(sels[at].cand_gain.max())
        assert r.best_gain_room <= r.best_gain_any and r.nodes == len(sels[at].node_xy_m)   # one room holds all
        assert np.isnan(r.door_band_seen_pct) and r.other_band_seen_pct == r.band_seen_pct
    sides = [v for v in rows[1].side_seen_pct if np.isfinite(v)]        # nan: none of the wall's band in the grid
    assert sides and 0.0 <= min(sides) and max(sides) <= 100.0
    assert mod.main([str(logs[1]), "--steps", "5"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[2].startswith("| full tiny-00 seed 0 | 5 | kitchen-0 |")
    entered = str(runs["kitchen-0"].entered_step) if inside else "-"
    assert any(line.startswith(f"| full tiny-00 seed 0 | kitchen-0 | {entered} | {new_targets} | ") for line in printed)
    assert any(line.startswith("seen through their door only") and line.endswith(": 0 of 1 rooms in 1 runs")
               for line in printed)
    with pytest.raises(SystemExit, match="no room 'bathroom-9' in tiny-00: use one of kitchen-0"):
        mod.main([str(logs[1]), "--room", "bathroom-9"])
    with pytest.raises(SystemExit, match="bad --steps"):
        mod.main([str(logs[1]), "--steps", "5,x"])
    with pytest.raises(SystemExit, match="the log holds no step 6; ask for steps the run took"):
        mod.main([str(logs[1]), "--steps", "2,6"])                     # the run took steps 0-5
    with pytest.raises(SystemExit, match="bad --band"):
        mod.main([str(logs[1]), "--band", "0"])
    with pytest.raises(SystemExit, match="error: .*missing.mcap"):
        mod.main([str(out / "missing.mcap")])
