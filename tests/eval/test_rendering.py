"""Image metrics on known pairs, LPIPS availability, and the render metrics of a map."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import ndimage

from dynactivegs.eval.lpips import LpipsAlex, load_lpips
from dynactivegs.eval.rendering import (SeenSplit, depth_l1_cm, psnr_db, psnr_split, render_metrics, seen_split,
                                       ssim_value)
from dynactivegs.splat import Gaussians
from dynactivegs.sim.render import intrinsics
from dynactivegs.sim.robot import camera_pose


def test_psnr_of_identical_images_is_inf_and_of_a_known_mse_is_known():
    rng = np.random.default_rng(0)
    img = rng.integers(50, 200, size=(20, 30, 3)).astype(np.uint8)
    assert psnr_db(img, img) == math.inf
    shifted = (img.astype(np.float64) / 255.0 + 0.1)            # MSE 0.01 -> 20 dB
    assert psnr_db(shifted, img) == pytest.approx(20.0, abs=1e-9)
    plus16 = img + np.uint8(16)                                  # MSE (16 / 255)^2
    assert psnr_db(plus16, img) == pytest.approx(20 * math.log10(255 / 16), abs=1e-9)


def test_seen_split_pools_the_error_of_seen_and_unseen_pixels_over_views():
    h, w = 10, 20
    true = np.full((h, w, 3), 0.5)
    pred = true.copy()
    pred[:, :5] += 0.1                                 # error 0.01 on a quarter, all of it unseen ...
    pred[:, 5:10] += 0.01                              # ... and 1e-4 on a quarter that was seen
    seen = np.zeros((h, w), bool)
    seen[:, 5:] = True
    a = seen_split(pred, true, seen)
    assert (a.seen_px, a.unseen_px) == (150, 50)
    assert a.unseen_sse == pytest.approx(50 * 0.01) and a.seen_sse == pytest.approx(50 * 1e-4)
    unseen_px, unseen_err, psnr_seen, psnr_all = SeenSplit.pooled([a])
    assert unseen_px == 0.25 and unseen_err == pytest.approx(0.5 / 0.505)
    assert psnr_seen == pytest.approx(-10 * np.log10(50 * 1e-4 / 150))
    assert psnr_all == pytest.approx(psnr_db(pred, true)) and psnr_all < psnr_seen
    # a view that saw nothing adds its pixels to the unseen ones and nothing to the seen PSNR
    b = seen_split(pred, true, np.zeros((h, w), bool))
    unseen_px, _, psnr_both, psnr_all_both = SeenSplit.pooled([a, b])
    assert unseen_px == pytest.approx(250 / 400) and psnr_both == pytest.approx(psnr_seen)
    assert psnr_all_both == pytest.approx(psnr_all)                # the same image twice: the same MSE
    assert np.isnan(SeenSplit.pooled([b])[2]) and SeenSplit.pooled([seen_split(true, true, seen)])[2] == np.inf
    with pytest.raises(AssertionError):
        seen_split(pred, true, seen[:, :5])


def test_psnr_split_puts_each_pixel_in_one_class_and_the_error_where_it_is():
    h, w = 10, 20
    true = np.full((h, w, 3), 0.5)
    true_depth = np.full((h, w), 2.0)
    pred, depth, alpha = true.copy(), true_depth.copy(), np.ones((h, w))
    alpha[:, :4] = 0.5                               # a hole: 20 % of the pixels
    depth[:, 4:6] = 1.8                              # 20 cm too near (tolerance 10 cm): front, 10 %
    depth[:, 6:8] = 2.15                             # 15 cm too far: behind, 10 %
    depth[:, 8:10] = 2.08                            # 8 cm off: still right
    pred[:, :4] += 0.2                               # the error: 0.04 per pixel in the hole ...
    pred[:, 4:6] += 0.1                              # ... 0.01 on the front pixels ...
    pred[:, 10:] += 0.01                             # ... 1e-4 on half the right pixels, none on the behind ones
    s = psnr_split(pred, depth, alpha, true, true_depth)
    total = 40 * 0.04 + 20 * 0.01 + 100 * 1e-4
    assert (s.hole_px, s.front_px, s.behind_px) == pytest.approx((0.2, 0.1, 0.1))
    assert s.hole_err == pytest.approx(40 * 0.04 / total) and s.front_err == pytest.approx(20 * 0.01 / total)
    assert s.behind_err == 0.0
    assert s.right_psnr_db == pytest.approx(-10 * math.log10(100 * 1e-4 / 120))    # 120 right pixels
    perfect = psnr_split(true, true_depth, np.ones((h, w)), true, true_depth)
    assert perfect.right_psnr_db == math.inf and perfect.hole_err == perfect.front_err == 0.0
    # A pixel with no true depth return is never front or behind.
    no_return = np.zeros((h, w))
    s = psnr_split(pred, depth, np.ones((h, w)), true, no_return)
    assert s.front_px == s.behind_px == 0.0 and s.hole_px == 0.0


def ssim_twin(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM with scipy's Gaussian filter (sigma 1.5, 11 taps, zero padding), channels averaged."""
    f = lambda x: ndimage.gaussian_filter(x, 1.5, mode="constant", cval=0.0, truncate=5 / 1.5)  # noqa: E731
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    vals = []
    for c in range(3):
        x, y = a[..., c], b[..., c]
        mx, my = f(x), f(y)
        sxx, syy, sxy = f(x * x) - mx * mx, f(y * y) - my * my, f(x * y) - mx * my
        vals.append(((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2)))
    return float(np.mean(vals))


def test_ssim_is_one_for_identical_images_and_matches_an_independent_twin():
    rng = np.random.default_rng(1)
    a = rng.random((24, 32, 3))
    b = np.clip(a + rng.normal(0.0, 0.1, a.shape), 0.0, 1.0)
    assert ssim_value(a, a) == pytest.approx(1.0, abs=1e-12)
    assert ssim_value(b, a) == pytest.approx(ssim_twin(b, a), abs=1e-9)
    assert ssim_value(b, a) < 0.99
    # Constant images far from the border: SSIM reduces to the luminance term (2ab + C1) / (a^2 + b^2 + C1).
    big_a, big_b = np.full((200, 200, 3), 0.5), np.full((200, 200, 3), 0.3)
    interior = (2 * 0.5 * 0.3 + 1e-4) / (0.25 + 0.09 + 1e-4)
    assert ssim_value(big_b, big_a) == pytest.approx(interior, abs=0.01)


def test_depth_l1_counts_only_pixels_with_a_true_return():
    true = np.full((10, 12), 2.0, np.float32)
    true[:, :4] = 0.0                                            # no return there
    pred = true + 0.03
    pred[:, :4] = 100.0                                          # ignored
    assert depth_l1_cm(pred, true) == pytest.approx(3.0, abs=1e-4)
    pred[0, 5] = np.nan                                          # a non-finite render counts as depth 0
    assert depth_l1_cm(pred, true) > 3.0
    assert math.isnan(depth_l1_cm(pred, np.zeros_like(true)))


def lpips_state_dict(seed: int) -> dict[str, torch.Tensor]:
    """Random weights in the lpips package's key layout (stand-ins: these are not trained LPIPS weights)."""
    g = torch.Generator().manual_seed(seed)
    state = {}
    for slice_id, (idx, ci, co, k, _, _) in zip((1, 2, 3, 4, 5), ((0, 3, 64, 11, 0, 0), (3, 64, 192, 5, 0, 0),
                                                                 (6, 192, 384, 3, 0, 0), (8, 384, 256, 3, 0, 0),
                                                                 (10, 256, 256, 3, 0, 0))):
        state[f"net.slice{slice_id}.{idx}.weight"] = torch.randn(co, ci, k, k, generator=g) * 0.05
        state[f"net.slice{slice_id}.{idx}.bias"] = torch.zeros(co)
        state[f"lin{slice_id - 1}.model.1.weight"] = torch.rand(1, co, 1, 1, generator=g)
    state["scaling_layer.shift"] = torch.tensor([-0.030, -0.088, -0.188])[None, :, None, None]
    state["scaling_layer.scale"] = torch.tensor([0.458, 0.448, 0.450])[None, :, None, None]
    return state


def test_lpips_is_unavailable_without_local_weights_and_says_why(tmp_path):
    model, note = load_lpips("")
    assert model is None and "eval.lpips_weights_path" in note
    model, note = load_lpips(str(tmp_path / "missing.pth"))
    assert model is None and "not found" in note
    bad = tmp_path / "bad.pth"
    torch.save({"lin0.model.1.weight": torch.zeros(1, 64, 1, 1)}, bad)
    model, note = load_lpips(str(bad))
    assert model is None and "lack" in note
    garbage = tmp_path / "garbage.pth"
    garbage.write_bytes(b"not a torch file")
    model, note = load_lpips(str(garbage))
    assert model is None and "could not be read" in note


def test_lpips_loads_the_lpips_package_layout_and_is_a_distance(tmp_path):
    path = tmp_path / "alex.pth"
    torch.save(lpips_state_dict(0), path)
    model, note = load_lpips(str(path))
    assert isinstance(model, LpipsAlex) and str(path) in note
    assert torch.equal(model.convs[1].weight, lpips_state_dict(0)["net.slice2.3.weight"])
    g = torch.Generator().manual_seed(3)
    a = torch.rand(1, 3, 92, 160, generator=g)
    b = (a + 0.2 * torch.randn(1, 3, 92, 160, generator=g)).clamp(0, 1)
    with torch.no_grad():
        assert float(model(a, a)[0]) == 0.0
        d_ab, d_ba = float(model(a, b)[0]), float(model(b, a)[0])
    assert d_ab > 0.0 and d_ab == pytest.approx(d_ba, rel=1e-6)


def wall_map(width: int, height: int, K: np.ndarray, T: np.ndarray) -> tuple[Gaussians, np.ndarray, np.ndarray]:
    """Dense small Gaussians on a grey plane 2 m in front of the camera, and the plane's true image and depth."""
    depth = np.full((height, width), 2.0, np.float32)
    rgb = np.full((height, width, 3), 128, np.uint8)
    g = Gaussians.from_rgbd(rgb, depth, K, T, opacity=0.99, scale_factor=1.0)
    return g, rgb, depth


def test_render_metrics_of_a_map_that_matches_the_truth(tmp_path):
    w, h = 48, 28
    K = intrinsics(w, h, 24.0, 24.0)
    T = camera_pose(0.0, 0.0, 0.0, 1.25)
    g, rgb, depth = wall_map(w, h, K, T)
    poses = np.stack([T, T])
    m = render_metrics(g, poses, np.stack([rgb, rgb]), np.stack([depth, depth]), K, backend="cpu")
    assert m.n_views == 2 and m.lpips is None and m.lpips_note == "no LPIPS model given"
    assert m.psnr_db > 35.0 and m.ssim > 0.95 and m.depth_l1_cm < 1.0
    assert m.psnr_views_db == pytest.approx((m.psnr_db, m.psnr_db)) and m.psnr_right_db >= m.psnr_db - 1.0
    assert m.hole_err_pct < 20.0
    # An empty map: black image, depth 0 everywhere -> depth L1 is the full 200 cm.
    empty = render_metrics(Gaussians.empty(), poses[:1], rgb[None], depth[None], K, backend="cpu")
    assert empty.depth_l1_cm == pytest.approx(200.0, abs=1e-3)
    assert empty.psnr_db == pytest.approx(-10 * math.log10((128 / 255) ** 2), abs=1e-6)
    assert empty.hole_err_pct == pytest.approx(100.0) and math.isnan(empty.psnr_right_db)
    path = tmp_path / "alex.pth"
    torch.save(lpips_state_dict(1), path)
    model, note = load_lpips(str(path))
    too_small = render_metrics(g, poses[:1], rgb[None], depth[None], K, lpips_model=model, lpips_note=note,
                               backend="cpu")
    assert too_small.lpips is None and "too small" in too_small.lpips_note
    K64 = intrinsics(64, 40, 32.0, 32.0)
    g64, rgb64, depth64 = wall_map(64, 40, K64, T)
    with_lpips = render_metrics(g64, poses[:1], rgb64[None], depth64[None], K64, lpips_model=model, lpips_note=note,
                                backend="cpu")
    assert with_lpips.lpips is not None and with_lpips.lpips >= 0.0 and with_lpips.lpips_note == note
