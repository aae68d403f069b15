"""The Rerun sink writes .rrd files that rerun itself accepts, without touching the global recording."""

from __future__ import annotations

import dataclasses
import shutil
import subprocess
import sys

import numpy as np
import rerun as rr
import torch

from dynactivegs.splat.gaussians import Gaussians
from recorder.codec import Metrics
from recorder.rerun_sink import RerunSink, _target_label, colormap, label_colors
from tests.recorder.synthetic import all_record_types, step_records

SMALL = {"w": 48, "h": 28, "grid": (12, 10, 5), "n_nodes": 15, "n_cand": 40, "n_surface": 300}


def _rerun_cli() -> list[str]:
    exe = shutil.which("rerun")
    return [exe] if exe else [sys.executable, "-m", "rerun"]


def test_rrd_of_a_run_passes_rerun_rrd_verify(tmp_path):
    path = tmp_path / "run.rrd"
    g = torch.Generator().manual_seed(0)
    gaussians = Gaussians.from_params(torch.rand(500, 3, generator=g) * 4, torch.full((500, 3), 0.02),
                                      torch.tensor([[1.0, 0, 0, 0]]).repeat(500, 1), torch.full((500,), 0.9),
                                      torch.rand(500, 3, generator=g))
    occupancy = (np.linspace(-3, 3, 20 * 30, dtype=np.float32).reshape(20, 30), np.array([-1.0, -1.5]), 0.1)
    with RerunSink(path, max_map_points=200, max_voxels=100) as sink:
        for k in range(4):
            recs = step_records(k, edge_cases=(k == 2), **SMALL)
            if k == 3:
                sink.log_step(recs["/frame"], truth=recs["/truth"], perception=recs["/perception"],
                              mapping=recs["/mapping"], fields=recs["/fields"], selection=recs["/selection"],
                              planning=recs["/planning"], gaussians=gaussians, occupancy=occupancy,
                              metrics={"psnr": 21.5, "coverage": 0.4})
            else:
                sink.log_records(recs)
    assert rr.get_global_data_recording() is None
    out = subprocess.run([*_rerun_cli(), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "1 file verified without error" in out.stderr + out.stdout


def test_a_caller_owned_stream_gets_the_steps(tmp_path):
    rec = rr.RecordingStream("dynactivegs-test")
    path = tmp_path / "own.rrd"
    rec.save(path)
    sink = RerunSink(rec)
    recs = step_records(0, **SMALL)
    sink.log_records({"/frame": recs["/frame"], "/metrics": Metrics(0, {"loss": 1.0})})
    sink.close()
    rec.disconnect()
    assert path.stat().st_size > 10_000       # the image is in it
    assert rr.get_global_data_recording() is None


def test_colour_helpers():
    c = colormap(np.array([0.0, 0.5, 1.0, np.nan]), 0.0, 1.0)
    assert c.dtype == np.uint8 and c.shape == (4, 3) and (c[3] == 128).all() and not (c[0] == c[2]).all()
    lc = label_colors(np.array([0, 1, 0, -1]))
    assert (lc[0] == lc[2]).all() and not (lc[0] == lc[1]).all() and (lc[3] == 160).all()


def test_the_target_label_says_what_became_of_the_previous_target_when_it_changed():
    sel = next(r for r in all_record_types() if type(r).__name__ == "SelectionOut")
    assert _target_label(dataclasses.replace(sel, mode="global", target_reason="stuck")) == "global (previous stuck)"
    assert _target_label(dataclasses.replace(sel, mode="local", target_reason="none")) == "local"
    assert _target_label(dataclasses.replace(sel, mode="keep", target_reason="keep")) == "keep"
