"""The log codec: every record and state snapshot survives encode -> decode bit for bit; bad bytes are one-line errors."""

from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass

import msgpack
import numpy as np
import pytest
import torch

from dynactivegs.errors import DagsError
from recorder import codec
from recorder.codec import RECORD_TYPES, SCHEMA_VERSION, decode, decode_state, encode, encode_state
from tests.recorder.synthetic import all_record_types

THIS = __name__.split(".")[0]       # the test tree's top-level package, allowed for state classes


def assert_identical(a: object, b: object, where: str = "") -> None:
    """Same type and, field by field, the same values; arrays also the same dtype, shape and bytes."""
    assert type(a) is type(b), f"{where}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), where
    elif isinstance(a, torch.Tensor):
        assert a.dtype == b.dtype and a.shape == b.shape and a.device == b.device, where
        assert a.requires_grad == b.requires_grad, where
        assert a.detach().reshape(-1).view(torch.uint8).numpy().tobytes() == \
            b.detach().reshape(-1).view(torch.uint8).numpy().tobytes(), where
    elif dataclasses.is_dataclass(a):
        for f in dataclasses.fields(a):
            assert_identical(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_identical(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            assert_identical(a[k], b[k], f"{where}[{k!r}]")
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), f"{where}: {a!r} != {b!r}"
    elif isinstance(a, np.random.Generator):
        assert a.bit_generator.state == b.bit_generator.state, where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


@pytest.mark.parametrize("edge_cases", [False, True], ids=["typical", "nan-and-empty"])
@pytest.mark.parametrize("seed", [0, 1])
def test_every_record_type_round_trips_bit_identically(seed, edge_cases):
    recs = all_record_types(seed=seed, edge_cases=edge_cases)
    assert {type(r).__name__ for r in recs} == set(RECORD_TYPES)
    for r in recs:
        data = encode(r)
        back = decode(data, type(r))
        assert_identical(r, back, type(r).__name__)
        assert type(decode(data)) is type(r)
        assert encode(back) == data                  # and the bytes are stable


def test_nan_payloads_negative_zero_and_empty_arrays_survive():
    rec = next(r for r in all_record_types(edge_cases=True) if type(r).__name__ == "PerceptionOut")
    back = decode(encode(rec))
    assert np.isnan(back.beta[0, 0]) and np.signbit(back.beta[0, 1]) and np.isinf(back.beta[1, 0])
    assert np.isnan(back.loss)
    metrics = decode(encode(next(r for r in all_record_types(edge_cases=True) if type(r).__name__ == "Metrics")))
    assert np.float64(metrics.values["payload"]).tobytes() == \
        np.float64(np.array([0x7FC00001], np.uint32).view(np.float32)[0]).tobytes()
    fields = decode(encode(next(r for r in all_record_types(edge_cases=True) if type(r).__name__ == "FieldsOut")))
    assert fields.u_s.shape == (0, 3, 2) and fields.visible.dtype == np.bool_


def test_arrays_are_plain_msgpack_maps_a_foreign_reader_understands():
    frame = all_record_types()[0]
    m = msgpack.unpackb(encode(frame))
    assert m["_t"] == "Frame" and m["_v"] == SCHEMA_VERSION
    assert m["depth_m"]["dtype"] == "<f4" and m["rgb"]["dtype"] == "|u1"
    depth = np.frombuffer(m["depth_m"]["bytes"], m["depth_m"]["dtype"]).reshape(m["depth_m"]["shape"])
    assert np.array_equal(depth, frame.depth_m) and m["stamp_ns"] == frame.stamp_ns


def test_decoded_records_are_read_only_and_checked_by_their_constructor():
    frame = all_record_types()[0]
    back = decode(encode(frame))
    assert not back.rgb.flags.writeable
    m = msgpack.unpackb(encode(frame))
    m["depth_m"]["dtype"] = "<f8"                     # keeps the byte count consistent: (H, W/2) of float64
    m["depth_m"]["shape"] = [frame.height, frame.width // 2]
    with pytest.raises(DagsError, match="not a valid Frame"):
        decode(msgpack.packb(m))


@pytest.mark.parametrize("mutate, phrase", [
    (lambda m: m.update(_v=SCHEMA_VERSION + 1), "newer than this dynactivegs reads"),
    (lambda m: m.update(_v=0), "older than this dynactivegs reads"),
    (lambda m: m.update(_t="Castle"), "expected Frame"),
    (lambda m: m.pop("K"), "missing \\['K'\\]"),
    (lambda m: m.update(extra=1), "unknown \\['extra'\\]"),
    (lambda m: m.update(step="3"), "Frame.step: expected int"),
    (lambda m: m["rgb"].update(bytes=b"123"), "do not hold"),
    (lambda m: m["rgb"].update(dtype="|O"), "bad array header"),
    (lambda m: m.pop("_v"), "no _t/_v envelope"),
])
def test_bad_messages_are_one_line_errors(mutate, phrase):
    m = msgpack.unpackb(encode(all_record_types()[0]))
    mutate(m)
    with pytest.raises(DagsError, match=phrase) as e:
        decode(msgpack.packb(m), RECORD_TYPES["Frame"])
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("data", [b"", b"\xc1", b"garbage bytes", msgpack.packb([1, 2, 3])])
def test_garbage_is_a_one_line_error(data):
    with pytest.raises(DagsError):
        decode(data)
    with pytest.raises(DagsError):
        decode_state(data)


def test_encoding_the_wrong_type_is_a_programming_error():
    with pytest.raises(TypeError, match="not a log record type"):
        encode({"a": 1})
    frame = all_record_types()[0]
    object.__setattr__(frame, "step", "three")
    with pytest.raises(TypeError, match="Frame.step: expected int"):
        encode(frame)


# ------------------------------------------------------------------------------ state snapshots
class Mode(enum.IntEnum):
    A = 1
    B = 2


@dataclass(frozen=True)
class Inner:
    weights: torch.Tensor
    moments: tuple[torch.Tensor, ...]
    counts: np.ndarray


@dataclass(frozen=True, slots=True)
class Outer:
    inner: Inner
    history: tuple[Inner, ...]
    table: dict
    items: list
    mode: Mode
    prev: np.ndarray | None
    scalar: np.float32
    big: int
    rng: np.random.Generator
    done: bool = False
    derived: float = dataclasses.field(init=False, default=0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "derived", float(self.counts_sum()))

    def counts_sum(self) -> int:
        return int(self.inner.counts.sum())


def _state(seed: int) -> Outer:
    g = torch.Generator().manual_seed(seed)
    rng = np.random.default_rng(seed)
    inner = Inner(torch.randn(5, 3, generator=g, requires_grad=True),
                  (torch.randn(5, 3, generator=g), torch.zeros(0), torch.tensor(7, dtype=torch.int64),
                   torch.randn(4, generator=g).to(torch.bfloat16), torch.tensor([True, False])),
                  rng.integers(0, 9, (2, 2)).astype(np.int16))
    other = Inner(torch.full((1,), float("nan")), (), np.zeros((0, 4), np.float64))
    return Outer(inner, (inner, other), {"a": 1.5, 2: None, (1, "x"): [np.float64(-0.0)], "dtype": torch.float16},
                 [1, "two", b"\x00\x01", {"nested": np.arange(3)}], Mode.B, None, np.float32(3.25), 2 ** 100 + 1,
                 rng, True)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_state_snapshot_round_trips_nested_dataclasses_tensors_and_arrays(seed):
    state = _state(seed)
    data = encode_state(state)
    back = decode_state(data, allowed_modules=(*codec.DEFAULT_STATE_MODULES, THIS))
    assert_identical(state, back, "state")
    assert back.derived == state.derived
    assert back.inner.counts.flags.writeable and back.inner.weights.requires_grad
    assert back.rng.random() == state.rng.random()       # the generator continues the same stream
    assert encode_state(decode_state(data, allowed_modules=(*codec.DEFAULT_STATE_MODULES, THIS))) == data


def test_state_snapshot_of_the_gaussian_map_and_a_stage_state():
    from dynactivegs.fields.grid import FieldsState
    from dynactivegs.splat.gaussians import Gaussians

    g = torch.Generator().manual_seed(0)
    gs = Gaussians(torch.randn(10, 3, generator=g), torch.randn(10, 3, generator=g), torch.randn(10, 4, generator=g),
                   torch.randn(10, generator=g), torch.randn(10, 3, generator=g))
    back = decode_state(encode_state(gs))
    assert type(back) is Gaussians and all(torch.equal(a, b) for a, b in zip(gs.tensors(), back.tensors()))
    fs = FieldsState((1, -2, 0), np.ones((2, 3, 4), np.float32), np.zeros((2, 3, 4), np.float32),
                     np.full((2, 3, 4), 0.5, np.float32))
    back = decode_state(encode_state(fs))
    assert_identical(fs, back, "FieldsState")
    assert not back.n_obs.flags.writeable                    # the class's own __post_init__ ran


def test_state_snapshot_rejects_classes_outside_the_allowed_packages():
    data = encode_state(_state(0))
    with pytest.raises(DagsError, match="outside the allowed packages"):
        decode_state(data)
    m = msgpack.unpackb(data, strict_map_key=False)
    m["value"] = {"$": "dc", "cls": "dynactivegs.records:NoSuchRecord", "fields": {}}
    with pytest.raises(DagsError, match="does not exist"):
        decode_state(msgpack.packb(m))
    m["value"] = {"$": "what"}
    with pytest.raises(DagsError, match="unknown snapshot tag"):
        decode_state(msgpack.packb(m))
    with pytest.raises(DagsError, match="not a state snapshot"):
        decode_state(encode(all_record_types()[0]))


def test_state_snapshot_refuses_unsupported_values():
    with pytest.raises(TypeError, match="cannot hold a builtins.set"):
        encode_state({"a": {1, 2}})
    with pytest.raises(TypeError, match="cannot encode an array of dtype object"):
        encode_state(np.array([None]))


def test_tensors_move_to_the_requested_device():
    back = decode_state(encode_state((torch.ones(2),)), device="cpu")
    assert back[0].device.type == "cpu"
    m = msgpack.unpackb(encode_state((torch.ones(2),)), strict_map_key=False)
    m["value"]["items"][0]["device"] = "nosuchdevice"
    with pytest.raises(DagsError, match="cannot place a tensor"):
        decode_state(msgpack.packb(m))


def test_a_selection_of_schema_version_3_reads_with_every_way_clear():
    sel = next(r for r in all_record_types() if type(r).__name__ == "SelectionOut")
    m = msgpack.unpackb(encode(sel))
    for k in ("node_leg_clear", "local_clear_m", "local_origin_xy_m", "local_cell_m"):
        m.pop(k)
    m["_v"] = 3
    old = decode(msgpack.packb(m))
    assert old.node_leg_clear.dtype == np.bool_ and old.node_leg_clear.all()
    assert old.node_leg_clear.shape == (len(sel.node_xy_m),) and np.array_equal(old.node_xy_m, sel.node_xy_m)
    m["_v"] = SCHEMA_VERSION                          # the current version must have it
    with pytest.raises(DagsError, match="missing \\['local_cell_m', 'local_clear_m', 'local_origin_xy_m', 'node_leg_clear'\\]"):
        decode(msgpack.packb(m))


def test_a_selection_of_schema_version_4_reads_with_an_empty_local_window():
    sel = next(r for r in all_record_types() if type(r).__name__ == "SelectionOut")
    assert sel.local_clear_m.size > 0
    m = msgpack.unpackb(encode(sel))
    for k in ("local_clear_m", "local_origin_xy_m", "local_cell_m"):
        m.pop(k)
    m["_v"] = 4
    old = decode(msgpack.packb(m))
    assert old.local_clear_m.shape == (0, 0) and old.local_clear_m.dtype == np.float32
    assert old.local_origin_xy_m.shape == (2,) and old.local_cell_m == 0.0
    assert np.array_equal(old.node_leg_clear, sel.node_leg_clear)
    m["_v"] = SCHEMA_VERSION
    with pytest.raises(DagsError, match="missing \\['local_cell_m', 'local_clear_m', 'local_origin_xy_m'\\]"):
        decode(msgpack.packb(m))


def test_a_selection_of_schema_version_5_reads_with_no_target_reason():
    sel = next(r for r in all_record_types() if type(r).__name__ == "SelectionOut")
    assert sel.target_reason != ""
    m = msgpack.unpackb(encode(sel))
    m.pop("target_reason")
    m["_v"] = 5
    old = decode(msgpack.packb(m))
    assert old.target_reason == "" and np.array_equal(old.local_clear_m, sel.local_clear_m)
    m["_v"] = SCHEMA_VERSION
    with pytest.raises(DagsError, match="missing \\['target_reason'\\]"):
        decode(msgpack.packb(m))
