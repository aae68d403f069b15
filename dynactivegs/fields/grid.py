"""The voxel query grid Omega and its per-frame update (the paper's eqs. 4 and 5).

Grid. A dense box of voxels of edge ``voxel_m``, world-aligned: voxel ``(i, j, k)`` of a grid
whose min corner is the integer voxel offset ``origin_ijk`` has its centre at
``(origin_ijk + (i, j, k) + 0.5) * voxel_m``. It starts empty and grows to contain the
camera and every depth return within ``max_range_m``; new bounds snap outwards to multiples
of ``grow_chunk_m`` (whole voxels, measured from the world origin), so growth is
deterministic, never shifts voxel boundaries and keeps every existing value.

Per voxel the state holds

- ``n_obs``: the effective observation count n_t, the sum over frames of the reliability
  weight ``w(u) = min(1, (beta_ref / beta(u))^2)`` of the pixel the voxel projects to, over the
  frames in which it is *visible*. A pixel at the perception floor (beta ~ 0.1) counts fully,
  a pixel on a person (beta ~ 2) counts about 2 %: uncertain views hardly reduce U_s. The
  weight is the 1 / beta^2 of the mapping loss, clipped at 1 so that n_t stays a count.
- ``e_res``: the aggregated render residual e_t, an exponential moving average over the
  frames in which the voxel is a visible *surface* voxel, with rate ``e_rate * w(u)``, of the
  pixel residual ``r(u) = mean_c |I - I_render| / 255 + depth_weight * min(|D - D_render|,
  depth_clip_m)`` where the render is opaque (alpha >= alpha_min) and the pixel has a depth;
  ``r(u) = e_max`` where the map renders nothing there yet (unmapped is as bad as it gets).
- ``u_m``: the motion uncertainty of eq. (5), updated only where the voxel is visible:
  ``U_m <- (1 - a) U_m + a * b(x)`` with ``b(x) = max(beta(u) - beta_static, 0)`` (beta above the level
  of static surfaces) for a visible surface voxel and
  ``b(x) = 0`` for a visible voxel in the free space in front of the surface. Lifting beta
  only at the surface keeps a person's uncertainty from being smeared along the rays
  toward the camera; over time a voxel's U_m is the rate at which people are seen there
  times their beta. Voxels not visible keep their value (the literal ``1_t(x)`` of eq. 5 would
  decay U_m whenever the robot looks away, forgetting busy places).

Visibility in frame t, ``1_t(x)``: the voxel centre is within ``max_range_m`` (Euclidean) of the
camera, in front of it (z >= min_depth_m), projects into the image at pixel u (nearest pixel:
the one containing the projection), that pixel has a depth return d(u) > 0, and the voxel's
z-depth is at most ``d(u) + surface_margin_m`` (in front of the observed surface, or on it).
A visible voxel is a *surface* voxel when ``|z - d(u)| <= surface_margin_m``.

Eq. (4): ``U_s = l_c / sqrt(n_t + eps) + l_r * clip(e_t, 0, e_max)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynactivegs.errors import check_config


@dataclass(frozen=True, slots=True)
class FieldsConfig:
    """The query grid and the weights of eqs. (4)-(5)."""

    voxel_m: float = 0.15
    """Edge of a query voxel in metres."""
    grow_chunk_m: float = 1.5
    """The grid grows to enclosing multiples of this many metres (rounded to whole voxels)."""
    max_range_m: float = 6.0
    """Returns and voxels farther than this from the camera (Euclidean) are ignored."""
    min_depth_m: float = 0.1
    """Voxels nearer than this z-depth to the camera are not observed."""
    surface_margin_m: float = 0.15
    """A voxel within this z-distance of the observed depth is on the surface; up to this far behind it is still visible."""
    beta_ref: float = 0.3
    """Reliability weight w = min(1, (beta_ref / beta)^2): pixels with beta up to this count as one full observation."""
    l_c: float = 1.0
    """lambda_c of eq. (4): weight of the observation-count term l_c / sqrt(n_t + eps)."""
    l_r: float = 1.0
    """lambda_r of eq. (4): weight of the clipped render residual."""
    eps: float = 1.0
    """eps of eq. (4); an unobserved voxel has U_s = l_c / sqrt(eps) + l_r * e (1 with the defaults)."""
    e_max: float = 1.0
    """Clip of the residual in eq. (4); also the residual of pixels where the map renders nothing yet."""
    depth_weight: float = 1.0
    """Weight (per metre) of the depth residual against the colour residual (colour L1 in [0, 1])."""
    depth_clip_m: float = 0.5
    """Depth residuals are clipped to this before weighting (a wrong depth is wrong whatever the size)."""
    alpha_min: float = 0.5
    """Render opacity below which the map counts as not covering the pixel (residual e_max)."""
    e_rate: float = 0.3
    """EMA rate of the aggregated residual e_t per fully reliable observation."""
    a_m: float = 0.2
    """a of eq. (5): EMA rate of the motion uncertainty U_m."""
    beta_static: float = 0.75
    """The beta of static surfaces: eq. (5) accumulates ``max(beta - beta_static, 0)``. Beta is not zero on static
    surfaces (median 0.41, 90th percentile 0.74 over a 600-step run; people: 10th percentile 1.08), so with the
    literal beta (0 here) U_m of a wall is about its beta and R_m of eq. (9) mostly counts surface."""

    def __post_init__(self) -> None:
        check_config(0.02 <= self.voxel_m <= 2.0, "fields.voxel_m", self.voxel_m, "in [0.02, 2] m")
        check_config(self.grow_chunk_m >= self.voxel_m, "fields.grow_chunk_m", self.grow_chunk_m, ">= fields.voxel_m")
        check_config(self.max_range_m > self.min_depth_m > 0.0, "fields.max_range_m", self.max_range_m,
                     "above fields.min_depth_m > 0")
        check_config(self.surface_margin_m > 0.0, "fields.surface_margin_m", self.surface_margin_m, "> 0 m")
        check_config(self.beta_ref > 0.0, "fields.beta_ref", self.beta_ref, "> 0")
        check_config(self.l_c >= 0.0, "fields.l_c", self.l_c, ">= 0")
        check_config(self.l_r >= 0.0, "fields.l_r", self.l_r, ">= 0")
        check_config(self.eps > 0.0, "fields.eps", self.eps, "> 0")
        check_config(self.e_max > 0.0, "fields.e_max", self.e_max, "> 0")
        check_config(self.depth_weight >= 0.0, "fields.depth_weight", self.depth_weight, ">= 0")
        check_config(self.depth_clip_m > 0.0, "fields.depth_clip_m", self.depth_clip_m, "> 0 m")
        check_config(0.0 <= self.alpha_min <= 1.0, "fields.alpha_min", self.alpha_min, "in [0, 1]")
        check_config(0.0 < self.e_rate <= 1.0, "fields.e_rate", self.e_rate, "in (0, 1]")
        check_config(0.0 < self.a_m <= 1.0, "fields.a_m", self.a_m, "in (0, 1]")
        check_config(self.beta_static >= 0.0, "fields.beta_static", self.beta_static, ">= 0")


@dataclass(frozen=True, slots=True)
class FieldsState:
    """The fields' memory between steps: the grid's placement and its per-voxel accumulators.

    Arrays are read-only; an update returns a new state.
    """

    origin_ijk: tuple[int, int, int]  # integer voxel offset of voxel (0, 0, 0): its min corner is origin_ijk * voxel_m
    n_obs: np.ndarray             # float32 (X, Y, Z) effective observation count n_t
    e_res: np.ndarray             # float32 (X, Y, Z) aggregated render residual e_t
    u_m: np.ndarray               # float32 (X, Y, Z) motion uncertainty U_m (eq. 5)

    def __post_init__(self) -> None:
        s = self.n_obs.shape
        assert len(s) == 3 and self.e_res.shape == s and self.u_m.shape == s
        assert self.n_obs.dtype == self.e_res.dtype == self.u_m.dtype == np.float32
        for a in (self.n_obs, self.e_res, self.u_m):
            a.flags.writeable = False

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.n_obs.shape  # type: ignore[return-value]

    @staticmethod
    def empty() -> "FieldsState":
        z = np.zeros((0, 0, 0), np.float32)
        return FieldsState((0, 0, 0), z, z.copy(), z.copy())


def structural_uncertainty(cfg: FieldsConfig, n_obs: np.ndarray, e_res: np.ndarray) -> np.ndarray:
    """float32, same shape: U_s = l_c / sqrt(n_t + eps) + l_r * clip(e_t, 0, e_max) (eq. 4)."""
    assert n_obs.shape == e_res.shape
    n = n_obs.astype(np.float64)
    e = np.clip(e_res.astype(np.float64), 0.0, cfg.e_max)
    return (cfg.l_c / np.sqrt(n + cfg.eps) + cfg.l_r * e).astype(np.float32)


def valid_points(depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray, max_range_m: float) -> np.ndarray:
    """float64 (N, 3) world points of the pixels with a return within ``max_range_m`` of the camera."""
    h, w = depth_m.shape
    v, u = np.mgrid[0:h, 0:w]
    d = depth_m.astype(np.float64)
    ok = d > 0
    z = d[ok]
    x = (u[ok] + 0.5 - K[0, 2]) / K[0, 0] * z
    y = (v[ok] + 0.5 - K[1, 2]) / K[1, 1] * z
    p = np.stack([x, y, z], axis=1)
    p = p[np.linalg.norm(p, axis=1) <= max_range_m]
    return p @ T_world_cam[:3, :3].T + T_world_cam[:3, 3]


def grown(cfg: FieldsConfig, state: FieldsState, lo_m: np.ndarray, hi_m: np.ndarray) -> FieldsState:
    """``state`` with its grid enlarged (new voxels: n = e = U_m = 0) to contain the box ``[lo_m, hi_m]``.

    New bounds snap outwards to multiples of ``grow_chunk_m`` in whole voxels; returns
    ``state`` itself when the box is already inside.
    """
    chunk = max(1, int(round(cfg.grow_chunk_m / cfg.voxel_m)))
    g_lo = np.floor(np.asarray(lo_m, np.float64) / cfg.voxel_m).astype(np.int64)
    g_hi = np.floor(np.asarray(hi_m, np.float64) / cfg.voxel_m).astype(np.int64) + 1
    o = np.array(state.origin_ijk, np.int64)
    s = np.array(state.shape, np.int64)
    has = bool(np.all(s > 0))
    if has and np.all(g_lo >= o) and np.all(g_hi <= o + s):
        return state
    n_lo = (g_lo // chunk) * chunk
    n_hi = -((-g_hi) // chunk) * chunk
    if has:
        n_lo = np.minimum(n_lo, o)
        n_hi = np.maximum(n_hi, o + s)
    shape = tuple(int(a) for a in n_hi - n_lo)
    sl = tuple(slice(int(a), int(a + b)) for a, b in zip(o - n_lo, s))
    out = []
    for a in (state.n_obs, state.e_res, state.u_m):
        b = np.zeros(shape, np.float32)
        if has:
            b[sl] = a
        out.append(b)
    return FieldsState(tuple(int(a) for a in n_lo), *out)


def pixel_residual(cfg: FieldsConfig, rgb: np.ndarray, depth_m: np.ndarray, render_rgb: np.ndarray,
                   render_depth_m: np.ndarray, render_alpha: np.ndarray) -> np.ndarray:
    """float64 (H, W) per-pixel render residual r(u) in [0, e_max] (see the module docstring)."""
    assert rgb.shape == render_rgb.shape and depth_m.shape == render_depth_m.shape == render_alpha.shape
    col = np.abs(rgb.astype(np.float64) - render_rgb.astype(np.float64)).mean(axis=2) / 255.0
    has_d = (depth_m > 0) & (render_depth_m > 0)
    dd = np.where(has_d, np.minimum(np.abs(depth_m.astype(np.float64) - render_depth_m.astype(np.float64)),
                                    cfg.depth_clip_m), 0.0)
    r = col + cfg.depth_weight * dd
    r = np.where(render_alpha >= cfg.alpha_min, r, cfg.e_max)
    return np.clip(r, 0.0, cfg.e_max)


def pixel_weight(cfg: FieldsConfig, beta: np.ndarray) -> np.ndarray:
    """float64 (H, W) reliability weight w = min(1, (beta_ref / beta)^2)."""
    b = np.maximum(beta.astype(np.float64), 1e-6)
    return np.minimum(1.0, (cfg.beta_ref / b) ** 2)


def voxel_box_near(cfg: FieldsConfig, state: FieldsState, cam_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """int64 (3,) lo and hi (exclusive) grid indices of the voxels whose centres may lie within max_range of ``cam_m``."""
    o = np.array(state.origin_ijk, np.int64)
    lo = np.floor((cam_m - cfg.max_range_m) / cfg.voxel_m - 0.5).astype(np.int64) - o
    hi = np.ceil((cam_m + cfg.max_range_m) / cfg.voxel_m - 0.5).astype(np.int64) + 1 - o
    s = np.array(state.shape, np.int64)
    return np.clip(lo, 0, s), np.clip(hi, 0, s)


def project_voxels(cfg: FieldsConfig, centres_m: np.ndarray, depth_m: np.ndarray, K: np.ndarray,
                   T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visibility of voxel centres (N, 3) in one frame: (visible bool (N,), surface bool (N,), flat pixel int64 (N,)).

    The pixel index is valid only where ``visible``. See the module docstring for the rule.
    """
    h, w = depth_m.shape
    R = T_world_cam[:3, :3]
    t = T_world_cam[:3, 3]
    rel = centres_m - t
    dist = np.sqrt((rel * rel).sum(axis=1))
    pc = rel @ R                                   # camera coordinates (R^T rel for each row)
    z = pc[:, 2]
    front = (z >= cfg.min_depth_m) & (dist <= cfg.max_range_m)
    zs = np.where(front, z, 1.0)
    u = K[0, 0] * pc[:, 0] / zs + K[0, 1] * pc[:, 1] / zs + K[0, 2]
    v = K[1, 1] * pc[:, 1] / zs + K[1, 2]
    inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    col = np.where(inside, np.floor(u), 0).astype(np.int64)
    row = np.where(inside, np.floor(v), 0).astype(np.int64)
    pix = row * w + col
    d = depth_m.reshape(-1)[pix].astype(np.float64)
    visible = inside & (d > 0) & (z <= d + cfg.surface_margin_m)
    surface = visible & (np.abs(z - d) <= cfg.surface_margin_m)
    return visible, surface, pix


def voxel_centres(cfg: FieldsConfig, state: FieldsState, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """float64 (N, 3) centres of the voxels of the index box [lo, hi), in C order."""
    o = np.array(state.origin_ijk, np.float64)
    axes = [(o[a] + np.arange(lo[a], hi[a], dtype=np.float64) + 0.5) * cfg.voxel_m for a in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    return np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)


def update_voxels(cfg: FieldsConfig, state: FieldsState, depth_m: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray,
                  beta: np.ndarray, residual: np.ndarray) -> tuple[FieldsState, np.ndarray]:
    """One frame's update of n_t, e_t and U_m on an already grown grid; returns the state and ``visible`` bool (X, Y, Z).

    ``depth_m`` float32 (H, W); ``beta`` float32 (H, W); ``residual`` float64 (H, W) from
    :func:`pixel_residual`. Only the box of voxels within range of the camera is touched.
    """
    assert beta.shape == depth_m.shape == residual.shape
    shape = state.shape
    visible = np.zeros(shape, np.bool_)
    n_obs, e_res, u_m = state.n_obs.copy(), state.e_res.copy(), state.u_m.copy()
    if 0 in shape:
        return FieldsState(state.origin_ijk, n_obs, e_res, u_m), visible
    cam = T_world_cam[:3, 3].astype(np.float64)
    lo, hi = voxel_box_near(cfg, state, cam)
    if np.any(hi <= lo):
        return FieldsState(state.origin_ijk, n_obs, e_res, u_m), visible
    sl = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi))
    vis, surf, pix = project_voxels(cfg, voxel_centres(cfg, state, lo, hi), depth_m, K, T_world_cam)
    wgt = pixel_weight(cfg, beta).reshape(-1)[pix]
    b = beta.reshape(-1)[pix].astype(np.float64)
    r = residual.reshape(-1)[pix]
    sub_shape = tuple(int(b_ - a_) for a_, b_ in zip(lo, hi))

    n_sub = n_obs[sl].reshape(-1).astype(np.float64)
    n_sub = np.where(vis, n_sub + wgt, n_sub)
    e_sub = e_res[sl].reshape(-1).astype(np.float64)
    rate = cfg.e_rate * wgt
    e_sub = np.where(surf, e_sub + rate * (r - e_sub), e_sub)
    m_sub = u_m[sl].reshape(-1).astype(np.float64)
    sample = np.where(surf, np.maximum(b - cfg.beta_static, 0.0), 0.0)
    m_sub = np.where(vis, (1.0 - cfg.a_m) * m_sub + cfg.a_m * sample, m_sub)   # eq. (5)

    n_obs[sl] = n_sub.reshape(sub_shape).astype(np.float32)
    e_res[sl] = e_sub.reshape(sub_shape).astype(np.float32)
    u_m[sl] = m_sub.reshape(sub_shape).astype(np.float32)
    visible[sl] = vis.reshape(sub_shape)
    return FieldsState(state.origin_ijk, n_obs, e_res, u_m), visible


def grid_bounds_of_frame(cfg: FieldsConfig, depth_m: np.ndarray, K: np.ndarray,
                         T_world_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 (3,) lo and hi of the camera and the frame's returns within range (what the grid must contain)."""
    pts = valid_points(depth_m, K, T_world_cam, cfg.max_range_m)
    cam = T_world_cam[:3, 3].astype(np.float64)
    if len(pts) == 0:
        return cam.copy(), cam.copy()
    return np.minimum(pts.min(axis=0), cam), np.maximum(pts.max(axis=0), cam)


__all__ = ["FieldsConfig", "FieldsState", "structural_uncertainty", "grown", "pixel_residual", "pixel_weight",
           "update_voxels", "project_voxels", "grid_bounds_of_frame", "voxel_centres"]
