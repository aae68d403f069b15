"""Fields stage: fast update vs. the per-voxel reference, eqs. (4)-(5) on a crafted room, grid growth, purity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.errors import ConfigError
from dynactivegs.fields import FieldsConfig, init_state, step
from dynactivegs.fields._reference import structural_uncertainty_reference, update_voxels_reference
from dynactivegs.fields.grid import FieldsState, grown, pixel_residual, structural_uncertainty, update_voxels
from dynactivegs.records import Frame, MappingOut, PerceptionOut, StepRecord
from dynactivegs.rng import derive_rng

from tests.selection.scenes import intrinsics, render_depth, view

W, H = 48, 28
K = intrinsics(W, H)


def _random_state(rng: np.random.Generator, shape, origin) -> FieldsState:
    return FieldsState(origin, rng.uniform(0, 5, shape).astype(np.float32), rng.uniform(0, 1, shape).astype(np.float32),
                       rng.uniform(0, 2, shape).astype(np.float32))


def test_fast_update_equals_reference_on_seeded_random_frames():
    # Both compute the same float64 expressions in the same order per voxel, so the results are
    # bit-identical in practice; a voxel centre that projects within round-off of a pixel edge
    # could land in the neighbouring pixel in one of them, so up to 0.5 % of the voxels may
    # differ (none did when this was written), and float32 values agree to 1e-6.
    rng = derive_rng(0, "test-fields-twin")
    cfg = FieldsConfig(voxel_m=0.25, max_range_m=3.0)
    n_checked = 0
    for trial in range(6):
        shape = tuple(int(s) for s in rng.integers(6, 14, 3))
        origin = tuple(int(o) for o in rng.integers(-8, 2, 3))
        state = _random_state(rng, shape, origin)
        centre = (np.array(origin) + np.array(shape) / 2) * cfg.voxel_m
        T = view(centre[0] + rng.uniform(-1, 1), centre[1] + rng.uniform(-1, 1), rng.uniform(-math.pi, math.pi),
                 centre[2] + rng.uniform(-0.5, 0.5))
        depth = rng.uniform(0.2, 4.0, (H, W)).astype(np.float32)
        depth[rng.random((H, W)) < 0.15] = 0.0                      # pixels without a return
        if trial == 0:
            depth[:] = 0.0                                          # degenerate: nothing seen
        beta = rng.uniform(0.1, 3.0, (H, W)).astype(np.float32)
        resid = rng.uniform(0, 1, (H, W))
        fast, vis = update_voxels(cfg, state, depth, K, T, beta, resid)
        ref, vis_ref = update_voxels_reference(cfg, state, depth, K, T, beta, resid)
        assert np.mean(vis != vis_ref) <= 0.005
        same = vis == vis_ref
        for a, b in ((fast.n_obs, ref.n_obs), (fast.e_res, ref.e_res), (fast.u_m, ref.u_m)):
            np.testing.assert_allclose(a[same], b[same], rtol=1e-6, atol=1e-6)
        n_checked += int(vis.sum())
        us = structural_uncertainty(cfg, fast.n_obs, fast.e_res)
        i = tuple(int(x) for x in rng.integers(0, shape))
        assert us[i] == pytest.approx(structural_uncertainty_reference(cfg, float(fast.n_obs[i]), float(fast.e_res[i])),
                                      rel=1e-6)
    assert n_checked > 100                                          # the visible case was exercised


def _rec(T, depth, beta, render_depth=None, render_alpha=None, rgb=None, render_rgb=None, step_i=0) -> StepRecord:
    rgb = np.full((H, W, 3), 128, np.uint8) if rgb is None else rgb
    frame = Frame(step_i, step_i * 500_000_000, rgb, depth, K.copy(), T)
    rd = depth.copy() if render_depth is None else render_depth
    ra = np.ones((H, W), np.float32) if render_alpha is None else render_alpha
    mapping = MappingOut(rgb.copy() if render_rgb is None else render_rgb, rd, ra, np.zeros((0, 3), np.int32), 0.05,
                         0, 0, 0, float("nan"), False)
    return StepRecord(frame=frame, perception=PerceptionOut(beta, float("nan"), False), mapping=mapping)


def _room_frame(yaw_deg=0.0, person=True):
    """A 6 x 4 m room seen from (1, 2) looking along +x; a 'person' box at x = 3 with high beta."""
    T = view(1.0, 2.0, math.radians(yaw_deg))
    boxes = [(2.9, 1.7, 3.3, 2.3, 1.8)] if person else []
    depth, which = render_depth(T, K, W, H, (6.0, 4.0), boxes)
    beta = np.where(which == 0, 2.0, 0.1).astype(np.float32)
    return T, depth, beta


def _voxel_value(out, grid, xyz):
    ijk = np.floor((np.asarray(xyz) - out.origin_m) / out.voxel_m).astype(int)
    return float(grid[tuple(ijk)])


def test_motion_uncertainty_rises_on_the_person_and_stays_low_on_the_walls():
    cfg = FieldsConfig()
    T, depth, beta = _room_frame()
    state = init_state(cfg)
    for t in range(10):
        state, out = step(cfg, _rec(T, depth, beta, step_i=t), state, derive_rng(0, "fields", t))
    person = _voxel_value(out, out.u_m, (2.95, 2.0, 1.2))          # the person's front face
    wall = _voxel_value(out, out.u_m, (5.95, 1.0, 1.2))             # the far wall, beside the person
    free = _voxel_value(out, out.u_m, (2.0, 2.0, 1.2))              # free space in front of the person
    assert person > 1.0 and wall == 0.0 and free < 0.05             # the wall's beta 0.1 is below beta_static
    # eq. 5 with a = 0.2 and beta - beta_static = 2 - 0.75 for 10 frames: 1.25 * (1 - 0.8^10)
    assert person == pytest.approx((2.0 - cfg.beta_static) * (1 - 0.8 ** 10), rel=1e-5)
    # the person's pixels count only ~(0.3 / 2)^2 of an observation: U_s stays high there
    assert _voxel_value(out, out.n_obs, (2.95, 2.0, 1.2)) < 0.3
    # the literal eq. 5 (beta_static 0): the wall's U_m is its beta
    lit, state = FieldsConfig(beta_static=0.0), init_state(cfg)
    for t in range(10):
        state, out = step(lit, _rec(T, depth, beta, step_i=t), state, derive_rng(0, "fields", t))
    assert _voxel_value(out, out.u_m, (5.95, 1.0, 1.2)) == pytest.approx(0.1 * (1 - 0.8 ** 10), rel=1e-5)
    assert _voxel_value(out, out.n_obs, (5.95, 1.0, 1.2)) == pytest.approx(10.0)
    assert _voxel_value(out, out.u_s, (5.95, 1.0, 1.2)) == pytest.approx(1 / math.sqrt(11), rel=1e-5)
    # behind the person nothing is visible: never observed, U_s at its maximum l_c / sqrt(eps)
    assert not _voxel_value(out, out.visible, (4.5, 2.0, 1.2))
    assert _voxel_value(out, out.u_s, (4.5, 2.0, 1.2)) == pytest.approx(1.0)


def test_render_residual_raises_structural_uncertainty_where_the_map_is_wrong_or_missing():
    cfg = FieldsConfig()
    T, depth, beta = _room_frame(person=False)
    bad = depth.copy()
    bad[:, : W // 2] += 0.4                                        # the map's left half is 0.4 m off
    alpha = np.ones((H, W), np.float32)
    alpha[:, -4:] = 0.0                                             # and has nothing on the right edge
    _, out = step(cfg, _rec(T, depth, beta, render_depth=bad, render_alpha=alpha), init_state(cfg), derive_rng(0, "f"))
    r = pixel_residual(cfg, np.zeros((H, W, 3), np.uint8), depth, np.zeros((H, W, 3), np.uint8), bad, alpha)
    assert r[0, 0] == pytest.approx(0.4) and r[0, W // 2 + 1] == 0.0 and r[0, -1] == cfg.e_max
    surf = out.visible & (out.n_obs > 0)
    us_ok = structural_uncertainty(cfg, np.ones(1, np.float32), np.zeros(1, np.float32))[0]
    assert np.isclose(out.u_s[surf].min(), us_ok)                   # good surface: only the count term
    assert out.u_s[surf].max() > us_ok + 0.1                        # bad/missing map: residual term on top


def test_grid_grows_deterministically_and_keeps_its_values():
    cfg = FieldsConfig()
    T, depth, beta = _room_frame()
    s1, out1 = step(cfg, _rec(T, depth, beta), init_state(cfg), derive_rng(0, "f"))
    T2 = view(5.0, 2.0, 0.0)
    depth2 = np.full((H, W), 5.5, np.float32)                       # a frame that reaches 5 m beyond the room
    s2, out2 = step(cfg, _rec(T2, depth2, np.full((H, W), 0.1, np.float32), step_i=1), s1, derive_rng(0, "f"))
    assert out2.u_s.shape[0] > out1.u_s.shape[0]
    off = np.round((out1.origin_m - out2.origin_m) / cfg.voxel_m).astype(int)
    assert np.all(off >= 0)
    sl = tuple(slice(o, o + s) for o, s in zip(off, out1.n_obs.shape))
    seen_before_only = ~out2.visible[sl]
    np.testing.assert_array_equal(out2.n_obs[sl][seen_before_only], out1.n_obs[seen_before_only])
    np.testing.assert_array_equal(out2.u_m[sl][seen_before_only], out1.u_m[seen_before_only])
    # origins are multiples of the chunk, the same however the frames arrive
    chunk = round(cfg.grow_chunk_m / cfg.voxel_m)
    assert all(o % chunk == 0 for o in s2.origin_ijk)
    assert grown(cfg, s2, np.zeros(3) + out2.origin_m + 0.1, out2.origin_m + 0.2) is s2


def test_step_is_pure_and_deterministic():
    cfg = FieldsConfig()
    T, depth, beta = _room_frame()
    rec = _rec(T, depth, beta)
    s0 = init_state(cfg)
    s1, out1 = step(cfg, rec, s0, derive_rng(0, "f"))
    s1b, out1b = step(cfg, rec, s0, derive_rng(1, "other"))
    for a in ("u_s", "u_m", "n_obs", "visible", "origin_m"):
        assert np.array_equal(getattr(out1, a), getattr(out1b, a))
    n_before = s1.n_obs.copy()
    step(cfg, rec, s1, derive_rng(0, "f"))
    np.testing.assert_array_equal(s1.n_obs, n_before)              # the input state is not modified
    assert not s1.n_obs.flags.writeable and not out1.u_s.flags.writeable


def test_bad_config_values_raise_config_error():
    for kw in ({"voxel_m": 0.0}, {"a_m": 0.0}, {"eps": 0.0}, {"grow_chunk_m": 0.01}, {"beta_ref": -1.0}):
        with pytest.raises(ConfigError):
            FieldsConfig(**kw)
