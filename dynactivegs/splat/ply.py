"""Reading and writing Gaussian maps in the INRIA 3DGS ``.ply`` layout.

The layout is the one written by the reference 3DGS implementation (Kerbl et al. 2023) and
read by common viewers (SIBR, SuperSplat, antimatter15/splat, gsplat's tools): one
``vertex`` element with the properties

    x y z  nx ny nz  f_dc_0 f_dc_1 f_dc_2  [f_rest_0 .. f_rest_{3K-1}]  opacity
    scale_0 scale_1 scale_2  rot_0 rot_1 rot_2 rot_3

holding exactly our raw parameters: ``f_dc = sh0`` (so rgb = C0 * f_dc + 0.5), ``opacity``
the logit, ``scale_*`` the log standard deviations, ``rot_*`` the quaternion (w x y z, not
necessarily unit). Because stored values are raw parameters, writing and reading back is
bit-exact (float32 maps are written as ``float``, float64 maps as ``double``). Normals are
written as zeros. Higher SH bands are not modelled: ``f_rest_*`` are written as zeros only
when asked (some viewers expect degree 3) and ignored on reading.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from dynactivegs.errors import DagsError
from dynactivegs.splat.gaussians import Gaussians

_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def write_ply(path: str | Path, gaussians: Gaussians, *, sh_rest_coeffs: int = 0) -> None:
    """Write ``gaussians`` as a binary little-endian INRIA 3DGS ``.ply``.

    Args:
        path: output file; its parent directory must exist.
        gaussians: the map (any device; float32 is written as ``float``, float64 as ``double``).
        sh_rest_coeffs: number of zero ``f_rest_*`` properties to add (45 for viewers that
            require SH degree 3; 0 writes none).
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise DagsError(f"cannot write {path}: directory {path.parent} does not exist")
    assert sh_rest_coeffs >= 0
    g = gaussians.detach().to(device="cpu")
    is_f64 = g.dtype == torch.float64
    np_dtype = np.dtype("<f8" if is_f64 else "<f4")
    ply_type = "double" if is_f64 else "float"
    n = len(g)
    columns: list[tuple[str, np.ndarray]] = []
    means = g.means.numpy()
    for i, name in enumerate("xyz"):
        columns.append((name, means[:, i]))
    for name in ("nx", "ny", "nz"):
        columns.append((name, np.zeros(n)))
    sh0 = g.sh0.numpy()
    for i in range(3):
        columns.append((f"f_dc_{i}", sh0[:, i]))
    for i in range(sh_rest_coeffs):
        columns.append((f"f_rest_{i}", np.zeros(n)))
    columns.append(("opacity", g.opacity_logits.numpy()))
    log_scales = g.log_scales.numpy()
    for i in range(3):
        columns.append((f"scale_{i}", log_scales[:, i]))
    quats = g.quats.numpy()
    for i in range(4):
        columns.append((f"rot_{i}", quats[:, i]))

    record = np.empty(n, dtype=[(name, np_dtype) for name, _ in columns])
    for name, values in columns:
        record[name] = values
    header = "ply\nformat binary_little_endian 1.0\n"
    header += f"comment dynactivegs Gaussian map (INRIA 3DGS layout)\nelement vertex {n}\n"
    header += "".join(f"property {ply_type} {name}\n" for name, _ in columns)
    header += "end_header\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(record.tobytes())


def _parse_header(raw: bytes, path: Path) -> tuple[str, int, list[tuple[str, str]], int]:
    """(format, vertex count, [(property, numpy dtype code)], byte offset of the body)."""
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise DagsError(f"{path} is not a PLY file (no 'ply' magic or no 'end_header'); export the map as .ply")
    body_start = raw.find(b"\n", end) + 1
    if body_start == 0:
        raise DagsError(f"{path}: truncated PLY header; re-export the map")
    try:
        lines = raw[:end].decode("ascii").splitlines()
    except UnicodeDecodeError:
        raise DagsError(f"{path}: PLY header is not ASCII; re-export the map") from None
    fmt = ""
    n_vertex = -1
    props: list[tuple[str, str]] = []
    current = None
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            current = words[1]
            if current == "vertex":
                if n_vertex >= 0:
                    raise DagsError(f"{path}: more than one vertex element; expected the INRIA 3DGS layout")
                try:
                    n_vertex = int(words[2])
                except ValueError:
                    raise DagsError(f"{path}: bad vertex count '{words[2]}' in the PLY header") from None
            elif n_vertex < 0:
                raise DagsError(f"{path}: element '{current}' comes before 'vertex'; expected the INRIA 3DGS layout")
        elif words[0] == "property" and current == "vertex":
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise DagsError(f"{path}: unsupported vertex property '{line.strip()}'; expected scalar properties")
            props.append((words[2], _PLY_TYPES[words[1]]))
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise DagsError(f"{path}: unsupported PLY format '{fmt}'; "
                        "expected binary_little_endian, binary_big_endian or ascii")
    if n_vertex < 0:
        raise DagsError(f"{path}: no vertex element; expected the INRIA 3DGS layout")
    return fmt, n_vertex, props, body_start


def read_ply(path: str | Path) -> Gaussians:
    """Read a Gaussian map from an INRIA 3DGS ``.ply`` (binary either endianness, or ASCII).

    Returns a CPU :class:`Gaussians` in float64 if every required property is ``double``,
    else in float32. ``f_rest_*`` and normals are ignored.

    Raises:
        DagsError: the file is missing, not a PLY, truncated, or lacks a required property.
    """
    path = Path(path)
    if not path.is_file():
        raise DagsError(f"Gaussian map file not found: {path}")
    raw = path.read_bytes()
    fmt, n, props, body_start = _parse_header(raw, path)
    names = [p for p, _ in props]
    missing = [r for r in _REQUIRED if r not in names]
    if missing:
        raise DagsError(f"{path}: missing vertex properties {', '.join(missing)}; "
                        "expected the INRIA 3DGS layout (x y z f_dc_0..2 opacity scale_0..2 rot_0..3)")
    if fmt == "ascii":
        rows = raw[body_start:].decode("ascii", errors="replace").split("\n")
        rows = [r for r in rows if r.strip()][:n]
        try:
            table = np.array([[float(v) for v in r.split()] for r in rows], dtype=np.float64).reshape(len(rows), -1)
        except ValueError:
            raise DagsError(f"{path}: malformed ASCII PLY body; re-export the map") from None
        if table.shape != (n, len(props)):
            raise DagsError(f"{path}: ASCII PLY body has {table.shape[0]} rows of {table.shape[1]} values, "
                            f"header says {n} of {len(props)}; re-export the map")
        columns = {name: table[:, i] for i, name in enumerate(names)}
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        record_dtype = np.dtype([(name, endian + code) for name, code in props])
        need = n * record_dtype.itemsize
        if len(raw) - body_start < need:
            raise DagsError(f"{path}: truncated PLY body ({len(raw) - body_start} bytes, header needs {need}); "
                            "re-export the map")
        record = np.frombuffer(raw, dtype=record_dtype, count=n, offset=body_start)
        columns = {name: record[name] for name in names}

    codes = dict(props)
    all_double = all(codes[r] == "f8" for r in _REQUIRED)
    np_dtype = np.float64 if all_double else np.float32
    torch_dtype = torch.float64 if all_double else torch.float32

    def stack(keys: tuple[str, ...]) -> torch.Tensor:
        arr = np.stack([np.asarray(columns[k], dtype=np_dtype) for k in keys], axis=-1)
        return torch.from_numpy(np.ascontiguousarray(arr)).to(torch_dtype)

    return Gaussians(
        means=stack(("x", "y", "z")),
        log_scales=stack(("scale_0", "scale_1", "scale_2")),
        quats=stack(("rot_0", "rot_1", "rot_2", "rot_3")),
        opacity_logits=stack(("opacity",))[:, 0].contiguous(),
        sh0=stack(("f_dc_0", "f_dc_1", "f_dc_2")),
    )
