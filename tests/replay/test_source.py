"""MCAP logs: written step by step, read back whole steps only, also from files cut off anywhere."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import Writer

from dynactivegs.errors import DagsError
from recorder.codec import SCHEMA_VERSION, Metrics, encode
from recorder.mcap_log import LogWriter, run_metadata
from replay.source import LogReader
from tests.recorder.synthetic import all_record_types, step_records
from tests.recorder.test_codec import assert_identical

ROOT = Path(__file__).parents[2]
SMALL = {"w": 32, "h": 20, "grid": (10, 8, 5), "n_nodes": 12, "n_cand": 30, "n_surface": 200}


def write_log(path: Path, n_steps: int, *, close: bool = True, seed: int = 0) -> tuple[LogWriter, list[dict]]:
    steps = []
    w = LogWriter(path, run_metadata({"scene": "tiny-00", "lr": float("nan")}, seed=seed, preset="full"))
    for k in range(n_steps):
        recs = step_records(k, seed=seed, **SMALL)
        stamp = recs["/frame"].stamp_ns
        for topic, rec in recs.items():
            w.write(topic, rec, stamp)
        if k % 2 == 0:
            w.write_state("fields", {"k": k, "grid": np.full((2, 2), k, np.float32)}, stamp)
        steps.append(recs)
        w.end_step(k, stamp)
    if close:
        w.close({"coverage": "0.5"})
    return w, steps


def test_a_log_reads_back_every_step_and_its_metadata(tmp_path):
    path = tmp_path / "run.mcap"
    w, written = write_log(path, 4)
    r = LogReader(path)
    assert r.schema_version == SCHEMA_VERSION and r.seed == 0 and r.metadata["preset"] == "full"
    assert '"lr": "nan"' in r.config_json and "version.numpy" in r.metadata
    got = r.read_all()
    assert [s.step for s in got] == [0, 1, 2, 3]
    for s, recs in zip(got, written):
        assert s.stamp_ns == recs["/frame"].stamp_ns
        for topic, rec in recs.items():
            assert_identical(rec, s[topic], topic)
        assert ("/state/fields" in s) == (s.step % 2 == 0)
    assert got[2].state("fields")["k"] == 2
    rec = got[1].step_record(got[0]["/mapping"])
    assert rec.planning is not None and rec.prev_mapping is got[0]["/mapping"]
    assert r.end.complete and r.end.steps == 4 and r.end.last_step == 3
    assert r.end_metadata["coverage"] == "0.5" and r.end_metadata["steps"] == "4"
    assert r.end.describe() == "log complete: 4 steps, ends after step 3"
    assert [s.step for s in r.steps(start=1, stop=3)] == [1, 2]
    assert w.step_end_offsets[-1] < path.stat().st_size


def test_messages_of_an_unfinished_step_are_dropped(tmp_path):
    path = tmp_path / "run.mcap"
    w, written = write_log(path, 2, close=False)
    recs = step_records(2, **SMALL)
    w.write("/frame", recs["/frame"], recs["/frame"].stamp_ns)       # step 2 never ends
    w.close()
    r = LogReader(path)
    assert [s.step for s in r] == [0, 1] and r.end.complete


def test_a_log_cut_at_random_bytes_yields_exactly_its_whole_steps(tmp_path):
    path = tmp_path / "run.mcap"
    w, written = write_log(path, 5)
    data = path.read_bytes()
    chunk_ends = [s.end_offset for s in LogReader(path)]      # a step is whole once its chunk is
    assert all(c <= off for c, off in zip(chunk_ends, w.step_end_offsets))  # (message indexes follow it)
    rng = np.random.default_rng(6)
    cuts = sorted(set(rng.integers(0, len(data), 40).tolist()) | set(w.step_end_offsets) | {5, 30, 200})
    for cut in cuts:
        cut_path = tmp_path / f"cut_{cut}.mcap"
        cut_path.write_bytes(data[:cut])
        expected = sum(1 for off in chunk_ends if off <= cut)
        try:
            r = LogReader(cut_path)
        except DagsError as e:          # cut inside the magic or the metadata: nothing to replay
            phrase = "not an MCAP file" if cut < 8 else f"cut off before its first step (truncated at byte {cut})"
            assert phrase in str(e) and cut < w.step_end_offsets[0], (cut, e)
            continue
        got = [s.step for s in r]
        assert got == list(range(expected)), cut
        if cut < w.step_end_offsets[-1] or cut < len(data) - 8:
            assert not r.end.complete or cut >= len(data) - 8
        if not r.end.complete:
            where = f"after step {expected - 1}" if expected else "before its first whole step"
            assert r.end.describe() == f"log ends {where} (truncated at byte {cut})", cut
        for s in r.steps(start=max(0, expected - 1)):
            assert_identical(written[s.step]["/fields"], s["/fields"], "fields")


def test_a_killed_writer_leaves_a_log_of_whole_steps(tmp_path):
    path = tmp_path / "killed.mcap"
    code = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(ROOT)!r})
        from recorder.mcap_log import LogWriter
        from tests.recorder.synthetic import step_records
        w = LogWriter({str(path)!r}, {{"seed": "0"}})
        k = 0
        while True:
            recs = step_records(k, **{SMALL!r})
            for topic, rec in recs.items():
                w.write(topic, rec, recs["/frame"].stamp_ns)
                time.sleep(0.002)
            w.end_step(k, recs["/frame"].stamp_ns)
            print(k, flush=True)
            k += 1
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:
            if int(line) >= 3:
                break
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    r = LogReader(path)
    got = [s.step for s in r]
    assert len(got) >= 4 and got == list(range(len(got)))
    assert not r.end.complete and r.end.describe().startswith(f"log ends after step {got[-1]} (truncated at byte")
    assert all("/planning" in s for s in r)


def test_a_full_disk_ends_with_one_line_and_a_log_of_whole_steps(tmp_path):
    path = tmp_path / "full.mcap"
    limit = 60_000
    code = textwrap.dedent(f"""
        import resource, signal, sys
        sys.path.insert(0, {str(ROOT)!r})
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)      # writes past the limit fail with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
        from dynactivegs.errors import DagsError
        from recorder.mcap_log import LogWriter
        from tests.recorder.synthetic import step_records
        w = LogWriter({str(path)!r}, {{"seed": "0"}})
        try:
            for k in range(1000):
                recs = step_records(k, **{SMALL!r})
                for topic, rec in recs.items():
                    w.write(topic, rec, recs["/frame"].stamp_ns)
                w.end_step(k, recs["/frame"].stamp_ns)
        except DagsError as e:
            print(e)
            sys.exit(2)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    line = out.stdout.strip()
    assert "\n" not in line and line.startswith(f"could not write log {path}") and "keeps steps up to" in line, line
    kept = int(line.split("keeps steps up to ")[1].split()[0])
    r = LogReader(path)
    assert [s.step for s in r] == list(range(kept + 1))
    assert path.stat().st_size <= limit and r.end.truncated_at == path.stat().st_size


# ---------------------------------------------------------------------------------- bad files
def test_missing_empty_garbage_and_foreign_files_are_one_line_errors(tmp_path):
    cases = {"missing": (None, "log not found"),
             "empty": (b"", "not an MCAP file.*empty"),
             "garbage": (b"this is not a log at all" * 10, "not an MCAP file.*magic"),
             "dir": ("dir", "is not a file")}
    for name, (content, phrase) in cases.items():
        p = tmp_path / name
        if content == "dir":
            p.mkdir()
        elif content is not None:
            p.write_bytes(content)
        with pytest.raises(DagsError, match=phrase) as e:
            LogReader(p)
        assert "\n" not in str(e.value)
    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start()
        cid = w.register_channel("/x", "json", 0)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    with pytest.raises(DagsError, match="not a dynactivegs log"):
        LogReader(foreign)


def _foreign_log(path: Path, schema_version: int) -> None:
    """A log written with the plain mcap writer, as a newer dynactivegs would."""
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        w.add_metadata("dynactivegs", {"schema_version": str(schema_version)})
        w.finish()


def test_a_log_of_a_newer_schema_is_rejected(tmp_path):
    _foreign_log(tmp_path / "new.mcap", SCHEMA_VERSION + 1)
    with pytest.raises(DagsError, match=f"schema version {SCHEMA_VERSION + 1}, newer than this dynactivegs reads"):
        LogReader(tmp_path / "new.mcap")


def test_corruption_inside_the_file_is_a_one_line_error_not_a_short_log(tmp_path):
    path = tmp_path / "run.mcap"
    w, _ = write_log(path, 4)
    data = bytearray(path.read_bytes())
    mid = (w.step_end_offsets[1] + w.step_end_offsets[2]) // 2       # inside step 2's chunk
    data[mid:mid + 16] = bytes(16)
    path.write_bytes(bytes(data))
    r = LogReader(path)
    with pytest.raises(DagsError, match="corrupt log") as e:
        list(r)
    assert "\n" not in str(e.value)


def test_writer_checks_topics_and_types(tmp_path):
    w = LogWriter(tmp_path / "run.mcap", {"seed": "1"})
    recs = step_records(0, **SMALL)
    with pytest.raises(ValueError, match="unknown record topic"):
        w.write("/castle", recs["/frame"], 0)
    with pytest.raises(TypeError, match="carries Frame"):
        w.write("/frame", recs["/truth"], 0)
    w.write("/frame", recs["/frame"], 5)
    with pytest.raises(ValueError, match="written twice"):
        w.write("/frame", recs["/frame"], 5)
    w.write_metrics(0, {"loss": np.float32(0.5)}, 5)
    w.end_step(0, 5)
    w.close()
    s = LogReader(tmp_path / "run.mcap").read_all()[0]
    assert s["/metrics"] == Metrics(0, {"loss": 0.5})
    with pytest.raises(TypeError):
        LogWriter(tmp_path / "bad.mcap", {"seed": 1})   # type: ignore[dict-item]


def test_a_log_in_an_unwritable_place_is_a_one_line_error(tmp_path):
    (tmp_path / "file").write_text("x")
    with pytest.raises(DagsError, match="cannot create log"):
        LogWriter(tmp_path / "file" / "run.mcap", {})


def test_every_record_type_goes_through_a_log(tmp_path):
    path = tmp_path / "types.mcap"
    recs = {r for r in map(type, all_record_types())}
    assert len(recs) >= 9
    with LogWriter(path, {}) as w:
        for k, ec in enumerate((False, True)):
            for topic, rec in step_records(k, edge_cases=ec, **SMALL).items():
                w.write(topic, rec, 10 + k)
            w.end_step(k, 10 + k)
    got = LogReader(path).read_all()
    for s, ec in zip(got, (False, True)):
        for topic, rec in step_records(s.step, edge_cases=ec, **SMALL).items():
            assert_identical(rec, s[topic], topic)
            assert s.raw[topic] == encode(rec)


def test_the_refined_map_is_read_outside_the_steps_and_a_cut_before_it_loses_only_it(tmp_path):
    path = tmp_path / "run.mcap"
    w, written = write_log(path, 3, close=False)
    assert LogReader(path).refined_map() is None                   # no refinement (yet)
    refined = {"means": np.arange(12, dtype=np.float32).reshape(4, 3)}
    with pytest.raises(ValueError, match="end the step"):
        w.write("/frame", written[0]["/frame"], 1)
        w.write_refined_map(refined, 1)
    w._step_topics.clear()
    w.write_refined_map(refined, written[-1]["/frame"].stamp_ns + 1)
    w.close()
    r = LogReader(path)
    assert [s.step for s in r.steps()] == [0, 1, 2]               # it belongs to no step
    assert np.array_equal(r.refined_map()["means"], refined["means"])
    assert np.array_equal(LogReader(path).refined_map()["means"], refined["means"])   # reads through by itself
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[:w.step_end_offsets[-1] + 40])   # killed while writing the refined map
    r = LogReader(cut)
    assert [s.step for s in r.steps()] == [0, 1, 2] and r.refined_map() is None
