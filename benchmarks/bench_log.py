"""Cost of recording: MCAP bytes per step, encode and write time per step, and the Rerun sink's time.

Records are synthetic but sized like the defaults (160x92 images; a 80x70x17 field grid;
200 graph nodes and 1000 candidates; 15k surface voxels). The field grid evolves like the
real one: each step changes only the voxels in view (~15 % of the grid), values are
non-round floats. Sizes after compression depend on content, so the per-topic table is
the thing to read, not only the total.

    python benchmarks/bench_log.py [--steps 30] [--rrd]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import zstandard

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))      # the synthetic records live in tests/

from dynactivegs import records
from recorder.codec import encode
from recorder.mcap_log import LogWriter, run_metadata
from tests.recorder.synthetic import step_records


class EvolvingFields:
    """A FieldsOut whose grids change only inside a moving view box, like the fields stage's."""

    def __init__(self, shape: tuple[int, int, int] = (80, 70, 17), seed: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.n_obs = np.zeros(shape, np.float32)
        self.e_res = np.ones(shape, np.float32)
        self.u_m = np.zeros(shape, np.float32)

    def step(self, k: int) -> records.FieldsOut:
        X, Y, Z = self.n_obs.shape
        x0, y0 = (5 * k) % (X - 28), (3 * k) % (Y - 24)
        view = (slice(x0, x0 + 28), slice(y0, y0 + 24), slice(1, Z - 1))
        visible = np.zeros(self.n_obs.shape, bool)
        visible[view] = True
        w = np.minimum(1.0, (0.3 / self.rng.uniform(0.1, 2.0, visible[view].shape)) ** 2).astype(np.float32)
        self.n_obs[view] += w
        self.e_res[view] += (0.3 * w * (self.rng.random(w.shape, np.float32) * 0.2 - self.e_res[view])).astype(np.float32)
        self.u_m[view] = 0.8 * self.u_m[view] + 0.2 * (self.rng.random(w.shape, np.float32) < 0.05) * 1.5
        u_s = (1.0 / np.sqrt(self.n_obs + 1.0) + np.clip(self.e_res, 0, 1)).astype(np.float32)
        return records.FieldsOut(np.array([-3.0, -3.0, 0.0]), 0.15, u_s, self.u_m.copy(), self.n_obs.copy(), visible)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--rrd", action="store_true", help="also time the Rerun sink")
    args = ap.parse_args()

    fields = EvolvingFields()
    steps = []
    for k in range(args.steps):
        recs = step_records(k)
        recs["/fields"] = fields.step(k)
        steps.append(recs)

    sizes: dict[str, list[tuple[int, int]]] = {t: [] for t in steps[0]}
    enc_s, write_s = [], []
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bench.mcap"
        w = LogWriter(path, run_metadata({"bench": True}, seed=0))
        header = w.bytes_written
        for k, recs in enumerate(steps):
            stamp = recs["/frame"].stamp_ns
            t0 = time.perf_counter()
            payloads = {topic: encode(rec) for topic, rec in recs.items()}
            t1 = time.perf_counter()
            for topic, rec in recs.items():
                w.write_raw(topic, type(rec).__name__, payloads[topic], stamp)
            w.end_step(k, stamp)
            t2 = time.perf_counter()
            enc_s.append(t1 - t0)
            write_s.append(t2 - t1)
            for topic, data in payloads.items():
                sizes[topic].append((len(data), len(zstandard.compress(data))))
        w.close()
        total = path.stat().st_size
        footer = total - w.step_end_offsets[-1]

        rrd_s = None
        if args.rrd:
            from recorder.rerun_sink import RerunSink

            with RerunSink(Path(d) / "bench.rrd") as sink:
                sink.log_records(steps[0])                     # imports and first-use setup
                t0 = time.perf_counter()
                for recs in steps[1:]:
                    sink.log_records(recs)
                rrd_s = (time.perf_counter() - t0) / max(1, len(steps) - 1)
            rrd_bytes = (Path(d) / "bench.rrd").stat().st_size

    n = len(steps)
    print(f"{n} steps, MCAP file {total / 1e6:.2f} MB: {(total - header - footer) / n / 1e3:.1f} KB per step "
          f"(+ {header / 1e3:.1f} KB header/metadata and {footer / 1e3:.1f} KB summary once)")
    print(f"encode {1e3 * np.median(enc_s):.2f} ms/step, write+flush {1e3 * np.median(write_s):.2f} ms/step "
          f"(median); total {1e3 * np.median(np.add(enc_s, write_s)):.2f} ms/step = "
          f"{100 * np.median(np.add(enc_s, write_s)) / 0.5:.1f} % of a 0.5 s step")
    print(f"{'topic':<12} {'raw KB':>8} {'zstd KB':>8}")
    for topic, s in sizes.items():
        raw, z = np.mean(s, axis=0)
        print(f"{topic:<12} {raw / 1e3:8.1f} {z / 1e3:8.1f}")
    if rrd_s is not None:
        print(f"rerun sink: {1e3 * rrd_s:.1f} ms/step, {rrd_bytes / n / 1e3:.1f} KB/step of .rrd")


if __name__ == "__main__":
    main()
