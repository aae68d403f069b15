"""Plainly written twin of the fields update, for the tests: one Python loop over every voxel of the grid.

Per voxel it projects the centre, looks up the pixel and applies the rules of
:mod:`dynactivegs.fields.grid` one scalar at a time (no range box, no vectorisation).
"""

from __future__ import annotations

import math

import numpy as np

from dynactivegs.fields.grid import FieldsConfig, FieldsState


def update_voxels_reference(cfg: FieldsConfig, state: FieldsState, depth_m: np.ndarray, K: np.ndarray,
                            T_world_cam: np.ndarray, beta: np.ndarray,
                            residual: np.ndarray) -> tuple[FieldsState, np.ndarray]:
    """Reference of :func:`dynactivegs.fields.grid.update_voxels`."""
    h, w = depth_m.shape
    X, Y, Z = state.shape
    n_obs, e_res, u_m = state.n_obs.copy(), state.e_res.copy(), state.u_m.copy()
    visible = np.zeros(state.shape, bool)
    R = T_world_cam[:3, :3]
    t = T_world_cam[:3, 3]
    o = state.origin_ijk
    for i in range(X):
        for j in range(Y):
            for k in range(Z):
                c = [(o[0] + i + 0.5) * cfg.voxel_m, (o[1] + j + 0.5) * cfg.voxel_m, (o[2] + k + 0.5) * cfg.voxel_m]
                rel = [c[a] - t[a] for a in range(3)]
                dist = math.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2)
                pc = [rel[0] * R[0, a] + rel[1] * R[1, a] + rel[2] * R[2, a] for a in range(3)]
                z = pc[2]
                if z < cfg.min_depth_m or dist > cfg.max_range_m:
                    continue
                u = K[0, 0] * pc[0] / z + K[0, 1] * pc[1] / z + K[0, 2]
                v = K[1, 1] * pc[1] / z + K[1, 2]
                if not (0 <= u < w and 0 <= v < h):
                    continue
                row, col = int(math.floor(v)), int(math.floor(u))
                d = float(depth_m[row, col])
                if d <= 0 or z > d + cfg.surface_margin_m:
                    continue
                surface = abs(z - d) <= cfg.surface_margin_m
                b = float(beta[row, col])
                wgt = min(1.0, (cfg.beta_ref / max(b, 1e-6)) ** 2)
                visible[i, j, k] = True
                n_obs[i, j, k] = np.float32(float(n_obs[i, j, k]) + wgt)
                if surface:
                    e = float(e_res[i, j, k])
                    e_res[i, j, k] = np.float32(e + cfg.e_rate * wgt * (float(residual[row, col]) - e))
                sample = max(b - cfg.beta_static, 0.0) if surface else 0.0
                u_m[i, j, k] = np.float32((1.0 - cfg.a_m) * float(u_m[i, j, k]) + cfg.a_m * sample)
    return FieldsState(state.origin_ijk, n_obs, e_res, u_m), visible


def structural_uncertainty_reference(cfg: FieldsConfig, n: float, e: float) -> float:
    """Eq. (4) for one voxel."""
    return cfg.l_c / math.sqrt(n + cfg.eps) + cfg.l_r * min(max(e, 0.0), cfg.e_max)
