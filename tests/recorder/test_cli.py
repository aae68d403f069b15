"""dagsrun from the command line: a closed-loop run with its summary and log; bad input is one line."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

from recorder.cli import main
from replay.source import LogReader

SMALL = ["--scene", "tiny-00", "--no-progress", "--set", "sim.camera.width_px=48", "sim.camera.height_px=28"]


def test_dagsrun_runs_the_loop_and_prints_metrics_and_paths(tmp_path, capsys):
    rc = main([*SMALL, "--steps", "6", "--out", str(tmp_path), "--record", str(tmp_path / "run.mcap"),
               "--preset", "baseline", "--seed", "3"])
    assert rc == 0
    out = capsys.readouterr().out
    assert "tiny-00: 6 steps in" in out and "Gaussians" in out and "m^2 of floor known" in out
    assert "map (after 6 refinement steps, " in out and " s): Acc" in out and "C.R." in out and "PSNR" in out
    assert f"log:     {tmp_path / 'run.mcap'}" in out and "summary:" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["steps"] == 6 and summary["config"]["seed"] == 3 and not summary["config"]["mapping"]["weighted"]
    assert summary["map_metrics"]["cr_pct"] >= 0 and summary["last_step_metrics"]["n_gaussians"] > 0
    reader = LogReader(tmp_path / "run.mcap")
    assert len(reader.read_all()) == 6 and reader.end.complete and reader.metadata["preset"] == "baseline"
    # 3 passes over the keyframes of steps 0 and 3; the refined map is the one the summary measured
    assert len(reader.refined_map()) == len(reader.read_all()[-1]["/map"]) > 0


def test_dagsrun_without_refinement_logs_no_refined_map(tmp_path, capsys):
    assert main([*SMALL, "mapping.refine_passes=0", "--steps", "4", "--out", str(tmp_path), "--record",
                 str(tmp_path / "run.mcap")]) == 0
    assert "map (as the last step left it): Acc" in capsys.readouterr().out
    assert LogReader(tmp_path / "run.mcap").refined_map() is None


def test_dagsrun_bad_input_is_one_line_exit_2(tmp_path, capsys):
    import torch

    cases = [(["--scene", "castle-00"], "unknown scene"),
             (["--scene", str(tmp_path / "missing.glb")], "scene file not found"),
             (["--preset", "best"], "unknown preset 'best'"),
             (["--set", "mapping.bogus=1"], "unknown config key 'mapping.bogus'"),
             (["--set", "mapping.weighted=maybe"], "bad value for mapping.weighted"),
             (["--set", "sim.camera.width_px=2"], "camera.width_px"),
             (["--set", "sim.robot.turn_step_deg=15"], "planning.actions.turn_step_deg=10.0: must be =="),
             (["--steps", "0"], "--steps")]
    if not torch.cuda.is_available():
        cases.append((["--device", "cuda"], "--device cuda: no CUDA device"))
    for argv, phrase in cases:
        steps = [] if argv[0] == "--steps" else ["--steps", "2"]
        rc = main(argv + steps + ["--out", str(tmp_path), "--no-progress", "--no-eval"])
        err = capsys.readouterr().err.strip()
        assert rc == 2, argv
        assert len(err.splitlines()) == 1 and phrase in err and err.startswith("dagsrun: error:"), err


def test_settings_the_stages_copy_from_the_robot_must_agree_with_it():
    """A copy equal where it must be, a more cautious one allowed, a changed original alone refused naming both keys
    and the values to set; set together they pass, and the pipeline refuses a config built around the check."""
    import dataclasses

    import pytest

    from dynactivegs.config import PRESETS, check_consistent, preset, with_overrides
    from dynactivegs.errors import ConfigError
    from dynactivegs.pipeline import init_states

    for name in PRESETS:
        assert check_consistent(preset(name)) is preset(name)
    cfg = preset("full")
    moved = with_overrides(cfg, ["sim.robot.turn_step_deg=15", "planning.actions.turn_step_deg=15"])
    assert moved.planning.actions.turn_step_deg == 15.0
    assert with_overrides(cfg, ["planning.actions.radius_m=0.25"]).planning.actions.radius_m == 0.25   # a margin
    with pytest.raises(ConfigError, match=r"selection.voronoi.robot_radius_m=0.1: must be >= sim.robot.radius_m "
                                          r"\(0.18\).* --set sim.robot.radius_m=0.18 planning.actions.radius_m=0.18 "
                                          r"selection.voronoi.robot_radius_m=0.18$"):
        with_overrides(cfg, ["selection.voronoi.robot_radius_m=0.1"])
    with pytest.raises(ConfigError, match=r"planning.actions.target_tol_m=0.4: must be <= selection.reach_tol_m"):
        with_overrides(cfg, ["planning.actions.target_tol_m=0.4"])
    with pytest.raises(ConfigError, match=r"planning.actions.stuck_steps=40: must be == selection.stuck_steps \(60\)"):
        with_overrides(cfg, ["selection.stuck_steps=60"])
    built = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, camera=dataclasses.replace(cfg.sim.camera,
                                                                                                height_m=1.0)))
    with pytest.raises(ConfigError, match="selection.visibility.camera_height_m"):
        init_states(built)


def test_ctrl_c_stops_after_a_whole_step_and_the_log_replays(tmp_path):
    log = tmp_path / "run.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "recorder.cli", *SMALL, "--steps", "500", "--no-eval",
                             "--record", str(log), "--out", str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not log.exists() or log.stat().st_size < 60_000):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "stopped by Ctrl-C after" in out
    reader = LogReader(log)
    steps = reader.read_all()
    assert reader.end.complete and 0 < len(steps) < 500
    from replay.cli import main as dagsreplay

    assert dagsreplay([str(log), "--from-stage", "fields"]) == 0


def test_every_console_script_resolves_to_a_callable():
    import importlib
    import re
    from pathlib import Path

    text = (Path(__file__).parents[2] / "pyproject.toml").read_text()
    section = text.split("[project.scripts]", 1)[1].split("\n[", 1)[0]
    scripts = dict(re.findall(r'^(\S+) = "([^"]+)"', section, flags=re.M))
    assert {"dagsrun", "dagsreplay"} <= set(scripts)
    for name, target in scripts.items():
        module, func = target.split(":")
        assert callable(getattr(importlib.import_module(module), func)), name


def test_core_package_does_not_import_mcap_rerun_recorder_or_replay():
    import subprocess
    import sys

    code = ("import sys, dynactivegs, dynactivegs.sim.world, dynactivegs.splat.render, dynactivegs.perception.uncertainty, "
            "dynactivegs.selection.voronoi, dynactivegs.planning.paths; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('mcap', 'rerun', 'recorder', 'replay')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]", out


def test_ctrl_c_during_the_refinement_keeps_every_step_and_no_refined_map(tmp_path, monkeypatch):
    from dynactivegs import pipeline
    from recorder import live
    from recorder.cli import build_config, parser

    cfg = build_config(parser().parse_args([*SMALL]))
    stop = {"asked": True}                                  # Ctrl-C was pressed: the first Adam step stops it
    states = pipeline.run(cfg, 4).states
    with pytest.raises(live._Stop):
        live._refine(cfg, live._Fanout([], states=states), stop, False)

    def interrupted(*a, **k):
        raise live._Stop
    monkeypatch.setattr(pipeline, "refine_map", interrupted)
    res = live.record_run(cfg, 4, record=tmp_path / "run.mcap", progress=False, handle_sigint=False)
    assert res.interrupted and res.refine_iters == 0 and res.steps == 4
    reader = LogReader(tmp_path / "run.mcap")
    assert [s.step for s in reader.steps()] == [0, 1, 2, 3] and reader.end.complete
    assert reader.refined_map() is None and reader.end_metadata["interrupted"] == "true"
