"""Fast CPU rasterizer: numba kernels (``parallel=True``, ``cache=True``) and a hand-written backward.

Same image model as :mod:`dynactivegs.splat._reference` (see :mod:`dynactivegs.splat._common`);
the kernels compute in float64 whatever the input dtype, and outputs are cast back. Raw
parameters go in; activations, expected depth and their derivatives are done here in NumPy.

Pipeline (forward), each step a kernel below:

1. ``_project_fwd`` (parallel over Gaussians): EWA projection (Zwicker et al. 2002,
   eq. (31)-(34)), culling, conics, screen boxes.
2. ``_bin_tiles`` (serial, O(N log N + pairs)): one entry per (Gaussian, overlapped tile)
   pair, entries numbered in Gaussian order; one stable argsort of the depths, then a
   counting sort by tile visiting Gaussians front to back, gives every tile its list in
   depth order with ties in index order (as gsplat's radix sort of (tile | depth) keys).
3. ``_raster_fwd`` (parallel over tiles): front-to-back compositing. Within a tile the
   Gaussians are visited in depth order and each updates only the pixels inside its ellipse
   ``sigma <= ln(o / ALPHA_MIN)`` (rows from its exact height, per row the interval solved
   from the quadratic, both padded by ``SPAN_MARGIN`` px and then tested exactly). Outside
   that ellipse alpha < 1/255, so this is the same per-pixel sequence as a pixel-major loop
   over the tile list, minus pixels that would be skipped anyway. Along a row,
   o exp(-sigma) is updated by two multiplications per pixel (the exponent is quadratic
   in u), starting from two exps at the row's first pixel, where it is about 1/255 or more.

Backward: ``_raster_bwd`` walks each tile back to front from every pixel's last
contributor, recovering T_i = T_{i+1} / (1 - alpha_i) (as gsplat does), and accumulates the
gradient of each (Gaussian, tile) entry in that entry's own row; ``_reduce_entries`` sums the
rows of each Gaussian in entry order, and ``_project_bwd`` applies the chain rule of step 1.
No two threads ever add into the same memory, so results are bitwise deterministic and
independent of the number of threads. No kernel uses ``fastmath``: with it, LLVM may reorder
and fuse floating-point operations differently for each CPU it compiles for (measured: one
render and its backward gave different bits for the host CPU and ``NUMBA_CPU_NAME=generic``),
and a closed loop turns a last-bit difference into a different run. Without it both targets
give the same bits (a test compares them), at no measured cost in speed.

The kernels compile once (``cache=True`` keeps the machine code under ``__pycache__``), so
only the first render in a fresh environment pays a few seconds of compilation.

For pixel p and its contributing Gaussians i = 1..M (front to back), with
w_i = alpha_i T_i, T_i = prod_{j<i} (1 - alpha_j), T = T_{M+1}:

    C = sum_i w_i c_i + T bg,   D = sum_i w_i z_i,   A = 1 - T
    dC/dalpha_i = T_i c_i - (sum_{j>i} w_j c_j + T bg) / (1 - alpha_i)
    dD/dalpha_i = T_i z_i - (sum_{j>i} w_j z_j) / (1 - alpha_i)
    dA/dalpha_i = T / (1 - alpha_i)
"""

from __future__ import annotations

import math
import os

import numba
import numpy as np
import torch
from numba import njit, prange

from dynactivegs.splat._common import (
    ALPHA_MAX, ALPHA_MIN, EPS2D, EXTEND_MAX, FAR_PLANE, FOV_CLAMP, RADIUS_MAX, T_MIN, TILE,
)
from dynactivegs.splat.gaussians import SH_C0

# numba's OpenMP layer shares the machine with torch's OpenMP workers, which busy-wait after
# every torch op; on a 2-core machine that made a 20k-Gaussian render ~3x slower (and a tiny
# one ~20x). The workqueue layer has no such interaction. It is chosen only when the user has
# not picked a layer; it must not be entered from several Python threads at once.
if numba.config.THREADING_LAYER == "default" and "NUMBA_THREADING_LAYER" not in os.environ:
    numba.config.THREADING_LAYER = "workqueue"

N_GRAD = 10         # per-entry gradient row: mean2d x, y; conic a, b, c; opacity; colour r, g, b; depth
SPAN_MARGIN = 1e-4  # px added on both sides of each row span and row range


# --------------------------------------------------------------------------- 3x3 helpers
# 3x3 matrices are 9-tuples in row-major order; small tuples stay in registers under numba.

@njit(cache=True)
def _quat_to_rotmat(w, x, y, z):
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


@njit(cache=True)
def _mm(a, b):
    """a @ b."""
    return (a[0] * b[0] + a[1] * b[3] + a[2] * b[6], a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
            a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
            a[3] * b[0] + a[4] * b[3] + a[5] * b[6], a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
            a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
            a[6] * b[0] + a[7] * b[3] + a[8] * b[6], a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
            a[6] * b[2] + a[7] * b[5] + a[8] * b[8])


@njit(cache=True)
def _tr(a):
    return (a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8])


@njit(cache=True)
def _covariances(q, s, W):
    """Rotation R_q, M = R_q S, and camera-frame covariance W (M M^T) W^T."""
    R = _quat_to_rotmat(q[0], q[1], q[2], q[3])
    M = (R[0] * s[0], R[1] * s[1], R[2] * s[2],
         R[3] * s[0], R[4] * s[1], R[5] * s[2],
         R[6] * s[0], R[7] * s[1], R[8] * s[2])
    cov_c = _mm(_mm(W, _mm(M, _tr(M))), _tr(W))
    return R, M, cov_c


# --------------------------------------------------------------------------- projection
@njit(cache=True, parallel=True)
def _project_fwd(means, quats, scales, opac, vm, fx, fy, cx, cy, width, height, near,
                 means2d, conics, depths, radii):
    """Project N Gaussians; culled ones get radii (0, 0). Outputs are (N, 2), (N, 3), (N,), (N, 2)."""
    n = means.shape[0]
    W = (vm[0, 0], vm[0, 1], vm[0, 2], vm[1, 0], vm[1, 1], vm[1, 2], vm[2, 0], vm[2, 1], vm[2, 2])
    tan_x = 0.5 * width / fx
    tan_y = 0.5 * height / fy
    lim_xp = (width - cx) / fx + FOV_CLAMP * tan_x
    lim_xn = cx / fx + FOV_CLAMP * tan_x
    lim_yp = (height - cy) / fy + FOV_CLAMP * tan_y
    lim_yn = cy / fy + FOV_CLAMP * tan_y
    for g in prange(n):
        radii[g, 0] = 0
        radii[g, 1] = 0
        px, py, pz = means[g, 0], means[g, 1], means[g, 2]
        z = W[6] * px + W[7] * py + W[8] * pz + vm[2, 3]
        if not (z >= near and z <= FAR_PLANE):   # written so that NaN is culled too
            continue
        x = W[0] * px + W[1] * py + W[2] * pz + vm[0, 3]
        y = W[3] * px + W[4] * py + W[5] * pz + vm[1, 3]
        _, _, S = _covariances((quats[g, 0], quats[g, 1], quats[g, 2], quats[g, 3]),
                               (scales[g, 0], scales[g, 1], scales[g, 2]), W)
        tx = z * min(lim_xp, max(-lim_xn, x / z))
        ty = z * min(lim_yp, max(-lim_yn, y / z))
        j00 = fx / z
        j02 = -fx * tx / (z * z)
        j11 = fy / z
        j12 = -fy * ty / (z * z)
        # cov2d = J S J^T with J = [[j00, 0, j02], [0, j11, j12]]
        r00 = j00 * S[0] + j02 * S[6]
        r01 = j00 * S[1] + j02 * S[7]
        r02 = j00 * S[2] + j02 * S[8]
        r11 = j11 * S[4] + j12 * S[7]
        r12 = j11 * S[5] + j12 * S[8]
        a = r00 * j00 + r02 * j02 + EPS2D
        b = r01 * j11 + r02 * j12
        c = r11 * j11 + r12 * j12 + EPS2D
        det = a * c - b * b
        if not det > 0.0:
            continue
        o = opac[g]
        if not o >= ALPHA_MIN:
            continue
        extend = min(EXTEND_MAX, math.sqrt(2.0 * math.log(max(o / ALPHA_MIN, 1.0))))
        rx = float(math.ceil(min(extend * math.sqrt(a), RADIUS_MAX)))
        ry = float(math.ceil(min(extend * math.sqrt(c), RADIUS_MAX)))
        if rx <= 0.0 and ry <= 0.0:
            continue
        mx = fx * x / z + cx
        my = fy * y / z + cy
        if not (mx + rx > 0.0 and mx - rx < width and my + ry > 0.0 and my - ry < height):
            continue
        radii[g, 0] = np.int32(rx)
        radii[g, 1] = np.int32(ry)
        means2d[g, 0] = mx
        means2d[g, 1] = my
        depths[g] = z
        conics[g, 0] = c / det
        conics[g, 1] = -b / det
        conics[g, 2] = a / det


@njit(cache=True, parallel=True)
def _project_bwd(means, quats, scales, vm, fx, fy, cx, cy, width, height, radii, conics,
                 v_means2d, v_conics, v_depths, v_means, v_quats, v_scales):
    """Chain rule of ``_project_fwd`` for the Gaussians that were not culled (others get 0)."""
    n = means.shape[0]
    W = (vm[0, 0], vm[0, 1], vm[0, 2], vm[1, 0], vm[1, 1], vm[1, 2], vm[2, 0], vm[2, 1], vm[2, 2])
    tan_x = 0.5 * width / fx
    tan_y = 0.5 * height / fy
    lim_xp = (width - cx) / fx + FOV_CLAMP * tan_x
    lim_xn = cx / fx + FOV_CLAMP * tan_x
    lim_yp = (height - cy) / fy + FOV_CLAMP * tan_y
    lim_yn = cy / fy + FOV_CLAMP * tan_y
    for g in prange(n):
        for i in range(3):
            v_means[g, i] = 0.0
            v_scales[g, i] = 0.0
        for i in range(4):
            v_quats[g, i] = 0.0
        if radii[g, 0] <= 0 and radii[g, 1] <= 0:
            continue
        px, py, pz = means[g, 0], means[g, 1], means[g, 2]
        x = W[0] * px + W[1] * py + W[2] * pz + vm[0, 3]
        y = W[3] * px + W[4] * py + W[5] * pz + vm[1, 3]
        z = W[6] * px + W[7] * py + W[8] * pz + vm[2, 3]
        q = (quats[g, 0], quats[g, 1], quats[g, 2], quats[g, 3])
        s = (scales[g, 0], scales[g, 1], scales[g, 2])
        R, M, S = _covariances(q, s, W)
        rx_ok = -lim_xn <= x / z <= lim_xp
        ry_ok = -lim_yn <= y / z <= lim_yp
        tx = z * min(lim_xp, max(-lim_xn, x / z))
        ty = z * min(lim_yp, max(-lim_yn, y / z))
        j00 = fx / z
        j02 = -fx * tx / (z * z)
        j11 = fy / z
        j12 = -fy * ty / (z * z)

        # conic = cov2d^-1: dL/dcov2d = -conic G conic, G the symmetric gradient of the conic
        A, B, C = conics[g, 0], conics[g, 1], conics[g, 2]
        g00, g01, g11 = v_conics[g, 0], 0.5 * v_conics[g, 1], v_conics[g, 2]
        p00 = A * g00 + B * g01
        p01 = A * g01 + B * g11
        p10 = B * g00 + C * g01
        p11 = B * g01 + C * g11
        V00 = -(p00 * A + p01 * B)
        V01 = -0.5 * ((p00 * B + p01 * C) + (p10 * A + p11 * B))
        V11 = -(p10 * B + p11 * C)

        # cov2d = J S J^T: dL/dS = J^T V J, dL/dJ = 2 V J S  (V, S symmetric)
        # J^T V: rows (3) x cols (2)
        a0 = j00 * V00
        a1 = j00 * V01
        b0 = j11 * V01
        b1 = j11 * V11
        c0 = j02 * V00 + j12 * V01
        c1 = j02 * V01 + j12 * V11
        # (J^T V) J, J rows: (j00, 0, j02), (0, j11, j12)
        vS = (a0 * j00, a1 * j11, a0 * j02 + a1 * j12,
              b0 * j00, b1 * j11, b0 * j02 + b1 * j12,
              c0 * j00, c1 * j11, c0 * j02 + c1 * j12)
        # V J (2x3), then (V J) S
        vj0 = (V00 * j00, V01 * j11, V00 * j02 + V01 * j12)
        vj1 = (V01 * j00, V11 * j11, V01 * j02 + V11 * j12)
        dJ00 = 2.0 * (vj0[0] * S[0] + vj0[1] * S[3] + vj0[2] * S[6])
        dJ02 = 2.0 * (vj0[0] * S[2] + vj0[1] * S[5] + vj0[2] * S[8])
        dJ11 = 2.0 * (vj1[0] * S[1] + vj1[1] * S[4] + vj1[2] * S[7])
        dJ12 = 2.0 * (vj1[0] * S[2] + vj1[1] * S[5] + vj1[2] * S[8])

        vmx, vmy = v_means2d[g, 0], v_means2d[g, 1]
        vx = fx / z * vmx
        vy = fy / z * vmy
        vz = -fx * x / (z * z) * vmx - fy * y / (z * z) * vmy + v_depths[g]
        vz += -fx / (z * z) * dJ00 - fy / (z * z) * dJ11
        if rx_ok:   # J02 = -fx x / z^2
            vx += -fx / (z * z) * dJ02
            vz += 2.0 * fx * x / (z * z * z) * dJ02
        else:       # J02 = -fx L / z with L the clamp limit
            vz += fx * tx / (z * z * z) * dJ02
        if ry_ok:
            vy += -fy / (z * z) * dJ12
            vz += 2.0 * fy * y / (z * z * z) * dJ12
        else:
            vz += fy * ty / (z * z * z) * dJ12
        # mean_c = W mean + t
        v_means[g, 0] = W[0] * vx + W[3] * vy + W[6] * vz
        v_means[g, 1] = W[1] * vx + W[4] * vy + W[7] * vz
        v_means[g, 2] = W[2] * vx + W[5] * vy + W[8] * vz
        # S = W Sigma W^T: dL/dSigma = W^T vS W; Sigma = M M^T: dL/dM = 2 dL/dSigma M
        vSig = _mm(_mm(_tr(W), vS), W)
        vM = _mm(vSig, M)
        vM = (2.0 * vM[0], 2.0 * vM[1], 2.0 * vM[2], 2.0 * vM[3], 2.0 * vM[4], 2.0 * vM[5],
              2.0 * vM[6], 2.0 * vM[7], 2.0 * vM[8])
        # M = R diag(s)
        for j in range(3):
            v_scales[g, j] = vM[j] * R[j] + vM[3 + j] * R[3 + j] + vM[6 + j] * R[6 + j]
        G = (vM[0] * s[0], vM[1] * s[1], vM[2] * s[2],
             vM[3] * s[0], vM[4] * s[1], vM[5] * s[2],
             vM[6] * s[0], vM[7] * s[1], vM[8] * s[2])
        w, qx, qy, qz = q
        v_quats[g, 0] = 2.0 * (-qz * G[1] + qy * G[2] + qz * G[3] - qx * G[5] - qy * G[6] + qx * G[7])
        v_quats[g, 1] = 2.0 * (qy * G[1] + qz * G[2] + qy * G[3] - 2.0 * qx * G[4] - w * G[5]
                               + qz * G[6] + w * G[7] - 2.0 * qx * G[8])
        v_quats[g, 2] = 2.0 * (-2.0 * qy * G[0] + qx * G[1] + w * G[2] + qx * G[3] + qz * G[5]
                               - w * G[6] + qz * G[7] - 2.0 * qy * G[8])
        v_quats[g, 3] = 2.0 * (-2.0 * qz * G[0] - w * G[1] + qx * G[2] + w * G[3] - 2.0 * qz * G[4]
                               + qy * G[5] + qx * G[6] + qy * G[7])


# --------------------------------------------------------------------------- binning
@njit(cache=True)
def _bin_tiles(means2d, radii, depths, tiles_x, tiles_y):
    """Entries (Gaussian, tile), numbered in Gaussian order, and each tile's list in depth order.

    Returns g_off (N+1,) the entry range of each Gaussian, entry_gid (E,), tile_off (tiles+1,)
    and tile_entries (E,): the entry ids of tile t are tile_entries[tile_off[t]:tile_off[t+1]],
    front to back. The lists are filled by visiting Gaussians in a stable depth order, so ties
    keep index order, as gsplat's radix sort of (tile | depth) keys does.
    """
    n = means2d.shape[0]
    g_off = np.zeros(n + 1, dtype=np.int64)
    x0s = np.zeros(n, dtype=np.int64)
    x1s = np.zeros(n, dtype=np.int64)
    y0s = np.zeros(n, dtype=np.int64)
    y1s = np.zeros(n, dtype=np.int64)
    keys = np.empty(n)
    for g in range(n):
        cnt = 0
        keys[g] = np.inf
        if radii[g, 0] > 0 or radii[g, 1] > 0:
            mx = means2d[g, 0] / TILE
            my = means2d[g, 1] / TILE
            rx = radii[g, 0] / TILE
            ry = radii[g, 1] / TILE
            x0s[g] = int(min(max(0.0, math.floor(mx - rx)), tiles_x))
            x1s[g] = int(min(max(0.0, math.ceil(mx + rx)), tiles_x))
            y0s[g] = int(min(max(0.0, math.floor(my - ry)), tiles_y))
            y1s[g] = int(min(max(0.0, math.ceil(my + ry)), tiles_y))
            cnt = (x1s[g] - x0s[g]) * (y1s[g] - y0s[g])
            keys[g] = depths[g]
        g_off[g + 1] = g_off[g] + cnt
    n_entries = g_off[n]
    n_tiles = tiles_x * tiles_y
    entry_gid = np.empty(n_entries, dtype=np.int32)
    entry_tile = np.empty(n_entries, dtype=np.int32)
    tile_off = np.zeros(n_tiles + 1, dtype=np.int64)
    for g in range(n):
        e = g_off[g]
        for ty in range(y0s[g], y1s[g]):
            for tx in range(x0s[g], x1s[g]):
                t = ty * tiles_x + tx
                entry_gid[e] = g
                entry_tile[e] = t
                tile_off[t + 1] += 1
                e += 1
    for t in range(n_tiles):
        tile_off[t + 1] += tile_off[t]
    fill = tile_off[:-1].copy()
    tile_entries = np.empty(n_entries, dtype=np.int64)
    order = np.argsort(keys, kind="mergesort")
    for g in order:
        for e in range(g_off[g], g_off[g + 1]):
            t = entry_tile[e]
            tile_entries[fill[t]] = e
            fill[t] += 1
    return g_off, entry_gid, tile_off, tile_entries


@njit(cache=True)
def _rows(my, ext_y, y0, ph):
    """Rows [v0, v1] of a tile whose pixel centres lie within ext_y (+ SPAN_MARGIN) of my."""
    v0 = int(max(float(y0), math.ceil(my - ext_y - 0.5 - SPAN_MARGIN)))
    v1 = int(min(float(y0 + ph - 1), math.floor(my + ext_y - 0.5 + SPAN_MARGIN)))
    return v0, v1


@njit(cache=True)
def _row_span(mx, dy, A, B, C, level, x0, pw):
    """Columns [u0, u1] of a tile row whose pixel centres may have sigma <= level.

    sigma(dx) = 0.5 A dx^2 + B dy dx + 0.5 C dy^2 with dx = mx - (u + 0.5) is a parabola in
    dx; its sub-level set is an interval. It is widened by SPAN_MARGIN px (and a near-zero
    discriminant is treated as zero) so that rounding never drops a pixel the exact test
    would keep; pixels inside are still tested exactly. Empty when u0 > u1.
    """
    bdy = B * dy
    disc = bdy * bdy - A * (C * dy * dy - 2.0 * level)
    if disc < 0.0:
        if disc < -1e-9 * (bdy * bdy + A * C * dy * dy + 2.0 * A * level + 1.0):
            return 1, 0
        disc = 0.0
    root = math.sqrt(disc)
    dx_lo = (-bdy - root) / A
    dx_hi = (-bdy + root) / A
    lo = max(float(x0), math.ceil(mx - dx_hi - 0.5 - SPAN_MARGIN))
    hi = min(float(x0 + pw - 1), math.floor(mx - dx_lo - 0.5 + SPAN_MARGIN))
    if lo > hi:
        return 1, 0
    return int(lo), int(hi)


# --------------------------------------------------------------------------- rasterization
@njit(cache=True, parallel=True)
def _raster_fwd(tile_off, tile_entries, entry_gid, means2d, conics, opac, colors, depths, radii,
                levels, steps, ext_y, bg, width, height, tiles_x,
                out_rgb, out_depth, out_T, out_last, entry_count, entry_weight):
    """Front-to-back compositing per tile; also each pixel's final T and last contributor."""
    n_tiles = tile_off.shape[0] - 1
    for t in prange(n_tiles):
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        pw = min(TILE, width - x0)
        ph = min(TILE, height - y0)
        T = np.ones((ph, pw))
        acc = np.zeros((ph, pw, 4))
        last = np.full((ph, pw), -1, dtype=np.int64)
        done = np.zeros((ph, pw), dtype=np.bool_)
        row_done = np.zeros(ph, dtype=np.int64)
        n_done = 0
        for k in range(tile_off[t], tile_off[t + 1]):
            if n_done == pw * ph:
                break
            e = tile_entries[k]
            g = entry_gid[e]
            mx, my = means2d[g, 0], means2d[g, 1]
            A, B, C = conics[g, 0], conics[g, 1], conics[g, 2]
            o = opac[g]
            cr, cg, cb, z = colors[g, 0], colors[g, 1], colors[g, 2], depths[g]
            v0, v1 = _rows(my, ext_y[g], y0, ph)
            level = levels[g]
            step = steps[g]
            cnt = 0
            wsum = 0.0
            for v in range(v0, v1 + 1):
                if row_done[v - y0] == pw:
                    continue
                dy = my - (v + 0.5)
                u0, u1 = _row_span(mx, dy, A, B, C, level, x0, pw)
                if u0 > u1:
                    continue
                # o exp(-sigma) along the row by recurrence: moving one pixel right multiplies it by
                # ratio = exp(A dx - A / 2 + B dy), and ratio itself by exp(-A)
                dx = mx - (u0 + 0.5)
                gauss = o * math.exp(-(0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy))
                ratio = math.exp(A * dx - 0.5 * A + B * dy)
                for u in range(u0, u1 + 1):
                    g_u = gauss
                    gauss *= ratio
                    ratio *= step
                    i = v - y0
                    j = u - x0
                    if done[i, j]:
                        continue
                    dx = mx - (u + 0.5)
                    sigma = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
                    if sigma < 0.0:
                        continue
                    alpha = min(ALPHA_MAX, g_u)
                    if alpha < ALPHA_MIN:
                        continue
                    Tc = T[i, j]
                    next_T = Tc * (1.0 - alpha)
                    if next_T <= T_MIN:
                        done[i, j] = True
                        n_done += 1
                        row_done[i] += 1
                        continue
                    wgt = alpha * Tc
                    acc[i, j, 0] += wgt * cr
                    acc[i, j, 1] += wgt * cg
                    acc[i, j, 2] += wgt * cb
                    acc[i, j, 3] += wgt * z
                    T[i, j] = next_T
                    last[i, j] = k
                    cnt += 1
                    wsum += wgt
            entry_count[e] = cnt
            entry_weight[e] = wsum
        for i in range(ph):
            for j in range(pw):
                Tf = T[i, j]
                out_rgb[y0 + i, x0 + j, 0] = acc[i, j, 0] + Tf * bg[0]
                out_rgb[y0 + i, x0 + j, 1] = acc[i, j, 1] + Tf * bg[1]
                out_rgb[y0 + i, x0 + j, 2] = acc[i, j, 2] + Tf * bg[2]
                out_depth[y0 + i, x0 + j] = acc[i, j, 3]
                out_T[y0 + i, x0 + j] = Tf
                out_last[y0 + i, x0 + j] = last[i, j]


@njit(cache=True, parallel=True)
def _raster_bwd(tile_off, tile_entries, entry_gid, means2d, conics, opac, colors, depths, radii,
                levels, steps, ext_y, bg, width, height, tiles_x, T_final, last, v_rgb, v_depth, v_alpha,
                entry_grad):
    """Back-to-front pass per tile; writes each entry's gradient row (see N_GRAD).

    Per pixel it keeps T_i (recovered by division), the upstream gradients, and
    behind = sum_{j>i} w_j (c_j . v_rgb + z_j v_depth), so that (module docstring)
    dL/dalpha_i = T_i (c_i . v_rgb + z_i v_depth) - (behind + T (bg . v_rgb) - T v_alpha) / (1 - alpha_i).
    """
    n_tiles = tile_off.shape[0] - 1
    for t in prange(n_tiles):
        x0 = (t % tiles_x) * TILE
        y0 = (t // tiles_x) * TILE
        pw = min(TILE, width - x0)
        ph = min(TILE, height - y0)
        npx = ph * pw
        Tcur = np.empty(npx)
        behind = np.zeros(npx)
        const = np.empty(npx)        # T (bg . v_rgb) - T v_alpha
        up = np.empty((npx, 4))      # v_rgb, v_depth
        lastk = np.empty(npx, dtype=np.int64)
        row_last = np.full(ph, -1, dtype=np.int64)
        k_max = -1
        for i in range(ph):
            for j in range(pw):
                p = i * pw + j
                Tf = T_final[y0 + i, x0 + j]
                Tcur[p] = Tf
                vr = v_rgb[y0 + i, x0 + j, 0]
                vg = v_rgb[y0 + i, x0 + j, 1]
                vb = v_rgb[y0 + i, x0 + j, 2]
                up[p, 0] = vr
                up[p, 1] = vg
                up[p, 2] = vb
                up[p, 3] = v_depth[y0 + i, x0 + j]
                const[p] = Tf * (bg[0] * vr + bg[1] * vg + bg[2] * vb) - Tf * v_alpha[y0 + i, x0 + j]
                lastk[p] = last[y0 + i, x0 + j]
                row_last[i] = max(row_last[i], lastk[p])
                k_max = max(k_max, lastk[p])
        for k in range(k_max, tile_off[t] - 1, -1):
            e = tile_entries[k]
            g = entry_gid[e]
            mx, my = means2d[g, 0], means2d[g, 1]
            A, B, C = conics[g, 0], conics[g, 1], conics[g, 2]
            o = opac[g]
            cr, cg, cb, z = colors[g, 0], colors[g, 1], colors[g, 2], depths[g]
            v0, v1 = _rows(my, ext_y[g], y0, ph)
            level = levels[g]
            step = steps[g]
            gx = 0.0
            gy = 0.0
            gA = 0.0
            gB = 0.0
            gC = 0.0
            go = 0.0
            gr = 0.0
            gg = 0.0
            gb = 0.0
            gz = 0.0
            for v in range(v0, v1 + 1):
                if k > row_last[v - y0]:
                    continue
                dy = my - (v + 0.5)
                u0, u1 = _row_span(mx, dy, A, B, C, level, x0, pw)
                if u0 > u1:
                    continue
                dx = mx - (u0 + 0.5)
                gauss = math.exp(-(0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy))
                ratio = math.exp(A * dx - 0.5 * A + B * dy)
                row = (v - y0) * pw - x0
                for u in range(u0, u1 + 1):
                    ex = gauss
                    gauss *= ratio
                    ratio *= step
                    p = row + u
                    if k > lastk[p]:
                        continue
                    dx = mx - (u + 0.5)
                    sigma = 0.5 * (A * dx * dx + C * dy * dy) + B * dx * dy
                    if sigma < 0.0:
                        continue
                    raw = o * ex
                    alpha = min(ALPHA_MAX, raw)
                    if alpha < ALPHA_MIN:
                        continue
                    ra = 1.0 / (1.0 - alpha)
                    Ti = Tcur[p] * ra
                    Tcur[p] = Ti
                    wgt = alpha * Ti
                    vr = up[p, 0]
                    vg = up[p, 1]
                    vb = up[p, 2]
                    vd = up[p, 3]
                    gr += wgt * vr
                    gg += wgt * vg
                    gb += wgt * vb
                    gz += wgt * vd
                    cv = cr * vr + cg * vg + cb * vb + z * vd
                    v_a = Ti * cv - ra * (behind[p] + const[p])
                    behind[p] += wgt * cv
                    if raw <= ALPHA_MAX:   # alpha = o exp(-sigma), not clamped
                        go += ex * v_a
                        v_s = -alpha * v_a
                        gA += 0.5 * dx * dx * v_s
                        gB += dx * dy * v_s
                        gC += 0.5 * dy * dy * v_s
                        gx += (A * dx + B * dy) * v_s
                        gy += (B * dx + C * dy) * v_s
            entry_grad[e, 0] = gx
            entry_grad[e, 1] = gy
            entry_grad[e, 2] = gA
            entry_grad[e, 3] = gB
            entry_grad[e, 4] = gC
            entry_grad[e, 5] = go
            entry_grad[e, 6] = gr
            entry_grad[e, 7] = gg
            entry_grad[e, 8] = gb
            entry_grad[e, 9] = gz


@njit(cache=True, parallel=True)
def _reduce_entries(g_off, entry_vals, out):
    """out[g] = sum of entry_vals rows g_off[g] .. g_off[g+1]-1, in entry order."""
    n = g_off.shape[0] - 1
    m = entry_vals.shape[1]
    for g in prange(n):
        for c in range(m):
            acc = 0.0
            for e in range(g_off[g], g_off[g + 1]):
                acc += entry_vals[e, c]
            out[g, c] = acc


# --------------------------------------------------------------------------- torch glue
# The glue uses NumPy only (no torch kernels): torch's OpenMP workers busy-wait after each op
# and, on a machine with few cores, steal the CPU from the numba threads that run next.

def _np64(t: torch.Tensor) -> np.ndarray:
    """float64, C-contiguous NumPy copy (or view) of a CPU tensor."""
    return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float64)


def _to_torch(a: np.ndarray, dtype: torch.dtype) -> torch.Tensor:
    np_dtype = np.float32 if dtype == torch.float32 else np.float64
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np_dtype))


class _Render(torch.autograd.Function):
    """Raw Gaussian parameters -> (rgb, expected depth, alpha, radii, n_touched, weight_sum).

    Activations are applied here (see :mod:`dynactivegs.splat.gaussians`): scales = exp,
    opacity = sigmoid, unit quaternions, rgb = max(C0 sh0 + 0.5, 0); and the expected depth is
    D / max(alpha, 1e-10) as gsplat's "RGB+ED". Differentiable in the five raw parameter
    tensors and the background.
    """

    @staticmethod
    def forward(ctx, means, log_scales, quats, opacity_logits, sh0, background, viewmat, K, width, height,
                near_plane):
        dt = means.dtype
        n = means.shape[0]
        m64, ls64, qr64, ol64, sh64, bg64 = (_np64(x) for x in (means, log_scales, quats, opacity_logits, sh0,
                                                                 background))
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # like torch: inf / nan, no warning
            s64 = np.exp(ls64)
            o64 = 1.0 / (1.0 + np.exp(-ol64))
            qnorm = np.sqrt((qr64 * qr64).sum(axis=1, keepdims=True))
            q64 = qr64 / qnorm
        c_lin = SH_C0 * sh64 + 0.5
        c64 = np.maximum(c_lin, 0.0)
        vm = np.ascontiguousarray(viewmat, dtype=np.float64)
        fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
        means2d = np.zeros((n, 2))
        conics = np.zeros((n, 3))
        depths = np.zeros(n)
        radii = np.zeros((n, 2), dtype=np.int32)
        _project_fwd(m64, q64, s64, o64, vm, fx, fy, cx, cy, width, height, near_plane,
                     means2d, conics, depths, radii)
        tiles_x, tiles_y = math.ceil(width / TILE), math.ceil(height / TILE)
        g_off, entry_gid, tile_off, tile_entries = _bin_tiles(means2d, radii, depths, tiles_x, tiles_y)
        n_entries = entry_gid.shape[0]
        rgb = np.empty((height, width, 3))
        depth_acc = np.empty((height, width))
        T_final = np.empty((height, width))
        last = np.empty((height, width), dtype=np.int64)
        entry_count = np.zeros(n_entries, dtype=np.int64)
        entry_weight = np.zeros(n_entries)
        # sigma above which o exp(-sigma) < ALPHA_MIN for sure: ln(o / ALPHA_MIN), padded for rounding
        levels = np.log(np.maximum(o64 / ALPHA_MIN, 1.0)) * (1.0 + 1e-9) + 1e-9
        steps = np.exp(-conics[:, 0])
        # half height of the ellipse sigma <= level: sqrt(2 level cov2d_yy), cov2d_yy = a / (a c - b^2)
        det_conic = np.where(radii[:, 0] > 0, conics[:, 0] * conics[:, 2] - conics[:, 1] ** 2, 1.0)
        ext_y = np.sqrt(2.0 * levels * conics[:, 0] / det_conic)
        _raster_fwd(tile_off, tile_entries, entry_gid, means2d, conics, o64, c64, depths, radii,
                    levels, steps, ext_y, bg64, width, height, tiles_x, rgb, depth_acc, T_final, last,
                    entry_count, entry_weight)
        entry_stats = np.empty((n_entries, 2))
        entry_stats[:, 0] = entry_count
        entry_stats[:, 1] = entry_weight
        stats = np.zeros((n, 2))
        _reduce_entries(g_off, entry_stats, stats)
        alpha = 1.0 - T_final
        alpha_c = np.maximum(alpha, 1e-10)
        depth = depth_acc / alpha_c

        ctx.saved = (m64, s64, qr64, qnorm, q64, o64, c_lin, c64, bg64, vm, (fx, fy, cx, cy), width, height,
                     means2d, conics, depths, radii, g_off, entry_gid, tile_off, tile_entries, T_final, last,
                     tiles_x, depth_acc, alpha, alpha_c, levels, steps, ext_y)
        ctx.dtype = dt
        out_radii = torch.from_numpy(radii)
        n_touched = torch.from_numpy(stats[:, 0].astype(np.int32))
        weight_sum = _to_torch(stats[:, 1], dt)
        ctx.mark_non_differentiable(out_radii, n_touched, weight_sum)
        return (_to_torch(rgb, dt), _to_torch(depth, dt), _to_torch(alpha, dt), out_radii, n_touched, weight_sum)

    @staticmethod
    def backward(ctx, v_rgb, v_depth, v_alpha, _v_radii, _v_touched, _v_wsum):
        (m64, s64, qr64, qnorm, q64, o64, c_lin, c64, bg64, vm, (fx, fy, cx, cy), width, height,
         means2d, conics, depths, radii, g_off, entry_gid, tile_off, tile_entries, T_final, last,
         tiles_x, depth_acc, alpha, alpha_c, levels, steps, ext_y) = ctx.saved
        dt = ctx.dtype
        n = m64.shape[0]
        v_rgb64 = _np64(v_rgb) if v_rgb is not None else np.zeros((height, width, 3))
        v_ed = _np64(v_depth) if v_depth is not None else np.zeros((height, width))
        v_alpha64 = _np64(v_alpha) if v_alpha is not None else np.zeros((height, width))
        # expected depth = D / max(alpha, 1e-10)
        v_dacc = v_ed / alpha_c
        v_alpha64 = v_alpha64 - np.where(alpha >= 1e-10, v_ed * depth_acc / (alpha_c * alpha_c), 0.0)
        entry_grad = np.zeros((entry_gid.shape[0], N_GRAD))
        _raster_bwd(tile_off, tile_entries, entry_gid, means2d, conics, o64, c64, depths, radii,
                    levels, steps, ext_y, bg64, width, height, tiles_x, T_final, last, v_rgb64, v_dacc, v_alpha64,
                    entry_grad)
        grad = np.zeros((n, N_GRAD))
        _reduce_entries(g_off, entry_grad, grad)
        v_means = np.empty((n, 3))
        v_quats = np.empty((n, 4))
        v_scales = np.empty((n, 3))
        _project_bwd(m64, q64, s64, vm, fx, fy, cx, cy, width, height, radii, conics,
                     np.ascontiguousarray(grad[:, 0:2]), np.ascontiguousarray(grad[:, 2:5]),
                     np.ascontiguousarray(grad[:, 9]), v_means, v_quats, v_scales)
        # activations
        v_log_scales = v_scales * s64
        v_logits = grad[:, 5] * o64 * (1.0 - o64)
        v_qraw = (v_quats - q64 * (v_quats * q64).sum(axis=1, keepdims=True)) / qnorm
        v_sh0 = np.where(c_lin >= 0.0, SH_C0 * grad[:, 6:9], 0.0)
        v_bg = (T_final[:, :, None] * v_rgb64).sum(axis=(0, 1))
        return (_to_torch(v_means, dt), _to_torch(v_log_scales, dt), _to_torch(v_qraw, dt),
                _to_torch(v_logits, dt), _to_torch(v_sh0, dt), _to_torch(v_bg, dt),
                None, None, None, None, None)


def render_raw(means: torch.Tensor, log_scales: torch.Tensor, quats: torch.Tensor, opacity_logits: torch.Tensor,
               sh0: torch.Tensor, background: torch.Tensor, viewmat: np.ndarray, K: np.ndarray,
               width: int, height: int, near_plane: float
               ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Render raw Gaussian parameters (the fields of :class:`~dynactivegs.splat.gaussians.Gaussians`).

    Returns rgb (H, W, 3), expected depth (H, W) in m, alpha (H, W), radii (N, 2) int32,
    n_touched (N,) int32, weight_sum (N,); float outputs in the parameters' dtype.
    """
    n = means.shape[0]
    assert means.shape == (n, 3) and log_scales.shape == (n, 3) and quats.shape == (n, 4)
    assert opacity_logits.shape == (n,) and sh0.shape == (n, 3) and background.shape == (3,)
    return _Render.apply(means, log_scales, quats, opacity_logits, sh0, background, viewmat, K,
                         int(width), int(height), float(near_plane))
