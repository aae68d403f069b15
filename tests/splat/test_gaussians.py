"""The Gaussian container: activations, creation from RGB-D, set operations, .ply files."""

from __future__ import annotations

import struct

import numpy as np
import pytest
import torch

from dynactivegs.errors import DagsError
from dynactivegs.splat import SH_C0, Gaussians, render
from dynactivegs.splat.ply import read_ply, write_ply
from tests.splat._splat_scenes import camera, random_scene


def _assert_bit_equal(a: Gaussians, b: Gaussians) -> None:
    assert a.dtype == b.dtype
    for x, y in zip(a.tensors(), b.tensors()):
        assert x.shape == y.shape and torch.equal(x, y)


def test_activations():
    g = Gaussians.from_params(
        means=torch.zeros(2, 3), scales=torch.tensor([[0.1, 0.2, 0.3], [1.0, 1.0, 1.0]]),
        quats=torch.tensor([[2.0, 0.0, 0.0, 0.0], [0.0, 0.0, 3.0, 4.0]]),
        opacities=torch.tensor([0.25, 0.75]), rgb=torch.tensor([[0.0, 0.5, 1.0], [0.2, 0.4, 0.6]]))
    assert torch.allclose(g.scales, torch.tensor([[0.1, 0.2, 0.3], [1.0, 1.0, 1.0]]))
    assert torch.allclose(g.opacities, torch.tensor([0.25, 0.75]))
    assert torch.allclose(g.unit_quats, torch.tensor([[1.0, 0, 0, 0], [0, 0, 0.6, 0.8]]))
    assert torch.allclose(g.rgb, torch.tensor([[0.0, 0.5, 1.0], [0.2, 0.4, 0.6]]), atol=1e-6)
    # colour is clamped at 0 only, as INRIA / gsplat evaluate SH degree 0
    dark_and_bright = Gaussians(g.means, g.log_scales, g.quats, g.opacity_logits,
                                torch.tensor([[-10.0, 0.0, 10.0], [0.0, 0.0, 0.0]]))
    assert dark_and_bright.rgb[0].tolist() == [0.0, 0.5, pytest.approx(0.5 + 10 * SH_C0)]


def test_from_rgbd_backprojects_pixel_centres_with_footprint_scale():
    w, h = 8, 6
    K, T = camera(w, h)
    depth = np.full((h, w), 2.0, dtype=np.float32)
    depth[0, 0] = 0.0                                     # no return: skipped
    rgb = np.zeros((h, w, 3), dtype=np.uint8)
    rgb[..., 0] = 255
    g = Gaussians.from_rgbd(rgb, depth, K, T)
    assert len(g) == w * h - 1
    # back to the camera: every centre projects to its pixel centre at z = 2
    Tinv = np.linalg.inv(T)
    p_cam = g.means.double().numpy() @ Tinv[:3, :3].T + Tinv[:3, 3]
    uv = p_cam[:, :2] / p_cam[:, 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    assert np.allclose(p_cam[:, 2], 2.0, atol=1e-6)
    assert np.allclose(uv - 0.5, np.round(uv - 0.5), atol=1e-5)
    assert torch.allclose(g.scales, torch.full((len(g), 3), 2.0 / K[0, 0]))
    assert torch.allclose(g.rgb, torch.tensor([1.0, 0.0, 0.0]).expand(len(g), 3), atol=1e-6)
    assert torch.allclose(g.opacities, torch.full((len(g),), 0.5))
    # stride and mask select pixels; stride widens the footprint
    mask = np.zeros((h, w), dtype=bool)
    mask[2:, :] = True
    g2 = Gaussians.from_rgbd(rgb, depth, K, T, stride=2, mask=mask)
    assert len(g2) == 2 * 4
    assert torch.allclose(g2.scales, torch.full((8, 3), 4.0 / K[0, 0]))


def test_from_rgbd_render_reproduces_the_frame():
    """Back-projected pixels, rendered from the same camera, give back the colours and depths."""
    w, h = 32, 24
    K, T = camera(w, h)
    v, u = np.mgrid[0:h, 0:w]
    rgb = np.stack([u * 255 // (w - 1), v * 255 // (h - 1), np.full_like(u, 128)], axis=-1).astype(np.uint8)
    depth = np.full((h, w), 3.0, dtype=np.float32)
    g = Gaussians.from_rgbd(rgb, depth, K, T, opacity=0.99, dtype=torch.float64)
    out = render(g, K, T, w, h, backend="cpu")
    inner = (slice(2, -2), slice(2, -2))
    assert float(out.alpha[inner].min()) > 0.99
    assert torch.allclose(out.depth[inner], torch.full((h - 4, w - 4), 3.0, dtype=torch.float64), atol=1e-6)
    err = (out.rgb[inner] - torch.from_numpy(rgb / 255.0)[inner]).abs().mean()
    # all at one depth, so a Gaussian drawn earlier partly covers its neighbours (sigma = one pixel):
    # the colour is off by about one pixel's step of the ramp (1/31 in red), not more
    assert err < 1.5 / 31


def test_cat_and_masked():
    gen = torch.Generator().manual_seed(0)
    a, _, _ = random_scene(10, 16, 16, gen, adversarial=False)
    b, _, _ = random_scene(5, 16, 16, gen, adversarial=False)
    c = Gaussians.cat([a, b])
    assert len(c) == 15 and torch.equal(c.means[10:], b.means)
    keep = torch.zeros(15, dtype=torch.bool)
    keep[[0, 3, 12]] = True
    m = c.masked(keep)
    assert len(m) == 3 and torch.equal(m.sh0[2], b.sh0[2])
    assert len(c.masked(torch.zeros(15, dtype=torch.bool))) == 0
    assert len(Gaussians.cat([Gaussians.empty(torch.float64), a])) == 10


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_ply_round_trip_is_bit_exact(tmp_path, dtype):
    gen = torch.Generator().manual_seed(1)
    g, _, _ = random_scene(257, 40, 30, gen, dtype=dtype)
    path = tmp_path / "map.ply"
    g.save_ply(path)
    back = Gaussians.load_ply(path)
    _assert_bit_equal(g, back)
    # with 45 zero f_rest fields (viewers that expect SH degree 3) it still reads back exactly
    write_ply(tmp_path / "sh3.ply", g, sh_rest_coeffs=45)
    _assert_bit_equal(g, read_ply(tmp_path / "sh3.ply"))


def test_ply_header_is_the_inria_layout(tmp_path):
    g, _, _ = random_scene(3, 16, 16, torch.Generator().manual_seed(2), dtype=torch.float32)
    g.save_ply(tmp_path / "m.ply")
    header = (tmp_path / "m.ply").read_bytes().split(b"end_header\n")[0].decode()
    props = [line.split()[-1] for line in header.splitlines() if line.startswith("property")]
    assert props == ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                     "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    assert "format binary_little_endian 1.0" in header and "element vertex 3" in header
    assert all(line.startswith("property float ") for line in header.splitlines() if line.startswith("property"))


def _write_handmade(path, fmt: str, rows: list[list[float]], names: list[str]) -> None:
    header = f"ply\nformat {fmt} 1.0\nelement vertex {len(rows)}\n"
    header += "".join(f"property float {n}\n" for n in names)
    header += "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
    if fmt == "ascii":
        body = "".join(" ".join(repr(v) for v in r) + "\n" for r in rows).encode()
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        body = b"".join(struct.pack(e + "f" * len(r), *r) for r in rows)
    path.write_bytes(header.encode() + body)


@pytest.mark.parametrize("fmt", ["binary_big_endian", "ascii"])
def test_ply_reads_other_encodings_and_property_orders(tmp_path, fmt):
    names = ["rot_0", "rot_1", "rot_2", "rot_3", "x", "y", "z", "opacity", "f_dc_0", "f_dc_1", "f_dc_2",
             "scale_0", "scale_1", "scale_2", "f_rest_0"]
    rows = [[1.0, 0.0, 0.0, 0.0, 1.5, -2.0, 3.25, 0.5, 0.125, -0.25, 1.0, -3.0, -2.5, -2.0, 9.0],
            [0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, -1.0, -1.0, 9.0]]
    path = tmp_path / "hand.ply"
    _write_handmade(path, fmt, rows, names)
    g = read_ply(path)
    assert g.dtype == torch.float32 and len(g) == 2
    assert g.means[0].tolist() == [1.5, -2.0, 3.25]
    assert g.quats[1].tolist() == [0.5, 0.5, 0.5, 0.5]
    assert g.opacity_logits.tolist() == [0.5, -1.0]
    assert g.sh0[0].tolist() == [0.125, -0.25, 1.0]
    assert g.log_scales[0].tolist() == [-3.0, -2.5, -2.0]


def test_bad_ply_files_raise_one_line_dags_errors(tmp_path):
    good = tmp_path / "good.ply"
    random_scene(4, 16, 16, torch.Generator().manual_seed(3), dtype=torch.float32)[0].save_ply(good)
    raw = good.read_bytes()

    cases = {
        "missing.ply": None,
        "text.ply": b"hello, not a ply\n",
        "truncated.ply": raw[:-10],
        "no_rot.ply": raw.replace(b"property float rot_3\n", b""),  # header lacks a field, body too long is fine
        "bad_format.ply": raw.replace(b"binary_little_endian", b"binary_middle_endian"),
    }
    expect = {"missing.ply": "not found", "text.ply": "not a PLY", "truncated.ply": "truncated",
              "no_rot.ply": "rot_3", "bad_format.ply": "format"}
    for name, content in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(DagsError, match=expect[name]) as err:
            read_ply(path)
        assert "\n" not in str(err.value)
    with pytest.raises(DagsError, match="does not exist"):
        write_ply(tmp_path / "nodir" / "m.ply", Gaussians.empty())
