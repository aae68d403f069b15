"""dagsrun from the command line: writes the pictures a newcomer looks at; bad input is one line."""

from __future__ import annotations

import cv2
import numpy as np

from recorder.cli import main


def test_dagsrun_writes_frames_contact_sheet_and_floorplan(tmp_path, capsys):
    rc = main(["--scene", "tiny-00", "--steps", "6", "--out", str(tmp_path), "--no-progress",
               "--sim.camera.width-px", "48", "--sim.camera.height-px", "28"])
    assert rc == 0
    for k in range(7):
        rgb = cv2.imread(str(tmp_path / "frames" / f"rgb_{k:04d}.png"))
        assert rgb is not None and rgb.shape == (28, 48, 3) and rgb.std() > 5
        assert cv2.imread(str(tmp_path / "frames" / f"depth_{k:04d}.png")) is not None
        assert cv2.imread(str(tmp_path / "frames" / f"people_{k:04d}.png"), cv2.IMREAD_UNCHANGED).dtype == np.uint8
    plan = cv2.imread(str(tmp_path / "floorplan.png"))
    assert plan is not None and plan.shape[0] > 200 and plan.std() > 10
    assert cv2.imread(str(tmp_path / "contact_sheet.png")) is not None
    out = capsys.readouterr().out
    assert "tiny-00: 6 steps" in out and "floor plan:" in out


def test_dagsrun_bad_input_is_one_line_exit_2(tmp_path, capsys):
    cases = [(["--scene", "castle-00"], "unknown scene"),
             (["--scene", str(tmp_path / "missing.glb")], "scene file not found"),
             (["--sim.camera.width-px", "2"], "camera.width_px"),
             (["--steps", "0"], "--steps")]
    for argv, phrase in cases:
        rc = main(argv + ["--out", str(tmp_path), "--no-progress"])
        err = capsys.readouterr().err.strip()
        assert rc == 2, argv
        assert len(err.splitlines()) == 1 and phrase in err and err.startswith("dagsrun: error:"), err


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
