"""The fields stage: ``step(cfg, rec, state, rng) -> (state, FieldsOut)`` (DESIGN.md §3, §5 Fields)."""

from __future__ import annotations

import numpy as np

from dynactivegs.fields.grid import (
    FieldsConfig, FieldsState, grid_bounds_of_frame, grown, pixel_residual, structural_uncertainty, update_voxels,
)
from dynactivegs.records import FieldsOut, StepRecord

__all__ = ["FieldsConfig", "FieldsState", "init_state", "step"]


def init_state(cfg: FieldsConfig) -> FieldsState:
    """Step 0's state: an empty grid (the first frame allocates it)."""
    assert isinstance(cfg, FieldsConfig)
    return FieldsState.empty()


def step(cfg: FieldsConfig, rec: StepRecord, state: FieldsState | None,
         rng: np.random.Generator) -> tuple[FieldsState, FieldsOut]:
    """Integrate frame t into n_t, e_t and U_m and return U_s (eq. 4), U_m (eq. 5) on the grown grid.

    Reads ``rec.frame`` (depth_m, rgb, K, T_world_cam), ``rec.perception.beta`` and
    ``rec.mapping.render_rgb / render_depth_m / render_alpha`` (the map before this step's
    update, rendered at frame t's pose). Deterministic; ``rng`` is not used.
    """
    assert rec.perception is not None and rec.mapping is not None, "fields runs after perception and mapping"
    f = rec.frame
    beta = rec.perception.beta
    m = rec.mapping
    assert beta.shape == f.depth_m.shape, f"beta {beta.shape} must match depth {f.depth_m.shape}"
    assert m.render_depth_m.shape == f.depth_m.shape, "mapping renders must match the frame"
    state = init_state(cfg) if state is None else state
    lo, hi = grid_bounds_of_frame(cfg, f.depth_m, f.K, f.T_world_cam)
    state = grown(cfg, state, lo, hi)
    residual = pixel_residual(cfg, f.rgb, f.depth_m, m.render_rgb, m.render_depth_m, m.render_alpha)
    state, visible = update_voxels(cfg, state, f.depth_m, f.K, f.T_world_cam, beta, residual)
    out = FieldsOut(
        origin_m=np.array(state.origin_ijk, np.float64) * cfg.voxel_m,
        voxel_m=float(cfg.voxel_m),
        u_s=structural_uncertainty(cfg, state.n_obs, state.e_res),
        u_m=state.u_m.copy(),
        n_obs=state.n_obs.copy(),
        visible=visible,
    )
    return state, out
