"""Writing a run to an MCAP log, one whole step at a time.

The log is the run's source of truth (DESIGN.md §7). Layout (details in ``docs/log_schema.md``):

- a metadata record ``dynactivegs`` at the start: schema version, resolved config (JSON),
  seed, package versions and whatever else the caller passes;
- per step, one zstd-compressed chunk holding the step's messages on their topics
  (:data:`TOPICS`, ``/state/<stage>`` snapshots, ``/map``) and, last, a ``/step_end``
  marker; log and publish times are the frame's ``stamp_ns``;
- on a clean close, a metadata record ``dynactivegs.end`` and the MCAP summary.

Each step's chunk is written with one ``os.write`` loop and no user-space buffering at
:meth:`LogWriter.end_step`, so whatever stops the process (Ctrl-C, a crash, SIGKILL) leaves
a file whose every whole step is readable (:class:`replay.source.LogReader` stops at the
last ``/step_end``). A failed write (a full disk) cuts the file back to the end of the last
whole step and raises a one-line :class:`~dynactivegs.errors.DagsError`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import platform
from collections.abc import Mapping
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from dynactivegs import records
from dynactivegs.errors import DagsError
from recorder.codec import (MESSAGE_ENCODING, SCHEMA_VERSION, Metrics, StepEnd, encode, encode_fields_delta,
                           encode_state, fields_delta_applies)

TOPICS: dict[str, type] = {
    "/frame": records.Frame,
    "/truth": records.SimTruth,
    "/perception": records.PerceptionOut,
    "/mapping": records.MappingOut,
    "/fields": records.FieldsOut,
    "/selection": records.SelectionOut,
    "/planning": records.PlanningOut,
    "/metrics": Metrics,
    "/step_end": StepEnd,
}
"""The record topics and the record type each carries. ``/truth`` is for evaluation and viewers only."""

FIELDS_DELTA_NAME = "FieldsDelta"

STATE_TOPIC_PREFIX = "/state/"
"""``/state/<stage>``: a state snapshot (:func:`recorder.codec.encode_state`) of that stage."""

MAP_TOPIC = "/map"
"""An occasional snapshot of the Gaussian map (a state snapshot of a ``Gaussians`` object)."""
REFINED_MAP_TOPIC = "/map_refined"
"""The map after the offline refinement, written once after the last step, in a chunk of its own and outside any
step (no ``/step_end``); :meth:`replay.source.LogReader.refined_map` reads it."""

STAGE_TOPICS: dict[str, str] = {"perception": "/perception", "mapping": "/mapping", "fields": "/fields",
                                "selection": "/selection", "planning": "/planning"}
"""The output topic of each pipeline stage, by stage name (the ``StepRecord`` field)."""

METADATA_NAME = "dynactivegs"
"""Name of the metadata record written when the log is opened."""

END_METADATA_NAME = "dynactivegs.end"
"""Name of the metadata record written when the log is closed cleanly."""

CHUNK_SIZE = 256 * 2 ** 20
"""Chunks close at step ends, not by size: a step larger than this is split (harmlessly) in two."""

FIELDS_FULL_EVERY = 50
"""``/fields`` is written whole at least every this many steps (and when the grid does not contain the previous one), else as a delta."""

VERSIONED_PACKAGES = ("dynactivegs", "numpy", "scipy", "torch", "mcap", "msgpack", "zstandard", "rerun-sdk",
                      "gsplat", "trimesh", "networkx")


def package_versions(names: tuple[str, ...] = VERSIONED_PACKAGES) -> dict[str, str]:
    """Installed versions of Python and of ``names``, by default the packages a run's results depend on (missing
    ones are left out)."""
    out = {"python": platform.python_version()}
    for name in names:
        try:
            out[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            pass
    return out


MACHINE_PACKAGES = ("numpy", "scipy", "torch", "numba", "llvmlite", "embreex", "trimesh", "networkx", "kornia",
                    "opencv-python-headless", "gsplat")
"""The numeric libraries whose versions go into :func:`machine_info`'s ``id``."""


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def machine_info() -> dict[str, str]:
    """What a run's bits depend on besides the code, the config and the seed (all strings).

    ``cpu`` (model name), ``isa`` (the instruction set torch's CPU kernels dispatch to: AVX2, AVX512, ...),
    ``llvm_cpu`` (the CPU numba compiles its kernels for), ``cores`` (recorded, not part of the id: the
    rasteriser's kernels give the same bits on any thread count), and ``id``, a short hash of cpu, isa,
    llvm_cpu, Python's and :data:`MACHINE_PACKAGES`' versions. A closed loop turns a last-bit difference in a
    float reduction into a different run, so runs are promised to repeat bit for bit only where ``id`` is the
    same (DESIGN.md §3). A differing id can still repeat them: two AMD EPYC machines (znver4) whose ids differ by
    the packages' versions alone made 7 of 8 runs alike to the last digit, the eighth where an option's default
    had changed (benchmarks/results/apartment-1000-machine4); an Intel one did not."""
    try:
        import torch

        isa = str(torch.backends.cpu.get_cpu_capability())
    except Exception:                           # noqa: BLE001 - an old torch or none: the id still says so
        isa = "unknown"
    try:
        import numba
        import llvmlite.binding as llvm

        llvm_cpu = numba.config.CPU_NAME or llvm.get_host_cpu_name()
    except Exception:                           # noqa: BLE001
        llvm_cpu = "unknown"
    info = {"cpu": _cpu_model(), "isa": isa, "llvm_cpu": str(llvm_cpu), "cores": str(os.cpu_count() or 0)}
    return {**info, "id": machine_id(info, package_versions(MACHINE_PACKAGES))}


def machine_id(info: Mapping[str, str], versions: Mapping[str, str]) -> str:
    """10 hex digits over ``info``'s cpu, isa and llvm_cpu and every version in ``versions``."""
    key = json.dumps({"cpu": info.get("cpu"), "isa": info.get("isa"), "llvm_cpu": info.get("llvm_cpu"),
                      "versions": dict(sorted(versions.items()))}, sort_keys=True)
    return hashlib.sha256(key.encode()).hexdigest()[:10]


def machine_difference(logged: Mapping[str, str], here: Mapping[str, str]) -> str | None:
    """How the machine a log or run was made on differs from ``here`` (both as :func:`machine_info` gives them,
    the log's read from its ``machine.*`` metadata): e.g. "isa AVX2 there, AVX512 here"; "libraries' versions"
    when only the id differs; None when the ids agree or the log has none (written before they were recorded)."""
    if not logged.get("id") or logged.get("id") == here.get("id"):
        return None
    parts = [f"{k} {logged.get(k, '?')} there, {here.get(k, '?')} here" for k in ("cpu", "isa", "llvm_cpu")
             if logged.get(k) != here.get(k)]
    return "; ".join(parts) or "the numeric libraries' versions differ"


def _jsonable(v: Any) -> Any:
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: _jsonable(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, float) and not math.isfinite(v):
        return repr(v)                       # JSON has no NaN / inf: "nan", "inf"
    if isinstance(v, Path):
        return str(v)
    return v


def run_metadata(config: object, seed: int, **extra: str) -> dict[str, str]:
    """The metadata a run writes: ``config`` (a config dataclass as JSON), ``seed``, and ``extra``."""
    return {"config": json.dumps(_jsonable(config), sort_keys=True), "seed": str(int(seed)), **extra}


class _AppendFile:
    """A write-only file without user-space buffering: every ``write`` is on disk (or raises) on return.

    The MCAP writer calls ``write`` once per finished record group (a chunk and its
    indexes), so there are few system calls, and a failed write leaves nothing half-buffered.
    """

    def __init__(self, path: Path) -> None:
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._pos = 0

    def write(self, data: bytes | bytearray | memoryview) -> int:
        view = memoryview(data).cast("B")
        while view.nbytes:
            n = os.write(self._fd, view)
            self._pos += n
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        pass

    def fsync(self) -> None:
        os.fsync(self._fd)

    def truncate(self, size: int) -> None:
        os.ftruncate(self._fd, size)
        self._pos = size

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


class LogWriter:
    """Writes one run to an MCAP file; see the module docstring for the layout.

    Usage, per step: at most one message per topic with :meth:`write` (or :meth:`write_step_record`, :meth:`write_state`,
    :meth:`write_map`, :meth:`write_metrics`) for each message, then :meth:`end_step`.
    :meth:`close` (or leaving a ``with`` block) finishes the file; messages of a step that
    was not ended are dropped by readers.
    """

    def __init__(self, path: str | Path, metadata: Mapping[str, str], *, fsync: bool = False) -> None:
        """``metadata``: string keys and values (see :func:`run_metadata`); ``fsync``: also fsync each step."""
        self.path = Path(path)
        bad = [k for k, v in metadata.items() if not (isinstance(k, str) and isinstance(v, str))]
        if bad:
            raise TypeError(f"log metadata must map str to str; bad keys: {bad}")
        self._fsync = fsync
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._step_topics: set[str] = set()
        self._closed = False
        self._prev_fields: records.FieldsOut | None = None     # the last /fields written, the base of a delta
        self._fields_since_full = 0
        self.steps_written = 0
        """Whole steps on disk."""
        self.last_step: int | None = None
        """Step number of the last whole step on disk."""
        self.step_end_offsets: list[int] = []
        """File size after each whole step: a file cut at ``step_end_offsets[k]`` holds steps 0..k."""
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = _AppendFile(self.path)
        except OSError as e:
            raise DagsError(f"cannot create log {self.path}: {e.strerror or e}") from None
        self._mcap = Writer(self._file, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)  # type: ignore[arg-type]
        meta = {**metadata, "schema_version": str(SCHEMA_VERSION), "message_encoding": MESSAGE_ENCODING,
                **{f"version.{k}": v for k, v in package_versions().items()},
                **{f"machine.{k}": v for k, v in machine_info().items()}}
        self._io(lambda: (self._mcap.start(library=f"dynactivegs/{meta.get('version.dynactivegs', '?')}"),
                          self._mcap.add_metadata(METADATA_NAME, meta)))
        self._good_offset = self._file.tell()

    # ------------------------------------------------------------------ errors
    def _io(self, fn: Any) -> Any:
        """Run a write; on an OSError cut the file back to the last whole step and raise a DagsError."""
        if self._closed:
            raise DagsError(f"log {self.path} is already closed")
        try:
            return fn()
        except OSError as e:
            self._closed = True
            try:
                self._file.truncate(self._good_offset)
            except OSError:
                pass
            self._file.close()
            kept = (f"it keeps steps up to {self.last_step} ({self._good_offset} bytes)" if self.last_step is not None
                    else "it holds no whole step")
            raise DagsError(f"could not write log {self.path}: {e.strerror or e} (errno {e.errno}); {kept}") from None

    # ---------------------------------------------------------------- messages
    def _channel(self, topic: str, type_name: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            cid = self._mcap.register_channel(topic, MESSAGE_ENCODING, 0,
                                              {"dynactivegs.type": type_name, "schema_version": str(SCHEMA_VERSION)})
            self._channels[topic] = cid
            self._sequence[topic] = 0
        return cid

    def write_raw(self, topic: str, type_name: str, data: bytes, stamp_ns: int) -> None:
        """Write already-encoded message bytes (``type_name`` is the payload's ``_t``)."""
        if not (isinstance(stamp_ns, int) and stamp_ns >= 0):
            raise TypeError(f"stamp_ns must be a non-negative int; got {stamp_ns!r}")
        if topic in self._step_topics:
            raise ValueError(f"topic {topic} written twice in one step; end the step first")
        if topic == "/fields" and type_name != FIELDS_DELTA_NAME:
            self._prev_fields = None            # raw bytes written: the next /fields is written whole
        cid = self._channel(topic, type_name)
        seq = self._sequence[topic]
        self._sequence[topic] = seq + 1
        self._step_topics.add(topic)
        self._io(lambda: self._mcap.add_message(cid, log_time=stamp_ns, data=data, publish_time=stamp_ns,
                                                sequence=seq))

    def write(self, topic: str, record: object, stamp_ns: int) -> None:
        """Write a record on one of :data:`TOPICS` (the record's type must be the topic's)."""
        expected = TOPICS.get(topic)
        if expected is None:
            raise ValueError(f"unknown record topic {topic!r}; record topics are {sorted(TOPICS)}")
        if type(record) is not expected:
            raise TypeError(f"topic {topic} carries {expected.__name__}, not {type(record).__name__}")
        if topic == "/fields":
            self._write_fields(record, stamp_ns)        # type: ignore[arg-type]
            return
        self.write_raw(topic, expected.__name__, encode(record), stamp_ns)

    def _write_fields(self, rec: records.FieldsOut, stamp_ns: int) -> None:
        """``/fields`` whole, or as a delta against the previous step's (docs/log_schema.md, FieldsDelta)."""
        if fields_delta_applies(rec, self._prev_fields) and self._fields_since_full < FIELDS_FULL_EVERY - 1:
            self.write_raw("/fields", FIELDS_DELTA_NAME, encode_fields_delta(rec, self._prev_fields), stamp_ns)
            self._fields_since_full += 1
        else:
            self.write_raw("/fields", "FieldsOut", encode(rec), stamp_ns)
            self._fields_since_full = 0
        self._prev_fields = rec

    def write_step_record(self, rec: records.StepRecord, stamp_ns: int | None = None) -> None:
        """Write ``rec.frame`` and every stage output that is set (``prev_mapping`` is the previous step's)."""
        t = rec.frame.stamp_ns if stamp_ns is None else stamp_ns
        self.write("/frame", rec.frame, t)
        for stage, topic in STAGE_TOPICS.items():
            out = getattr(rec, stage)
            if out is not None:
                self.write(topic, out, t)

    def write_state(self, stage: str, state: object, stamp_ns: int) -> None:
        """Snapshot of a stage's state on ``/state/<stage>``: replay can start from this step."""
        if not stage.isidentifier():
            raise ValueError(f"stage name must be an identifier; got {stage!r}")
        self.write_raw(STATE_TOPIC_PREFIX + stage, "state", encode_state(state), stamp_ns)

    def write_map(self, gaussians: object, stamp_ns: int) -> None:
        """Snapshot of the Gaussian map on ``/map`` (any value :func:`encode_state` accepts)."""
        self.write_raw(MAP_TOPIC, "state", encode_state(gaussians), stamp_ns)

    def write_refined_map(self, gaussians: object, stamp_ns: int) -> None:
        """The map after the offline refinement on ``/map_refined`` (after the last :meth:`end_step`), written to
        disk at once in its own chunk. A log cut before it still replays every step; it then has no refined map."""
        if self._step_topics:
            raise ValueError("end the step in progress before writing the refined map")
        self.write_raw(REFINED_MAP_TOPIC, "state", encode_state(gaussians), stamp_ns)
        self._flush_chunk()

    def _flush_chunk(self) -> None:
        """Close the open chunk and write it to disk (fsync'ed if asked); a cut after this keeps it."""

        def flush() -> None:
            self._mcap.flush()
            if self._fsync:
                self._file.fsync()

        self._io(flush)
        self._good_offset = self._file.tell()
        self._step_topics.clear()

    def write_metrics(self, step: int, values: Mapping[str, float], stamp_ns: int) -> None:
        """Scalar metrics of this step on ``/metrics``."""
        self.write("/metrics", Metrics(step, {str(k): float(v) for k, v in values.items()}), stamp_ns)

    def end_step(self, step: int, stamp_ns: int) -> None:
        """Close step ``step``: write ``/step_end``, then its chunk to disk (fsync'ed if asked)."""
        self.write("/step_end", StepEnd(step, stamp_ns, len(self._step_topics)), stamp_ns)
        self._flush_chunk()
        self.step_end_offsets.append(self._good_offset)
        self.steps_written += 1
        self.last_step = step

    @property
    def bytes_written(self) -> int:
        """Size of the file so far."""
        return self._file.tell()

    def close(self, end_metadata: Mapping[str, str] | None = None) -> None:
        """Finish the file: an end metadata record (``steps`` plus ``end_metadata``) and the MCAP summary."""
        if self._closed:
            return
        meta = {"steps": str(self.steps_written), "last_step": str(self.last_step), **(end_metadata or {})}
        self._io(lambda: (self._mcap.add_metadata(END_METADATA_NAME, meta), self._mcap.finish()))
        self._closed = True
        self._file.close()

    def abort(self) -> None:
        """Stop without a summary (the file stays readable up to its last whole step)."""
        if not self._closed:
            self._closed = True
            self._file.close()

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None and issubclass(exc_type, DagsError) and self._closed:
            return
        self.close()
