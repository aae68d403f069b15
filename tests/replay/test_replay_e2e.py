"""dagsrun --record -> dagsreplay on the tiny scene: identical re-runs, truncated and tampered logs, what-if runs."""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from dynactivegs.pipeline import STAGE_NAMES
from recorder.cli import main as dagsrun
from recorder.mcap_log import LogWriter
from replay.cli import main as dagsreplay
from replay.source import LoggedStep, LogReader

STEPS = 8
SMALL = ["--scene", "tiny-00", "--steps", str(STEPS), "--no-eval", "--no-progress",
         "--set", "sim.camera.width_px=64", "sim.camera.height_px=40"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("run")
    rc = dagsrun([*SMALL, "--record", str(d / "run.mcap"), "--rrd", str(d / "run.rrd"), "--out", str(d),
                  "--map-every", "3"])
    assert rc == 0
    return {"log": d / "run.mcap", "rrd": d / "run.rrd", "dir": d}


def replay(capsys, *argv: str) -> tuple[int, str, str]:
    rc = dagsreplay([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_log_holds_every_step_with_every_topic_and_map_snapshots(recorded):
    reader = LogReader(recorded["log"])
    steps = reader.read_all()
    assert [s.step for s in steps] == list(range(STEPS)) and reader.end.complete
    for s in steps:
        assert {"/frame", "/truth", "/metrics", "/perception", "/mapping", "/fields", "/selection",
                "/planning"} <= set(s.topics)
    assert [s.step for s in steps if "/map" in s] == [3, 6, 7]          # every 3 steps and the last
    assert len(steps[-1]["/map"]) == steps[-1]["/mapping"].n_gaussians
    assert reader.metadata["preset"] == "full" and '"width_px": 64' in reader.config_json


@pytest.mark.parametrize("stage", STAGE_NAMES)
def test_replay_from_each_stage_is_identical(recorded, capsys, stage):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", stage)
    assert rc == 0, out + err
    assert f"replayed {stage} and after on steps 0..{STEPS - 1}" in out and "identical to the log" in out
    refined = f"/map_refined (the refinement re-run after step {STEPS - 1})" in out
    assert refined == (stage in ("perception", "mapping")), out


def test_log_holds_the_refined_map_after_its_last_step(recorded):
    reader = LogReader(recorded["log"])
    last = reader.read_all()[-1]
    refined = reader.refined_map()
    assert refined is not None and len(refined) > 0
    assert not all(np.array_equal(a.numpy(), b.numpy()) for a, b in zip(refined.tensors(), last["/map"].tensors()))


def test_tampered_refined_map_fails_naming_the_parameter(recorded, capsys, tmp_path):
    reader = LogReader(recorded["log"])
    bad = tmp_path / "tampered_refined.mcap"
    with LogWriter(bad, reader.metadata) as w:
        last_stamp = _copy_steps(reader, w)
        g = reader.refined_map()
        g.sh0[3, 1] += 0.25
        w.write_refined_map(g, last_stamp + 1)
    rc, out, err = replay(capsys, bad, "--from-stage", "mapping")
    assert rc == 1, out + err
    assert f"step {STEPS - 1}, topic /map_refined, field sh0, max abs diff 0.25" in out, out
    rc, out, err = replay(capsys, bad, "--from-stage", "mapping", "--to-step", str(STEPS - 2))
    assert rc == 0, out + err                  # a replay that stops before the last step does not refine


def test_what_if_refinement_reports_its_map_size(recorded, capsys):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", "mapping", "--set", "mapping.refine_passes=0")
    assert rc == 0, out + err
    reader = LogReader(recorded["log"])
    n_last = reader.read_all()[-1]["/mapping"].n_gaussians
    assert f"Gaussians after the refinement: {len(reader.refined_map())} logged, {n_last} replayed" in out, out


def test_refinement_with_the_final_mlp_is_re_run_only_with_perception(tmp_path, capsys):
    log = tmp_path / "final.mcap"
    assert dagsrun([*SMALL, "--record", str(log), "--out", str(tmp_path), "--set", "mapping.refine_beta=final"]) == 0
    rc, out, err = replay(capsys, log, "--from-stage", "perception")
    assert rc == 0 and "identical to the log" in out and "/map_refined (the refinement re-run" in out, out + err
    # from mapping on, the perception stage's final MLP is not there: the logged refined map is kept as it is
    rc, out, err = replay(capsys, log, "--from-stage", "mapping")
    assert rc == 0 and "identical to the log" in out and "/map_refined" not in out, out + err


def test_replay_from_a_later_step_fast_forwards(recorded, capsys):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", "mapping", "--from-step", "5", "--to-step", "6")
    assert rc == 0, out + err
    assert "steps 5..6 (steps 0..4 fast-forwarded)" in out


def test_log_cut_at_a_random_byte_replays_its_whole_steps_and_says_where_it_ends(recorded, capsys, tmp_path):
    full = recorded["log"].read_bytes()
    ends = [s.end_offset for s in LogReader(recorded["log"]).steps()]
    rng = np.random.default_rng(7)
    for cut in rng.integers(ends[0], ends[-1], size=2):
        whole = sum(e <= cut for e in ends)
        part = tmp_path / f"cut_{cut}.mcap"
        part.write_bytes(full[:cut])
        rc, out, err = replay(capsys, part, "--from-stage", "fields")
        assert rc == 0, out + err
        assert f"steps 0..{whole - 1}:" in out, out
        assert f"log ends after step {whole - 1} (truncated at byte {cut})" in out, out


def test_what_if_replay_reports_changes_and_exits_0(recorded, capsys):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", "selection", "--set", "selection.variant=random")
    assert rc == 0, out + err
    assert "what-if: selection.variant=random (was full)" in out
    n = int(out.split("selection target differs at ")[1].split(" of ")[0])
    assert 0 < n <= STEPS, out
    assert "/planning differs at" in out and "actions differ at" in out


def test_what_if_motion_weight_reports_path_lengths(recorded, capsys):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", "planning", "--set",
                          "planning.path.motion_weight=0")
    assert rc == 0, out + err
    assert "planning.path.motion_weight=0 (was" in out and "planned path length" in out


def _copy_steps(reader: LogReader, w: LogWriter, edit: Callable[[LoggedStep, str], bool] | None = None) -> int:
    """Copy every step of ``reader`` to ``w``; ``edit(step, topic)`` may write a message itself (returns True)
    instead of the copy. Returns the last step's stamp."""
    for ls in reader.steps():
        for topic in sorted(t for t in ls.raw if t != "/step_end"):
            if edit is None or not edit(ls, topic):
                w.write_raw(topic, "x", ls.raw[topic], ls.stamp_ns)
        w.end_step(ls.step, ls.stamp_ns)
    return ls.stamp_ns


def _tamper(src: Path, dst: Path, step: int) -> int:
    """Copy the log, changing the action of ``step``'s /planning; returns the new action."""
    reader = LogReader(src)
    new_action = None

    def edit(ls: LoggedStep, topic: str) -> bool:
        nonlocal new_action
        if topic != "/planning" or ls.step != step:
            return False
        p = ls[topic]
        new_action = (p.action + 1) % 4
        w.write(topic, dataclasses.replace(p, action=new_action), ls.stamp_ns)
        return True

    with LogWriter(dst, reader.metadata) as w:
        _copy_steps(reader, w, edit)
    return new_action


@pytest.mark.parametrize("stage", ["selection", "planning"])
def test_tampered_output_fails_with_its_step_and_topic(recorded, capsys, tmp_path, stage):
    bad = tmp_path / "tampered.mcap"
    _tamper(recorded["log"], bad, step=4)
    rc, out, err = replay(capsys, bad, "--from-stage", stage)
    assert rc == 1, out + err
    assert "step 4, topic /planning, field action, max abs diff" in out, out
    assert "another machine" not in out                     # recorded here


def test_a_difference_in_a_log_from_another_machine_says_so(recorded, capsys, tmp_path, monkeypatch):
    import replay.engine as engine

    bad = tmp_path / "tampered.mcap"
    _tamper(recorded["log"], bad, step=4)
    here = engine.machine_info()
    assert LogReader(bad).metadata["machine.id"] == here["id"]
    monkeypatch.setattr(engine, "machine_info", lambda: {**here, "isa": "AVX9", "id": "0123456789"})
    rc, out, err = replay(capsys, bad, "--from-stage", "planning")
    assert rc == 1, out + err
    assert f"recorded on another machine (isa {here['isa']} there, AVX9 here)" in out, out


def test_replayed_run_can_be_recorded_and_viewed(recorded, capsys, tmp_path):
    rc, out, err = replay(capsys, recorded["log"], "--from-stage", "fields", "--record", tmp_path / "re.mcap",
                          "--rrd", tmp_path / "re.rrd")
    assert rc == 0, out + err
    assert LogReader(tmp_path / "re.mcap").refined_map() is not None      # copied from the log it replayed
    rc, out, err = replay(capsys, tmp_path / "re.mcap")
    assert rc == 0, out + err
    assert "/map_refined (the refinement re-run" in out, out
    verify = subprocess.run([shutil.which("rerun") or "rerun", "rrd", "verify", str(tmp_path / "re.rrd")],
                            capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr


def test_rrd_of_a_real_run_passes_rerun_verify(recorded):
    assert recorded["rrd"].stat().st_size > 10_000
    verify = subprocess.run([shutil.which("rerun") or "rerun", "rrd", "verify", str(recorded["rrd"])],
                            capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr


def test_bad_input_is_one_line_exit_2(recorded, capsys, tmp_path, monkeypatch):
    corrupt = tmp_path / "corrupt.mcap"
    data = bytearray(recorded["log"].read_bytes())
    ends = [s.end_offset for s in LogReader(recorded["log"]).steps()]
    data[ends[1] + 40: ends[1] + 80] = b"\xff" * 40
    corrupt.write_bytes(bytes(data))
    (tmp_path / "text.mcap").write_text("hello")

    import recorder.mcap_log

    monkeypatch.setattr(recorder.mcap_log, "SCHEMA_VERSION", 99)
    newer = tmp_path / "newer.mcap"
    with LogWriter(newer, LogReader(recorded["log"]).metadata):
        pass
    monkeypatch.undo()
    cases = [([recorded["log"], "--from-stage", "render"], "unknown stage 'render'"),
             ([tmp_path / "missing.mcap"], "log not found"),
             ([tmp_path / "text.mcap"], "not an MCAP file"),
             ([newer], "newer than this dynactivegs reads"),
             ([corrupt, "--from-stage", "planning"], "corrupt log"),
             ([recorded["log"], "--set", "planning.bogus=1"], "unknown config key 'planning.bogus'"),
             ([recorded["log"], "--from-step", "50"], "nothing to replay")]
    for argv, phrase in cases:
        rc, out, err = replay(capsys, *argv)
        assert rc == 2, (argv, out, err)
        assert len(err.strip().splitlines()) == 1 and phrase in err and err.startswith("dagsreplay: error:"), err


def test_a_target_reason_missing_from_an_older_log_is_not_a_difference(recorded):
    from replay.engine import compare_records
    sel = next(LogReader(recorded["log"]).steps())["/selection"]
    assert sel.target_reason in ("keep", "reached", "unreachable", "stuck", "timeout", "none")
    assert compare_records(sel, dataclasses.replace(sel, target_reason="")) is None
    assert compare_records(sel, dataclasses.replace(sel, target_reason="timeout" if sel.target_reason != "timeout"
                                                   else "keep"))[0] == "target_reason"
