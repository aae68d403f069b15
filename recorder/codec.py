"""The message encoding of dynactivegs logs: versioned msgpack, documented in ``docs/log_schema.md``.

Two kinds of payload share one envelope, a msgpack map with ``_t`` (the type name) and
``_v`` (the schema version, :data:`SCHEMA_VERSION`):

**Records** (:func:`encode` / :func:`decode`): the frozen dataclasses of
:mod:`dynactivegs.records` plus :class:`StepEnd` and :class:`Metrics`. The map's other keys
are the record's fields, encoded by their type hints:

- ``np.ndarray``: a map ``{"dtype": "<f4", "shape": [H, W], "bytes": <bin>}``; the dtype is
  numpy's ``dtype.str`` (always little-endian, ``|`` for one-byte types) and the bytes are
  the array in C order. ``np.frombuffer(m["bytes"], m["dtype"]).reshape(m["shape"])``
  rebuilds it bit for bit (NaN payloads, -0.0 and empty arrays included).
- ``int`` / ``bool`` / ``str``: msgpack's own types; ``float``: msgpack float 64 (NaN kept).
- a nested dataclass: a map of its fields (no envelope); ``X | None``: nil or ``X``;
  ``tuple[X, ...]``: an array; ``dict[str, X]``: a map.

Decoding is generic over ``dataclasses.fields`` and the type hints, so a new record type
needs no codec code. The record's constructor runs on decode, so its own checks
(dtypes, shapes) apply to what comes out of a log.

**State snapshots** (:func:`encode_state` / :func:`decode_state`): arbitrary nested values
a stage keeps between steps: dataclasses, tuples, lists, dicts, numpy arrays and scalars,
torch tensors (torch is imported only when a tensor is met), enums, numpy random
generators. Because nothing declares their types, every non-primitive value is a map
tagged with ``"$"`` (e.g. ``{"$": "nd", "dtype": ..., "shape": ..., "bytes": ...}`` or
``{"$": "dc", "cls": "dynactivegs.mapping.stage:MappingState", "fields": {...}}``).
Dataclasses are rebuilt only from modules the caller allows (by default the project's own
packages), so a log cannot make the reader import arbitrary code.

Every problem with the bytes (not msgpack, wrong type, newer schema, fields that do not
match) raises a one-line :class:`~dynactivegs.errors.DagsError`.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import sys
import types
import typing
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, TypeVar

import msgpack
import numpy as np

from dynactivegs import records
from dynactivegs.errors import DagsError

SCHEMA_VERSION = 6
"""Version of the message encoding and of the record layouts. Bump it when a record's fields change.

2: ``/fields`` may hold a :func:`encode_fields_delta` message (``_t`` ``FieldsDelta``).
3: a ``FieldsDelta`` may also follow a grid that grew (the previous grid placed inside the new one).
4: ``SelectionOut`` gains ``node_leg_clear``; older messages read with every node's way clear (what
   the planner then assumed).
5: ``SelectionOut`` gains ``local_clear_m``, ``local_origin_xy_m`` and ``local_cell_m``; older messages
   read with an empty window (the planner then steers by its path alone, as it did).
6: ``SelectionOut`` gains ``target_reason``; older messages read with ``""`` (not logged)."""

MIN_SCHEMA_VERSION = 1
"""Oldest schema version this code still reads."""

MESSAGE_ENCODING = "msgpack"
"""The MCAP ``message_encoding`` of every canonical topic."""

STATE_TYPE = "state"
"""``_t`` of a state snapshot."""

DEFAULT_STATE_MODULES = ("dynactivegs", "recorder", "replay")
"""Top-level packages whose dataclasses and enums a state snapshot may rebuild by default."""

_ARRAY_KINDS = frozenset("biufc")   # bool, signed, unsigned, float, complex: never object dtypes

T = TypeVar("T")


class LogDecodeError(DagsError):
    """Bytes that are not a valid message of the dynactivegs log schema."""


@dataclass(frozen=True, slots=True)
class StepEnd:
    """Marker written after every message of one step: a reader keeps only steps that have one."""

    step: int
    stamp_ns: int
    n_messages: int               # messages of this step before the marker


@dataclass(frozen=True, slots=True)
class Metrics:
    """Scalar metrics of one step (loss, Gaussian count, coverage, PSNR, ...), by name."""

    step: int
    values: dict[str, float]


RECORD_TYPES: dict[str, type] = {
    cls.__name__: cls
    for cls in (records.Frame, records.RobotPose2D, records.SimTruth, records.PerceptionOut, records.MappingOut,
                records.FieldsOut, records.SelectionOut, records.PlanningOut, records.StepRecord, StepEnd, Metrics)
}
"""Every type :func:`encode` accepts, by ``_t`` name."""


def _corrupt(what: str) -> LogDecodeError:
    return LogDecodeError(what.replace("\n", " "))


# --------------------------------------------------------------------------------------- arrays
def _pack_array(a: np.ndarray) -> dict[str, Any]:
    if a.dtype.kind not in _ARRAY_KINDS:
        raise TypeError(f"cannot encode an array of dtype {a.dtype}")
    if a.dtype.byteorder == ">" or (a.dtype.byteorder == "=" and sys.byteorder == "big"):
        a = a.astype(a.dtype.newbyteorder("<"))
    if not a.flags.c_contiguous:
        a = a.copy(order="C")                # (not np.ascontiguousarray: it turns 0-d into 1-d)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "bytes": a.tobytes()}


def _unpack_array(m: Any, where: str, writable: bool = False) -> np.ndarray:
    if not isinstance(m, dict) or not {"dtype", "shape", "bytes"} <= m.keys():
        raise _corrupt(f"{where}: expected an array map with dtype, shape and bytes")
    try:
        dtype = np.dtype(m["dtype"])
    except TypeError:
        raise _corrupt(f"{where}: unknown array dtype {m['dtype']!r}") from None
    shape = m["shape"]
    data = m["bytes"]
    if dtype.kind not in _ARRAY_KINDS or not isinstance(data, bytes) or not isinstance(shape, list) \
            or not all(isinstance(s, int) and s >= 0 for s in shape):
        raise _corrupt(f"{where}: bad array header dtype={m['dtype']!r} shape={shape!r}")
    if int(np.prod(shape, dtype=np.int64)) * dtype.itemsize != len(data):
        raise _corrupt(f"{where}: {len(data)} bytes do not hold a {m['dtype']} array of shape {tuple(shape)}")
    a = np.frombuffer(bytearray(data) if writable else data, dtype=dtype).reshape(shape)
    return a.astype(dtype.newbyteorder("="), copy=False) if not dtype.isnative else a


# -------------------------------------------------------------------- records (by type hints)
@lru_cache(maxsize=None)
def _hints(cls: type) -> tuple[tuple[str, Any, bool], ...]:
    """(name, type hint, init) of every dataclass field of ``cls``."""
    hints = typing.get_type_hints(cls)
    return tuple((f.name, hints[f.name], f.init) for f in dataclasses.fields(cls))


def _optional_arg(hint: Any) -> Any | None:
    """``X`` for a hint ``X | None`` / ``Optional[X]``; None for any other hint."""
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(hint)) == 2:
            return args[0]
        raise TypeError(f"unsupported union hint {hint}")
    return None


def _enc(hint: Any, v: Any, where: str) -> Any:
    if hint is np.ndarray:
        if not isinstance(v, np.ndarray):
            raise TypeError(f"{where}: expected np.ndarray, got {type(v).__name__}")
        return _pack_array(v)
    if hint is float:
        if not isinstance(v, (int, float, np.integer, np.floating)) or isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{where}: expected float, got {type(v).__name__}")
        return float(v)
    if hint is bool:
        if not isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{where}: expected bool, got {type(v).__name__}")
        return bool(v)
    if hint is int:
        if not isinstance(v, (int, np.integer)) or isinstance(v, (bool, np.bool_)):
            raise TypeError(f"{where}: expected int, got {type(v).__name__}")
        return int(v)
    if hint is str:
        if not isinstance(v, str):
            raise TypeError(f"{where}: expected str, got {type(v).__name__}")
        return v
    inner = _optional_arg(hint)
    if inner is not None:
        return None if v is None else _enc(inner, v, where)
    if dataclasses.is_dataclass(hint):
        if type(v) is not hint:
            raise TypeError(f"{where}: expected {hint.__name__}, got {type(v).__name__}")
        return {name: _enc(h, getattr(v, name), f"{where}.{name}") for name, h, _ in _hints(hint)}
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return [_enc(args[0], x, f"{where}[{i}]") for i, x in enumerate(v)]
    if origin is dict and args[0] is str:
        return {str(k): _enc(args[1], x, f"{where}[{k!r}]") for k, x in v.items()}
    raise TypeError(f"{where}: the log codec does not support fields of type {hint}")


def _dec(hint: Any, v: Any, where: str) -> Any:
    if hint is np.ndarray:
        return _unpack_array(v, where)
    if hint is float:
        if isinstance(v, float) or (isinstance(v, int) and not isinstance(v, bool)):
            return float(v)
    elif hint is bool:
        if isinstance(v, bool):
            return v
    elif hint is int:
        if isinstance(v, int) and not isinstance(v, bool):
            return v
    elif hint is str:
        if isinstance(v, str):
            return v
    elif (inner := _optional_arg(hint)) is not None:
        return None if v is None else _dec(inner, v, where)
    elif dataclasses.is_dataclass(hint):
        if isinstance(v, dict):
            return _build(hint, v, where)
    else:
        origin, args = typing.get_origin(hint), typing.get_args(hint)
        if origin is tuple and isinstance(v, list):
            return tuple(_dec(args[0], x, f"{where}[{i}]") for i, x in enumerate(v))
        if origin is dict and isinstance(v, dict):
            return {k: _dec(args[1], x, f"{where}[{k!r}]") for k, x in v.items()}
    raise _corrupt(f"{where}: expected {getattr(hint, '__name__', hint)}, found {type(v).__name__}")


def _build(cls: type, m: dict, where: str, skip: Iterable[str] = ()) -> Any:
    spec = _hints(cls)
    names = {name for name, _, _ in spec}
    extra = set(m) - names - set(skip)
    missing = names - set(m)
    if extra or missing:
        raise _corrupt(f"{where}: fields do not match {cls.__name__} (missing {sorted(missing)}, unknown {sorted(extra)})")
    kwargs = {name: _dec(h, m[name], f"{where}.{name}") for name, h, init in spec if init}
    try:
        obj = cls(**kwargs)
    except (ValueError, TypeError, AssertionError) as e:
        raise _corrupt(f"{where}: not a valid {cls.__name__}: {e}") from None
    for name, h, init in spec:
        if not init:
            object.__setattr__(obj, name, _dec(h, m[name], f"{where}.{name}"))
    return obj


def encode(record: object) -> bytes:
    """Bytes of one record (any type in :data:`RECORD_TYPES`), in the current schema version."""
    cls = type(record)
    if RECORD_TYPES.get(cls.__name__) is not cls:
        raise TypeError(f"not a log record type: {cls.__name__}")
    body = {name: _enc(h, getattr(record, name), f"{cls.__name__}.{name}") for name, h, _ in _hints(cls)}
    return msgpack.packb({"_t": cls.__name__, "_v": SCHEMA_VERSION, **body}, use_bin_type=True)


def _envelope(data: bytes | memoryview, what: str) -> dict:
    try:
        m = msgpack.unpackb(data, raw=False, strict_map_key=False)
    except (ValueError, msgpack.UnpackException, TypeError) as e:
        raise _corrupt(f"{what}: not a msgpack message ({type(e).__name__}: {e})") from None
    if not isinstance(m, dict) or "_t" not in m or "_v" not in m:
        raise _corrupt(f"{what}: not a dynactivegs log message (no _t/_v envelope)")
    check_schema_version(m["_v"], what)
    return m


def check_schema_version(version: object, what: str) -> int:
    """The schema version as an int; a one-line error for one this code cannot read."""
    try:
        v = int(version)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        raise _corrupt(f"{what}: schema version {version!r} is not an integer") from None
    if v > SCHEMA_VERSION:
        raise LogDecodeError(f"{what} has schema version {v}, newer than this dynactivegs reads "
                             f"(up to {SCHEMA_VERSION}); upgrade dynactivegs to read it")
    if v < MIN_SCHEMA_VERSION:
        raise LogDecodeError(f"{what} has schema version {v}, older than this dynactivegs reads "
                             f"(from {MIN_SCHEMA_VERSION}); replay it with the dynactivegs that wrote it")
    return v


def type_name(data: bytes | memoryview) -> str:
    """The ``_t`` of a message (a record type name or ``state``), after the version check."""
    return str(_envelope(data, "message")["_t"])


def decode(data: bytes | memoryview, cls: type[T] | None = None) -> T:
    """The record in ``data``; with ``cls``, a one-line error if it holds another type."""
    m = _envelope(data, "message")
    name = m["_t"]
    if cls is not None and name != cls.__name__:
        raise _corrupt(f"message holds a {name!r}, expected {cls.__name__}")
    found = RECORD_TYPES.get(name)
    if found is None:
        raise _corrupt(f"message holds an unknown record type {name!r}")
    if int(m["_v"]) < 6:
        _upgrade_selection(m.get("selection") if name == "StepRecord" else m if name == "SelectionOut" else None)
    return _build(found, m, name, skip=("_t", "_v"))


def _upgrade_selection(m: object) -> None:
    """A ``SelectionOut`` map of an older schema version given the fields it lacks: ``node_leg_clear`` (< 4)
    with every node clear, the local window (< 5) empty, ``target_reason`` (< 6) ``""``."""
    if not isinstance(m, dict):
        return
    if "node_leg_clear" not in m and isinstance(m.get("node_xy_m"), dict):
        shape = m["node_xy_m"].get("shape")
        n = shape[0] if isinstance(shape, list) and shape else 0
        m["node_leg_clear"] = _pack_array(np.ones(n, np.bool_))
    if "local_clear_m" not in m:
        m["local_clear_m"] = _pack_array(np.zeros((0, 0), np.float32))
        m["local_origin_xy_m"] = _pack_array(np.zeros(2, np.float64))
        m["local_cell_m"] = 0.0
    m.setdefault("target_reason", "")


# ------------------------------------------------------------------------------ state snapshots
def _torch_if_tensor(v: Any) -> Any | None:
    torch = sys.modules.get("torch")
    return torch if torch is not None and isinstance(v, torch.Tensor) else None


def _class_path(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _pack_any(v: Any, where: str) -> Any:
    if isinstance(v, np.generic):            # before float: np.float64 is a float
        return {"$": "np", **_pack_array(np.asarray(v))}
    if v is None or isinstance(v, (bool, str, bytes)):
        return v
    if isinstance(v, enum.Enum):             # before int: an IntEnum is an int
        return {"$": "enum", "cls": _class_path(type(v)), "value": _pack_any(v.value, where)}
    if isinstance(v, float):
        return v
    if isinstance(v, int):
        if -(2 ** 63) <= v < 2 ** 64:
            return int(v)
        return {"$": "bigint", "hex": hex(v)}
    if isinstance(v, np.ndarray):
        return {"$": "nd", **_pack_array(v)}
    if isinstance(v, np.random.Generator):
        return {"$": "nprng", "state": _pack_any(v.bit_generator.state, f"{where}.state")}
    if (torch := _torch_if_tensor(v)) is not None:
        t = v.detach().to("cpu").contiguous()
        assert sys.byteorder == "little", "tensor snapshots are written on little-endian hosts"
        raw = t.reshape(-1).view(torch.uint8).numpy().tobytes()
        return {"$": "torch", "dtype": str(t.dtype).removeprefix("torch."), "shape": list(t.shape), "bytes": raw,
                "device": str(v.device), "requires_grad": bool(v.requires_grad)}
    if type(v).__module__ == "torch" and type(v).__name__ in ("dtype", "device"):
        return {"$": f"torch.{type(v).__name__}", "name": str(v).removeprefix("torch.")}
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {"$": "dc", "cls": _class_path(type(v)),
                "fields": {f.name: _pack_any(getattr(v, f.name), f"{where}.{f.name}") for f in dataclasses.fields(v)}}
    if type(v) is tuple:
        return {"$": "tuple", "items": [_pack_any(x, f"{where}[{i}]") for i, x in enumerate(v)]}
    if type(v) is list:
        return [_pack_any(x, f"{where}[{i}]") for i, x in enumerate(v)]
    if type(v) is dict:
        return {"$": "dict", "items": [[_pack_any(k, f"{where} key"), _pack_any(x, f"{where}[{k!r}]")]
                                       for k, x in v.items()]}
    raise TypeError(f"{where}: a state snapshot cannot hold a {type(v).__module__}.{type(v).__qualname__}")


def _resolve(path: Any, allowed: tuple[str, ...], where: str) -> type:
    if not isinstance(path, str) or ":" not in path:
        raise _corrupt(f"{where}: bad class path {path!r}")
    module, qualname = path.split(":", 1)
    if module.split(".")[0] not in allowed:
        raise _corrupt(f"{where}: class {path} is outside the allowed packages {list(allowed)}")
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError):
        raise _corrupt(f"{where}: class {path} does not exist in this version of the code") from None
    if not isinstance(obj, type):
        raise _corrupt(f"{where}: {path} is not a class")
    return obj


def _unpack_any(v: Any, where: str, allowed: tuple[str, ...], device: str | None) -> Any:
    if isinstance(v, list):
        return [_unpack_any(x, f"{where}[{i}]", allowed, device) for i, x in enumerate(v)]
    if not isinstance(v, dict):
        return v
    tag = v.get("$")
    try:
        if tag == "nd":
            return _unpack_array(v, where, writable=True)
        if tag == "np":
            return _unpack_array(v, where, writable=True)[()]
        if tag == "tuple":
            return tuple(_unpack_any(x, f"{where}[{i}]", allowed, device) for i, x in enumerate(v["items"]))
        if tag == "dict":
            return {_unpack_any(k, f"{where} key", allowed, device): _unpack_any(x, f"{where}[{k!r}]", allowed, device)
                    for k, x in v["items"]}
        if tag == "bigint":
            return int(v["hex"], 16)
        if tag == "enum":
            return _resolve(v["cls"], allowed, where)(_unpack_any(v["value"], where, allowed, device))
        if tag == "nprng":
            state = _unpack_any(v["state"], where, allowed, device)
            bitgen = getattr(np.random, state["bit_generator"])
            if not (isinstance(bitgen, type) and issubclass(bitgen, np.random.BitGenerator)):
                raise _corrupt(f"{where}: unknown bit generator {state['bit_generator']!r}")
            g = np.random.Generator(bitgen())
            g.bit_generator.state = state
            return g
        if tag == "torch":
            return _unpack_tensor(v, where, device)
        if tag in ("torch.dtype", "torch.device"):
            import torch

            return getattr(torch, v["name"]) if tag == "torch.dtype" else torch.device(v["name"])
        if tag == "dc":
            cls = _resolve(v["cls"], allowed, where)
            if not dataclasses.is_dataclass(cls):
                raise _corrupt(f"{where}: {v['cls']} is not a dataclass")
            vals = {k: _unpack_any(x, f"{where}.{k}", allowed, device) for k, x in v["fields"].items()}
            spec = dataclasses.fields(cls)
            if {f.name for f in spec} != set(vals):
                raise _corrupt(f"{where}: snapshot fields {sorted(vals)} do not match {v['cls']}")
            try:
                obj = cls(**{f.name: vals[f.name] for f in spec if f.init})
            except (ValueError, TypeError, AssertionError) as e:
                raise _corrupt(f"{where}: not a valid {v['cls']}: {e}") from None
            for f in spec:
                if not f.init:
                    object.__setattr__(obj, f.name, vals[f.name])
            return obj
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        if isinstance(e, DagsError):
            raise
        raise _corrupt(f"{where}: malformed {tag!r} value ({type(e).__name__}: {e})") from None
    raise _corrupt(f"{where}: unknown snapshot tag {tag!r}")


def _unpack_tensor(v: dict, where: str, device: str | None) -> Any:
    import torch

    dtype = getattr(torch, v["dtype"], None)
    if not isinstance(dtype, torch.dtype):
        raise _corrupt(f"{where}: unknown tensor dtype {v['dtype']!r}")
    shape = [int(s) for s in v["shape"]]
    n = int(np.prod(shape, dtype=np.int64))
    itemsize = torch.empty((), dtype=dtype).element_size()
    if n * itemsize != len(v["bytes"]):
        raise _corrupt(f"{where}: {len(v['bytes'])} bytes do not hold a {v['dtype']} tensor of shape {tuple(shape)}")
    t = torch.frombuffer(bytearray(v["bytes"]), dtype=dtype) if n else torch.empty(0, dtype=dtype)
    t = t.reshape(shape)
    target = device if device is not None else v["device"]
    if target != "cpu":
        try:
            t = t.to(target)
        except (RuntimeError, AssertionError) as e:
            raise LogDecodeError(f"{where}: cannot place a tensor on {target} ({str(e).splitlines()[0]}); "
                                 f"decode with device='cpu'") from None
    if v["requires_grad"]:
        t.requires_grad_(True)
    return t


def encode_state(state: object) -> bytes:
    """Bytes of a state snapshot: any nesting of the types listed in the module docstring."""
    return msgpack.packb({"_t": STATE_TYPE, "_v": SCHEMA_VERSION, "value": _pack_any(state, "state")},
                         use_bin_type=True)


def decode_state(data: bytes | memoryview, *, allowed_modules: Iterable[str] = DEFAULT_STATE_MODULES,
                 device: str | None = None) -> Any:
    """The snapshot in ``data``; dataclasses and enums only from the ``allowed_modules`` packages.

    Arrays and tensors come back writable and owning their memory. ``device`` moves every
    tensor there (default: the device it was on when written).
    """
    m = _envelope(data, "state snapshot")
    if m["_t"] != STATE_TYPE:
        raise _corrupt(f"state snapshot: message holds a {m['_t']!r}, not a state snapshot")
    return _unpack_any(m.get("value"), "state", tuple(allowed_modules), device)


# ------------------------------------------------------------------------------ /fields deltas
FIELDS_DELTA_TYPE = "FieldsDelta"
"""``_t`` of a ``/fields`` message stored as the bitwise XOR against the previous step's ``FieldsOut``."""

_GRIDS = ("u_s", "u_m", "n_obs", "visible")


def _grid_offset(cur_origin_m: np.ndarray, cur_shape: tuple[int, ...], prev: records.FieldsOut,
                 voxel_m: float) -> tuple[int, int, int] | None:
    """Where ``prev``'s grid sits inside a grid at ``cur_origin_m`` of ``cur_shape`` (whole voxels), or None."""
    if prev.voxel_m != voxel_m or len(cur_shape) != 3:
        return None
    off = (np.asarray(prev.origin_m) - np.asarray(cur_origin_m)) / voxel_m
    r = np.round(off)
    if not np.all(np.abs(off - r) < 1e-6):
        return None
    o = tuple(int(v) for v in r)
    if any(a < 0 or a + n > m for a, n, m in zip(o, prev.u_s.shape, cur_shape)):
        return None
    return o


def _embedded_bits(prev_grid: np.ndarray, offset: tuple[int, int, int], shape: tuple[int, ...]) -> np.ndarray:
    """``prev_grid``'s bits placed at ``offset`` in a zero grid of ``shape`` (the grid grew around it)."""
    b = _bits(prev_grid)
    if b.shape == tuple(shape):
        return b
    out = np.zeros(shape, b.dtype)
    out[offset[0]:offset[0] + b.shape[0], offset[1]:offset[1] + b.shape[1], offset[2]:offset[2] + b.shape[2]] = b
    return out


def fields_delta_applies(cur: records.FieldsOut, prev: records.FieldsOut | None) -> bool:
    """Whether ``cur`` can be stored as a delta of ``prev``: same voxel size, and ``prev``'s grid lies
    inside ``cur``'s at a whole-voxel offset (the same grid, or one that grew around it)."""
    return prev is not None and _grid_offset(cur.origin_m, cur.u_s.shape, prev, cur.voxel_m) is not None


def _bits(a: np.ndarray) -> np.ndarray:
    """The array's bytes reinterpreted as unsigned integers of the same width (bool -> uint8)."""
    return np.ascontiguousarray(a).view({1: np.uint8, 4: np.uint32, 8: np.uint64}[a.dtype.itemsize])


def encode_fields_delta(cur: records.FieldsOut, prev: records.FieldsOut) -> bytes:
    """``cur`` as the XOR of each grid's bits with ``prev``'s (voxels out of view XOR to 0 and compress away).

    When the grid grew, ``prev`` is placed at its offset inside ``cur``'s grid and the new voxels
    are XORed with zeros (stored as they are).

    Lossless: :func:`decode_fields_delta` with the same ``prev`` gives ``cur`` bit for bit.
    """
    assert fields_delta_applies(cur, prev)
    body = {"origin_m": _pack_array(cur.origin_m), "voxel_m": float(cur.voxel_m)}
    off = _grid_offset(cur.origin_m, cur.u_s.shape, prev, cur.voxel_m)
    for name in _GRIDS:
        base = _embedded_bits(getattr(prev, name), off, cur.u_s.shape)
        body[name] = _pack_array(np.bitwise_xor(_bits(getattr(cur, name)), base))
    return msgpack.packb({"_t": FIELDS_DELTA_TYPE, "_v": SCHEMA_VERSION, **body}, use_bin_type=True)


def is_fields_delta(data: bytes | memoryview) -> bool:
    return type_name(data) == FIELDS_DELTA_TYPE


def decode_fields_delta(data: bytes | memoryview, prev: records.FieldsOut | None) -> records.FieldsOut:
    """The FieldsOut stored in ``data`` as a delta against ``prev`` (the previous step's)."""
    m = _envelope(data, "FieldsDelta")
    if m["_t"] != FIELDS_DELTA_TYPE:
        raise _corrupt(f"message holds a {m['_t']!r}, expected {FIELDS_DELTA_TYPE}")
    if prev is None:
        raise _corrupt("FieldsDelta: no previous /fields message to apply it to")
    grids = {}
    try:
        origin = _unpack_array(m.get("origin_m"), "FieldsDelta.origin_m").copy()
        voxel_m = float(m["voxel_m"])
    except (ValueError, KeyError, TypeError) as e:
        raise _corrupt(f"FieldsDelta: no valid grid origin / voxel size: {e}") from None
    for name in _GRIDS:
        base = getattr(prev, name)
        x = _unpack_array(m.get(name), f"FieldsDelta.{name}")
        off = _grid_offset(origin, x.shape, prev, voxel_m)
        if off is None or x.dtype != _bits(base).dtype:
            raise _corrupt(f"FieldsDelta.{name}: {x.dtype} {x.shape} does not fit the previous grid "
                           f"{base.dtype} {base.shape}")
        grids[name] = np.bitwise_xor(x, _embedded_bits(base, off, x.shape)).view(base.dtype)
    try:
        return records.FieldsOut(origin_m=origin, voxel_m=voxel_m, **grids)
    except (ValueError, KeyError, TypeError) as e:
        raise _corrupt(f"FieldsDelta: not a valid FieldsOut: {e}") from None
