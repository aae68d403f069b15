"""/fields deltas: stored as XOR against the previous step, read back bit for bit, also from a cut-off file."""

from __future__ import annotations

import numpy as np

from dynactivegs import records
from recorder.codec import decode_fields_delta, encode_fields_delta
from recorder.mcap_log import FIELDS_FULL_EVERY, LogWriter, run_metadata
from replay.source import LogReader


def _fields(k: int, shape: tuple[int, int, int], rng: np.random.Generator, prev: records.FieldsOut | None):
    if prev is None or prev.u_s.shape != shape:
        base = [np.zeros(shape, np.float32) for _ in range(3)]
        vis = np.zeros(shape, bool)
    else:
        base = [prev.u_s.copy(), prev.u_m.copy(), prev.n_obs.copy()]
        vis = prev.visible.copy()
    box = tuple(slice(k % 3, k % 3 + 2) for _ in range(3))          # only a small box changes per step
    for g in base:
        g[box] = rng.random(g[box].shape, np.float32) * 3 - 1
    base[0][0, 0, 0] = np.nan if k % 4 == 0 else -0.0                # NaN and -0.0 survive
    vis[box] = ~vis[box]
    return records.FieldsOut(np.array([-1.0, 0.5, 0.0]), 0.1, base[0], base[1], base[2], vis)


def _bits_equal(a: records.FieldsOut, b: records.FieldsOut) -> bool:
    return all(np.array_equal(np.ascontiguousarray(getattr(a, n)).view(np.uint8),
                              np.ascontiguousarray(getattr(b, n)).view(np.uint8))
               for n in ("origin_m", "u_s", "u_m", "n_obs", "visible")) and a.voxel_m == b.voxel_m


def test_delta_round_trip_is_bit_exact_and_small():
    rng = np.random.default_rng(0)
    prev = _fields(0, (20, 16, 8), rng, None)
    cur = _fields(1, (20, 16, 8), rng, prev)
    data = encode_fields_delta(cur, prev)
    assert _bits_equal(decode_fields_delta(data, prev), cur)


def test_log_with_deltas_reads_back_every_step_exactly_even_when_cut(tmp_path):
    rng = np.random.default_rng(1)
    written, prev = [], None
    path = tmp_path / "f.mcap"
    n = FIELDS_FULL_EVERY + 12
    with LogWriter(path, run_metadata({}, 0)) as w:
        for k in range(n):
            shape = (20, 16, 8) if k < 7 else (24, 16, 8)          # the grid grows at step 7
            prev = _fields(k, shape, rng, prev)
            written.append(prev)
            w.write("/fields", prev, k)
            w.end_step(k, k)
        offsets = list(w.step_end_offsets)
    steps = LogReader(path).read_all()
    assert len(steps) == n
    assert all(_bits_equal(s["/fields"], f) for s, f in zip(steps, written))
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: offsets[30] + 5])
    reader = LogReader(cut)
    got = reader.read_all()
    assert len(got) == 31 and _bits_equal(got[-1]["/fields"], written[30])
    assert "log ends after step 30" in reader.end.describe()


def test_deltas_make_the_log_smaller(tmp_path):
    rng = np.random.default_rng(2)
    prev = None
    with LogWriter(tmp_path / "f.mcap", run_metadata({}, 0)) as w:
        for k in range(10):
            prev = _fields(k, (40, 40, 16), rng, prev)
            w.write("/fields", prev, k)
            w.end_step(k, k)
    steps = LogReader(tmp_path / "f.mcap").read_all()
    whole = len(steps[0].raw["/fields"])
    assert (tmp_path / "f.mcap").stat().st_size < 3 * whole     # 10 steps in the space of 3 whole grids


def test_delta_across_a_grid_that_grew_around_the_previous_one_is_bit_exact():
    rng = np.random.default_rng(3)
    prev = _fields(0, (6, 5, 4), rng, None)
    grids = []
    for g in (prev.u_s, prev.u_m, prev.n_obs):
        big = rng.random((9, 7, 4), np.float32)                 # new voxels hold new values
        big[2:8, 1:6, 0:4] = g                                  # the old grid, 2 and 1 voxels in
        grids.append(big)
    vis = np.zeros((9, 7, 4), bool)
    vis[2:8, 1:6] = prev.visible
    cur = records.FieldsOut(prev.origin_m - np.array([0.2, 0.1, 0.0]), 0.1, *grids, vis)
    from recorder.codec import fields_delta_applies
    assert fields_delta_applies(cur, prev)
    assert _bits_equal(decode_fields_delta(encode_fields_delta(cur, prev), prev), cur)
    shifted = records.FieldsOut(prev.origin_m + 0.05, 0.1, *grids, vis)    # half a voxel off: no delta
    assert not fields_delta_applies(shifted, prev)
