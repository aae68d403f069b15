"""docs/log_schema.md: its reading example runs on a real log, and it documents every record field."""

from __future__ import annotations

import dataclasses
import re
import subprocess
import sys
from pathlib import Path

from recorder.codec import RECORD_TYPES, SCHEMA_VERSION
from tests.replay.test_source import write_log

DOC = Path(__file__).parents[2] / "docs" / "log_schema.md"


def test_the_plain_mcap_example_reads_our_log(tmp_path):
    text = DOC.read_text()
    block = text.split("<!-- example: read_log", 1)[1]
    code = re.search(r"```python\n(.*?)```", block, flags=re.S).group(1)
    assert len(code.strip().splitlines()) <= 20
    script = tmp_path / "read_log.py"
    script.write_text(code)
    _, steps = write_log(tmp_path / "run.mcap", 3)
    out = subprocess.run([sys.executable, str(script), str(tmp_path / "run.mcap")], capture_output=True, text=True,
                         timeout=60, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 3
    for line, recs in zip(lines, steps):
        f = recs["/frame"]
        assert line == f"{f.step} {f.stamp_ns} {f.depth_m.shape} {float(f.depth_m.max())}"


def test_every_record_field_and_the_version_are_documented():
    text = DOC.read_text()
    assert f"schema version {SCHEMA_VERSION})" in text
    for name, cls in RECORD_TYPES.items():
        if name in ("StepRecord", "RobotPose2D"):
            continue                         # StepRecord is not logged; RobotPose2D is listed inside SimTruth
        section = text.split(f"### {name} ", 1)[1].split("\n### ", 1)[0]
        for f in dataclasses.fields(cls):
            assert f"`{f.name}`" in section, f"{name}.{f.name} is not in docs/log_schema.md"
