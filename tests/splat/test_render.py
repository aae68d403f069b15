"""The fast CPU rasterizer against the torch reference, and the reference against finite differences.

Tolerances (float64 scenes): images, depths and silhouettes agree to 1e-9 absolute and every
gradient to 1e-8 relative to the largest entry of that gradient. Both backends evaluate the
same float64 expressions with the same culling, tile binning, depth order and thresholds, so
they differ only by summation order (per tile vs per Gaussian) and by the backward pass
recovering T_i = T_{i+1} / (1 - alpha_i), whose relative error grows at most like
(number of layers) x eps / (1 - alpha_max) ~ 1e3 x 1e-16. Threshold decisions (alpha vs
1/255, early stop, tile boxes) can only differ when a value lies within ~1e-16 of a
threshold, which these seeded scenes do not hit. In float32 (the production dtype) the
reference rounds every intermediate to float32 while the fast kernels compute in float64,
so there the bound is 1e-4 on images, as the issue asks.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dynactivegs.errors import DagsError
from dynactivegs.splat import Gaussians, render
from dynactivegs.splat.gaussians import rgb_to_sh0
from dynactivegs.splat.render import gsplat_available
from tests.splat._splat_scenes import camera, random_scene

GRAD_NAMES = ("means", "log_scales", "quats", "opacity_logits", "sh0", "background")


def _render_with_grads(g: Gaussians, K, T, width, height, backend, gen_seed=123):
    """Render, backprop a random linear functional of rgb, depth and alpha; return outputs and grads."""
    gen = torch.Generator().manual_seed(gen_seed)
    dt = g.dtype
    w_rgb = torch.randn(height, width, 3, generator=gen, dtype=dt)
    w_depth = torch.randn(height, width, generator=gen, dtype=dt)
    w_alpha = torch.randn(height, width, generator=gen, dtype=dt)
    gg = g.detach().requires_grad_()
    bg = torch.tensor([0.1, 0.5, 0.9], dtype=dt, requires_grad=True)
    out = render(gg, K, T, width, height, bg, backend=backend)
    loss = (out.rgb * w_rgb).sum() + (out.depth * w_depth).sum() + (out.alpha * w_alpha).sum()
    loss.backward()
    return out, [t.grad for t in gg.tensors()] + [bg.grad]


@pytest.mark.parametrize("seed,n,width,height", [
    (0, 200, 70, 45),      # partial tiles at the right and bottom edges
    (1, 400, 96, 64),      # whole tiles, denser
    (2, 60, 33, 17),       # sparse: background shows, tiny image
])
def test_fast_matches_reference_values_and_gradients(seed, n, width, height):
    gen = torch.Generator().manual_seed(seed)
    g, K, T = random_scene(n, width, height, gen)
    ref, ref_grads = _render_with_grads(g, K, T, width, height, "reference")
    fast, fast_grads = _render_with_grads(g, K, T, width, height, "cpu")
    assert ref.backend == "reference" and fast.backend == "cpu"
    # the scene exercises what it claims: some culled, some visible, transparent and opaque pixels
    assert 0 < int(ref.visible.sum()) < n
    assert float(ref.alpha.detach().min()) < 0.5 < float(ref.alpha.detach().max())
    for name in ("rgb", "depth", "alpha"):
        a, b = getattr(ref, name), getattr(fast, name)
        assert a.shape == b.shape
        assert torch.allclose(a, b, rtol=0, atol=1e-9), f"{name}: max diff {(a - b).abs().max():.3g}"
    assert torch.equal(ref.radii, fast.radii)
    assert torch.equal(ref.n_touched, fast.n_touched)
    assert torch.allclose(ref.weight_sum, fast.weight_sum, rtol=0, atol=1e-9)
    for name, a, b in zip(GRAD_NAMES, ref_grads, fast_grads):
        scale = float(a.abs().max())
        assert scale > 0, f"reference gradient of {name} is all zero: the test would be vacuous"
        err = float((a - b).abs().max())
        assert err <= 1e-8 * scale, f"grad {name}: max diff {err:.3g} vs max |grad| {scale:.3g}"


def test_culled_gaussians_get_zero_gradient():
    gen = torch.Generator().manual_seed(3)
    g, K, T = random_scene(120, 48, 32, gen)
    out, grads = _render_with_grads(g, K, T, 48, 32, "cpu")
    culled = ~out.visible
    assert culled.any()
    for grad in grads[:5]:
        assert torch.all(grad[culled] == 0)


def test_float32_fast_matches_reference_to_1e4():
    gen = torch.Generator().manual_seed(4)
    g, K, T = random_scene(300, 80, 48, gen, dtype=torch.float32)
    ref = render(g, K, T, 80, 48, (0.3, 0.3, 0.3), backend="reference")
    fast = render(g, K, T, 80, 48, (0.3, 0.3, 0.3), backend="cpu")
    assert fast.rgb.dtype == torch.float32
    for name in ("rgb", "alpha"):
        assert (getattr(ref, name) - getattr(fast, name)).abs().max() <= 1e-4
    # depth in metres (up to ~5 m): same relative accuracy
    assert (ref.depth - fast.depth).abs().max() <= 1e-4 * ref.depth.abs().max()


@pytest.mark.parametrize("backend,seed,n,w,h", [("reference", 5, 6, 20, 14), ("cpu", 6, 8, 24, 18)])
def test_backend_matches_finite_differences(backend, seed, n, w, h):
    """torch.autograd.gradcheck (float64 central differences) of a backend on a tiny scene."""
    gen = torch.Generator().manual_seed(seed)
    g, K, T = random_scene(n, w, h, gen, adversarial=False)

    def f(*params):
        out = render(Gaussians(*params), K, T, w, h, (0.2, 0.3, 0.4), backend=backend)
        return out.rgb, out.depth, out.alpha

    params = [t.detach().requires_grad_() for t in g.tensors()]
    assert torch.autograd.gradcheck(f, params, eps=1e-6, atol=1e-5, rtol=1e-4)


def test_single_gaussian_renders_its_colour_depth_and_peak_opacity():
    K, T = camera(33, 33)
    z = 2.0
    p_cam = torch.tensor([[0.0, 0.0, z]], dtype=torch.float64)   # on the optical axis: image centre
    means = p_cam @ torch.as_tensor(T[:3, :3]).T + torch.as_tensor(T[:3, 3])
    g = Gaussians(means=means, log_scales=torch.log(torch.full((1, 3), 0.05, dtype=torch.float64)),
                  quats=torch.tensor([[1.0, 0.0, 0.0, 0.0]], dtype=torch.float64),
                  opacity_logits=torch.logit(torch.tensor([0.8], dtype=torch.float64)),
                  sh0=rgb_to_sh0(torch.tensor([[0.9, 0.2, 0.1]], dtype=torch.float64)))
    for backend in ("reference", "cpu"):
        out = render(g, K, T, 33, 33, (0.0, 0.0, 1.0), backend=backend)
        # pixel (16, 16) has its centre exactly at the projected mean: alpha = opacity
        assert out.alpha[16, 16] == pytest.approx(0.8, abs=1e-12)
        assert torch.allclose(out.rgb[16, 16], torch.tensor([0.72, 0.16, 0.08 + 0.2], dtype=torch.float64))
        assert out.depth[16, 16] == pytest.approx(z, abs=1e-12)
        assert out.alpha[0, 0] == 0.0 and out.depth[0, 0] == 0.0
        assert torch.allclose(out.rgb[0, 0], torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
        # symmetric about the centre, falling off outwards
        assert out.alpha[16, 12] == pytest.approx(float(out.alpha[16, 20]), abs=1e-12)
        assert out.alpha[16, 12] < out.alpha[16, 14] < out.alpha[16, 16]
        assert int(out.n_touched[0]) == int((out.alpha > 0).sum())


def test_gaussian_behind_or_at_the_camera_is_culled():
    K, T = camera(32, 24)
    zs = torch.tensor([-1.0, 0.0, 0.005, 0.5], dtype=torch.float64)
    p_cam = torch.stack([torch.zeros(4, dtype=torch.float64), torch.zeros(4, dtype=torch.float64), zs], dim=-1)
    means = p_cam @ torch.as_tensor(T[:3, :3]).T + torch.as_tensor(T[:3, 3])
    g = Gaussians.from_params(means, torch.full((4, 3), 0.01, dtype=torch.float64),
                              torch.tensor([[1.0, 0, 0, 0]] * 4, dtype=torch.float64),
                              torch.full((4,), 0.9, dtype=torch.float64), torch.full((4, 3), 0.5, dtype=torch.float64))
    for backend in ("reference", "cpu"):
        out = render(g, K, T, 32, 24, backend=backend)
        assert out.visible.tolist() == [False, False, False, True]


def _stack(opacity: float, n: int = 12) -> tuple[Gaussians, np.ndarray, np.ndarray]:
    """n large Gaussians of equal opacity on the optical axis at 1..2 m, camera 17 x 17 px."""
    K, T = camera(17, 17)
    zs = torch.linspace(1.0, 2.0, n, dtype=torch.float64)
    p_cam = torch.stack([torch.zeros(n, dtype=torch.float64), torch.zeros(n, dtype=torch.float64), zs], dim=-1)
    means = p_cam @ torch.as_tensor(T[:3, :3]).T + torch.as_tensor(T[:3, 3])
    colours = torch.rand(n, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    g = Gaussians.from_params(means, torch.full((n, 3), 0.5, dtype=torch.float64),
                              torch.tensor([[1.0, 0, 0, 0]] * n, dtype=torch.float64),
                              torch.full((n,), opacity, dtype=torch.float64), colours)
    return g, K, T


def test_early_termination_is_exclusive():
    """Opacity 0.95 per layer at the centre pixel: T = 0.05, 0.0025, 1.25e-4, then 6.25e-6 <= 1e-4,
    so the fourth layer is not composited and exactly three contribute."""
    g, K, T = _stack(0.95)
    for backend in ("reference", "cpu"):
        out = render(g, K, T, 17, 17, backend=backend)
        assert out.alpha[8, 8] == pytest.approx(1 - 0.05 ** 3, abs=1e-12)
        colours = g.rgb.detach()
        expected = 0.95 * (colours[0] + 0.05 * colours[1] + 0.0025 * colours[2])
        assert torch.allclose(out.rgb[8, 8], expected, atol=1e-12)


def test_alpha_is_clamped_to_0999():
    g, K, T = _stack(0.9999)
    for backend in ("reference", "cpu"):
        out = render(g, K, T, 17, 17, backend=backend)
        # one layer at alpha 0.999 leaves T = 1e-3; the next would bring T below 1e-4
        assert out.alpha[8, 8] == pytest.approx(0.999, abs=1e-12)
        assert torch.allclose(out.rgb[8, 8], 0.999 * g.rgb.detach()[0], atol=1e-12)


def test_fast_backend_is_deterministic_across_thread_counts():
    import numba

    gen = torch.Generator().manual_seed(7)
    g, K, T = random_scene(300, 64, 48, gen)
    runs = []
    before = numba.get_num_threads()
    try:
        for threads in (1, before):
            numba.set_num_threads(threads)
            out, grads = _render_with_grads(g, K, T, 64, 48, "cpu")
            runs.append([out.rgb, out.depth, out.alpha, *grads])
    finally:
        numba.set_num_threads(before)
    for a, b in zip(*runs):
        assert torch.equal(a, b)


_DIGEST = """
import hashlib, torch
from tests.splat._splat_scenes import random_scene
from tests.splat.test_render import _render_with_grads
g, K, T = random_scene(300, 64, 48, torch.Generator().manual_seed(7))
out, grads = _render_with_grads(g, K, T, 64, 48, "cpu")
h = hashlib.sha1()
for t in (out.rgb, out.depth, out.alpha, *grads):
    h.update(t.detach().numpy().tobytes())
print(h.hexdigest())
"""


def test_fast_backend_gives_the_same_bits_compiled_for_any_cpu(tmp_path):
    """Compiled for this CPU and for a generic x86-64 (in fresh processes with their own numba caches), the
    render and its gradients agree bit for bit, so a run gives the same numbers on another machine."""
    import os
    import platform
    import subprocess
    import sys
    from pathlib import Path

    if platform.machine().lower() not in ("x86_64", "amd64"):
        pytest.skip("compares x86-64 targets")
    root = Path(__file__).parents[2]
    digests = []
    for cpu in ("host", "generic"):
        env = {**os.environ, "NUMBA_CPU_NAME": cpu, "NUMBA_CACHE_DIR": str(tmp_path / cpu),
               "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
        out = subprocess.run([sys.executable, "-c", _DIGEST], capture_output=True, text=True, env=env, cwd=root,
                             timeout=600)
        assert out.returncode == 0, out.stderr[-2000:]
        digests.append(out.stdout.strip())
    assert digests[0] == digests[1]


def test_non_finite_gaussians_are_culled_not_drawn():
    gen = torch.Generator().manual_seed(9)
    g, K, T = random_scene(40, 32, 24, gen, adversarial=False)
    clean = [render(g, K, T, 32, 24, backend=b) for b in ("reference", "cpu")]
    means, log_scales, opacity_logits = g.means.clone(), g.log_scales.clone(), g.opacity_logits.clone()
    means[0, 1] = float("nan")
    log_scales[1, 2] = float("nan")
    opacity_logits[2] = float("nan")
    log_scales[3] = 1e4            # exp overflows to inf
    broken = Gaussians(means, log_scales, g.quats, opacity_logits, g.sh0)
    keep = torch.ones(40, dtype=torch.bool)
    keep[:4] = False
    for backend in ("reference", "cpu"):
        out = render(broken, K, T, 32, 24, backend=backend)
        assert not out.visible[:4].any()
        assert torch.isfinite(out.rgb).all() and torch.isfinite(out.depth).all()
        without = render(g.masked(keep), K, T, 32, 24, backend=backend)
        assert torch.allclose(out.rgb, without.rgb, atol=1e-12)
    assert torch.allclose(clean[0].rgb, clean[1].rgb, atol=1e-9)


def test_empty_map_renders_background():
    K, T = camera(20, 10)
    for backend in ("reference", "cpu"):
        out = render(Gaussians.empty(torch.float64), K, T, 20, 10, (0.25, 0.5, 0.75), backend=backend)
        assert out.rgb.shape == (10, 20, 3) and torch.all(out.alpha == 0) and torch.all(out.depth == 0)
        assert torch.allclose(out.rgb, torch.tensor([0.25, 0.5, 0.75], dtype=torch.float64).expand(10, 20, 3))
        assert out.radii.shape == (0, 2)


def test_cuda_backend_without_cuda_is_a_one_line_error():
    if torch.cuda.is_available():
        pytest.skip("this machine has CUDA; the error path is for machines without it")
    K, T = camera(20, 10)
    with pytest.raises(DagsError, match="CUDA") as err:
        render(Gaussians.empty(), K, T, 20, 10, backend="cuda")
    assert "\n" not in str(err.value)


def test_auto_backend_is_cpu_without_cuda_and_matches_it():
    gen = torch.Generator().manual_seed(10)
    g, K, T = random_scene(50, 32, 24, gen, adversarial=False)
    auto = render(g, K, T, 32, 24)
    assert auto.backend == ("cuda" if gsplat_available() else "cpu")
    if auto.backend == "cpu":
        assert torch.equal(auto.rgb, render(g, K, T, 32, 24, backend="cpu").rgb)


def test_bad_camera_inputs_are_one_line_errors():
    K, T = camera(20, 10)
    g = Gaussians.empty()
    with pytest.raises(DagsError, match="backend"):
        render(g, K, T, 20, 10, backend="opengl")  # type: ignore[arg-type]
    with pytest.raises(DagsError, match="rigid"):
        render(g, K, 2.0 * T, 20, 10)
    with pytest.raises(DagsError, match="pinhole"):
        render(g, np.zeros((3, 3)), T, 20, 10)
    with pytest.raises(DagsError, match="background"):
        render(g, K, T, 20, 10, background=(1.0, 0.0))


@pytest.mark.skipif(not gsplat_available(), reason="needs a CUDA device and gsplat (the optional [cuda] extra)")
def test_gsplat_matches_reference():
    """gsplat runs in float32 with fast exp/log: 1e-3 on images is that rounding, not a model difference."""
    gen = torch.Generator().manual_seed(8)
    g, K, T = random_scene(300, 80, 48, gen, dtype=torch.float32, adversarial=False)
    ref, ref_grads = _render_with_grads(g.to(torch.float64), K, T, 80, 48, "reference")
    gpu, gpu_grads = _render_with_grads(g, K, T, 80, 48, "cuda")
    assert gpu.backend == "cuda"
    for name in ("rgb", "alpha"):
        assert (getattr(gpu, name).double().cpu() - getattr(ref, name)).abs().max() <= 1e-3
    assert (gpu.depth.double().cpu() - ref.depth).abs().max() <= 1e-3 * ref.depth.abs().max()
    for name, a, b in zip(GRAD_NAMES, ref_grads, gpu_grads):
        assert (a - b.double().cpu()).abs().max() <= 1e-2 * a.abs().max(), name
