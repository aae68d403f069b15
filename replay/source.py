"""Reading a dynactivegs MCAP log back, one whole step at a time.

:class:`LogReader` streams the file front to back with the ``mcap`` library's non-seeking
reader, so a log without its summary (the run was killed, the disk filled up) reads like
a finished one up to its last ``/step_end`` marker; messages after it are dropped and
:attr:`LogReader.end` says where the file stops. Every problem with the file is a
one-line :class:`~dynactivegs.errors.DagsError`: missing, not MCAP, not a dynactivegs
log, of a newer schema, or corrupt (a bad record inside the file, as opposed to a file
that merely stops early).
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mcap.exceptions import InvalidMagic
from mcap.records import Channel, Chunk, Footer, Header, Message, Metadata
from mcap.stream_reader import StreamReader, breakup_chunk

from dynactivegs import records
from dynactivegs.errors import DagsError
from recorder.codec import StepEnd, check_schema_version, decode, decode_fields_delta, decode_state, encode, type_name
from recorder.mcap_log import (END_METADATA_NAME, MAP_TOPIC, METADATA_NAME, REFINED_MAP_TOPIC, STAGE_TOPICS,
                               STATE_TOPIC_PREFIX, TOPICS)

_MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEADER = struct.Struct("<BQ")   # opcode, length of the record body


@dataclass(frozen=True, slots=True)
class LogEnd:
    """Where a log stops: after its last whole step, cleanly closed or cut off."""

    steps: int                    # whole steps in the file
    last_step: int | None         # step number of the last whole step; None when there is none
    complete: bool                # the file was closed cleanly (footer present)
    truncated_at: int | None      # file size when the file was cut off; None when complete

    def describe(self) -> str:
        """One line, e.g. ``log ends after step 41 (truncated at byte 917504)``."""
        after = f"after step {self.last_step}" if self.last_step is not None else "before its first whole step"
        if self.complete:
            return f"log complete: {self.steps} steps, ends {after}"
        return f"log ends {after} (truncated at byte {self.truncated_at})"


class LoggedStep:
    """The messages of one whole step, by topic; ``step[topic]`` decodes a message on first access."""

    def __init__(self, step: int, stamp_ns: int, raw: dict[str, bytes], *, end_offset: int) -> None:
        self.step = step
        self.stamp_ns = stamp_ns
        self.raw = raw
        """Encoded message bytes by topic."""
        self.end_offset = end_offset
        """Byte offset of the end of the chunk that closed this step."""
        self._decoded: dict[str, Any] = {}

    @property
    def topics(self) -> list[str]:
        return sorted(self.raw)

    def __contains__(self, topic: object) -> bool:
        return topic in self.raw

    def __getitem__(self, topic: str) -> Any:
        if topic not in self._decoded:
            data = self.raw[topic]
            if topic in TOPICS:
                self._decoded[topic] = decode(data, TOPICS[topic])
            elif topic.startswith(STATE_TOPIC_PREFIX) or topic == MAP_TOPIC:
                self._decoded[topic] = decode_state(data)
            else:
                raise KeyError(f"{topic}: not a topic of the dynactivegs log schema")
        return self._decoded[topic]

    def get(self, topic: str, default: Any = None) -> Any:
        return self[topic] if topic in self.raw else default

    def state(self, stage: str, **decode_kwargs: Any) -> Any:
        """The snapshot on ``/state/<stage>`` (``decode_kwargs`` go to :func:`recorder.codec.decode_state`)."""
        return decode_state(self.raw[STATE_TOPIC_PREFIX + stage], **decode_kwargs)

    def step_record(self, prev_mapping: records.MappingOut | None) -> records.StepRecord:
        """The step's frame and recorded stage outputs as a StepRecord (stages not logged are None)."""
        outs = {stage: self.get(topic) for stage, topic in STAGE_TOPICS.items()}
        return records.StepRecord(self["/frame"], prev_mapping, **outs)

    def __repr__(self) -> str:
        return f"LoggedStep(step={self.step}, topics={self.topics})"


class LogReader:
    """A dynactivegs MCAP log: its metadata, and its whole steps in order.

    Opening reads only the file's start (magic, header, metadata), which is enough to
    reject a file that is not a log of a schema this code reads.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise DagsError(f"log not found: {self.path}; pass the path of an MCAP file written by dagsrun --record")
        if not self.path.is_file():
            raise DagsError(f"log {self.path} is not a file")
        with open(self.path, "rb") as f:
            head = f.read(len(_MAGIC))
        if head != _MAGIC:
            what = "it is empty" if not head else "it does not start with the MCAP magic bytes"
            raise DagsError(f"not an MCAP file: {self.path} ({what})")
        self.metadata: dict[str, str] = {}
        """The ``dynactivegs`` metadata record: schema_version, config (JSON), seed, version.* and the run's own keys."""
        self.library = ""
        """The MCAP header's library string."""
        for rec, _ in self._records():
            if isinstance(rec, Header):
                self.library = rec.library
            elif isinstance(rec, Metadata) and rec.name == METADATA_NAME:
                self.metadata = dict(rec.metadata)
                break
            elif isinstance(rec, (Chunk, Message, Footer)):
                break
        if not self.metadata and self._cut is not None:
            raise DagsError(f"log {self.path} is cut off before its first step (truncated at byte {self._cut})")
        if not self.metadata:
            raise DagsError(f"{self.path} is an MCAP file but not a dynactivegs log (no {METADATA_NAME!r} metadata "
                            f"record before its first message)")
        self.schema_version = check_schema_version(self.metadata.get("schema_version"), f"log {self.path}")
        self.end: LogEnd | None = None
        """Set once :meth:`steps` has read to the end of the file."""
        self.end_metadata: dict[str, str] = {}
        """The ``dynactivegs.end`` metadata record of a cleanly closed log (steps, last_step, ...)."""
        self._refined: bytes | None = None          # /map_refined, once read through

    @property
    def seed(self) -> int | None:
        s = self.metadata.get("seed")
        return int(s) if s is not None else None

    @property
    def config_json(self) -> str | None:
        """The resolved config as the run wrote it (JSON), if it did."""
        return self.metadata.get("config")

    # ---------------------------------------------------------------- records
    def _records(self) -> Iterator[tuple[Any, int]]:
        """(record, byte offset after it) in file order; chunks are yielded whole.

        A record that cannot be read ends the iteration: silently when the file stops
        inside it (a cut-off file; :attr:`_cut` holds the file size), with a DagsError when
        the record lies wholly inside the file (corruption).
        """
        size = os.path.getsize(self.path)
        self._cut: int | None = None
        with open(self.path, "rb") as f:
            reader = StreamReader(f, emit_chunks=True, record_size_limit=None)
            it = reader.records
            pos = len(_MAGIC)
            while True:
                try:
                    rec = next(it)
                except StopIteration:
                    return
                except InvalidMagic:
                    if pos == len(_MAGIC):
                        raise DagsError(f"not an MCAP file: {self.path} (bad magic bytes)") from None
                    if f.tell() < size:      # bad closing magic after the footer
                        raise DagsError(f"corrupt log {self.path}: bad closing magic at byte {pos}") from None
                    self._cut = size
                    return
                except Exception as e:  # noqa: BLE001 - any parse failure is classified below
                    if self._stops_inside(f, pos, size):
                        self._cut = size
                        return
                    raise DagsError(f"corrupt log {self.path}: unreadable record at byte {pos} "
                                    f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})") from None
                pos = f.tell()
                yield rec, pos

    @staticmethod
    def _stops_inside(f: Any, pos: int, size: int) -> bool:
        """Whether the record starting at ``pos`` runs past the end of the file."""
        if pos + _RECORD_HEADER.size > size:
            return True
        f.seek(pos)
        _, length = _RECORD_HEADER.unpack(f.read(_RECORD_HEADER.size))
        return pos + _RECORD_HEADER.size + length > size

    def steps(self, start: int = 0, stop: int | None = None) -> Iterator[LoggedStep]:
        """Whole steps with ``start <= step < stop``, in file order; sets :attr:`end` when the file is read through.

        Messages are decoded lazily (on ``step[topic]``), so skipping steps is cheap.
        """
        channels: dict[int, str] = {}
        pending: dict[str, bytes] = {}
        prev_fields: records.FieldsOut | None = None
        n_steps, last = 0, None
        complete = False
        for rec, pos in self._records():
            if isinstance(rec, Chunk):
                try:
                    inner = breakup_chunk(rec, validate_crc=True)
                except Exception as e:  # noqa: BLE001 - zstd, CRC and framing errors alike
                    raise DagsError(f"corrupt log {self.path}: bad chunk ending at byte {pos} "
                                    f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})") from None
                for r in inner:
                    if isinstance(r, Channel):
                        channels[r.id] = r.topic
                    elif isinstance(r, Message):
                        topic = channels.get(r.channel_id)
                        if topic is None:
                            raise DagsError(f"corrupt log {self.path}: message on unknown channel {r.channel_id} "
                                            f"in the chunk ending at byte {pos}")
                        if topic == REFINED_MAP_TOPIC:
                            self._refined = r.data      # written after the last step, outside any step
                            continue
                        if topic != "/step_end":
                            pending[topic] = r.data
                            continue
                        end = decode(r.data, StepEnd)
                        if len(pending) != end.n_messages:
                            raise DagsError(f"corrupt log {self.path}: step {end.step} has {len(pending)} messages, "
                                            f"its /step_end says {end.n_messages}")
                        group, pending = pending, {}
                        n_steps, last = n_steps + 1, end.step
                        fields = None
                        if "/fields" in group:
                            fields, group["/fields"] = self._fields(group["/fields"], prev_fields, end.step)
                            prev_fields = fields
                        if end.step >= start and (stop is None or end.step < stop):
                            ls = LoggedStep(end.step, end.stamp_ns, group, end_offset=pos)
                            if fields is not None:
                                ls._decoded["/fields"] = fields
                            yield ls
                        elif stop is not None and end.step >= stop:
                            return
            elif isinstance(rec, Metadata) and rec.name == END_METADATA_NAME:
                self.end_metadata = dict(rec.metadata)
            elif isinstance(rec, Footer):
                complete = True
        self.end = LogEnd(n_steps, last, complete, None if complete else self._cut)

    def _fields(self, data: bytes, prev: records.FieldsOut | None, step: int) -> tuple[records.FieldsOut, bytes]:
        """A step's ``/fields`` and its canonical (whole FieldsOut) bytes, resolving a FieldsDelta against ``prev``."""
        if type_name(data) != "FieldsDelta":
            return decode(data, records.FieldsOut), data
        if prev is None:
            raise DagsError(f"corrupt log {self.path}: step {step}'s /fields is a delta with no earlier /fields")
        full = decode_fields_delta(data, prev)
        return full, encode(full)

    def refined_map(self) -> Any:
        """The map after the offline refinement (``/map_refined``), or None when the run wrote none (no
        refinement, or the run was stopped before it ended). Reads the file through if :meth:`steps` has not."""
        if self.end is None:
            for _ in self.steps():
                pass
        return decode_state(self._refined) if self._refined is not None else None

    def __iter__(self) -> Iterator[LoggedStep]:
        return self.steps()

    def read_all(self) -> list[LoggedStep]:
        """Every whole step (reads the file through, so :attr:`end` is set)."""
        return list(self.steps())
