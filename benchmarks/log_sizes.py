"""Bytes per step of an MCAP log, per topic, compressed the way the log compresses them.

    python benchmarks/log_sizes.py run.mcap

For each topic: mean message bytes as stored (msgpack; ``/fields`` mostly as deltas) and
after zstd (level 3, the mcap writer's default, one message at a time, close to its share
of the per-step chunk), and the file's total bytes per step.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections import defaultdict
from pathlib import Path

import zstandard

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def topic_sizes(path: Path) -> tuple[int, dict[str, tuple[float, float, int]]]:
    """(whole steps, {topic: (mean raw bytes, mean zstd bytes, messages)})."""
    raw: dict[str, list[int]] = defaultdict(list)
    comp: dict[str, list[int]] = defaultdict(list)
    z = zstandard.ZstdCompressor()
    n = 0
    from mcap.records import Channel, Chunk
    from mcap.stream_reader import StreamReader, breakup_chunk

    topics: dict[int, str] = {}
    with open(path, "rb") as f:
        for rec in StreamReader(f, emit_chunks=True).records:
            if not isinstance(rec, Chunk):
                continue
            for r in breakup_chunk(rec):
                if isinstance(r, Channel):
                    topics[r.id] = r.topic
                elif hasattr(r, "channel_id"):
                    t = topics[r.channel_id]
                    if t == "/step_end":
                        n += 1
                        continue
                    raw[t].append(len(r.data))
                    comp[t].append(len(z.compress(r.data)))
    return n, {t: (sum(raw[t]) / n, sum(comp[t]) / n, len(raw[t])) for t in sorted(raw)}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("log", type=Path)
    a = p.parse_args()
    n, sizes = topic_sizes(a.log)
    print(f"{a.log}: {n} steps, {os.path.getsize(a.log) / n / 1e3:.1f} kB/step in the file")
    print(f"{'topic':<12} {'msgs':>5} {'raw kB/step':>12} {'zstd kB/step':>13}")
    for t, (r, c, m) in sizes.items():
        print(f"{t:<12} {m:>5} {r / 1e3:>12.1f} {c / 1e3:>13.1f}")
    print(f"{'total':<12} {'':>5} {sum(v[0] for v in sizes.values()) / 1e3:>12.1f} "
          f"{sum(v[1] for v in sizes.values()) / 1e3:>13.1f}")


if __name__ == "__main__":
    main()
