"""Stand-in perception and mapping outputs made from simulator ground truth.

For tests and benchmarks of the later stages (fields, selection, planning) without running
perception and mapping: ``beta = 0.1 + 2 * people_mask`` (uncertain exactly on people), the
map's render is the static scene rendered at the frame's pose (a perfect map of the static
scene), and the map's surface voxels are the voxelised static-scene points seen so far
(back-projected from those renders). Not part of the method; stages never read ground truth.
"""

from __future__ import annotations

import numpy as np

from dynactivegs.records import Frame, MappingOut, PerceptionOut, SimTruth


class StandInUpstream:
    """Accumulates the observed static surface and makes per-step :class:`PerceptionOut` / :class:`MappingOut`."""

    def __init__(self, sim, surface_voxel_m: float = 0.05, max_range_m: float = 6.0) -> None:
        self.sim = sim
        self.voxel = float(surface_voxel_m)
        self.max_range = float(max_range_m)
        self._seen: set[tuple[int, int, int]] = set()
        self._ijk = np.zeros((0, 3), np.int32)

    def outputs(self, frame: Frame, truth: SimTruth) -> tuple[PerceptionOut, MappingOut]:
        beta = (0.1 + 2.0 * truth.people_mask).astype(np.float32)
        r = self.sim.render_static(frame.T_world_cam)
        d = r.depth_m.astype(np.float64)
        h, w = d.shape
        v, u = np.mgrid[0:h, 0:w]
        ok = (d > 0) & (d <= self.max_range)
        K = frame.K
        z = d[ok]
        pc = np.stack([(u[ok] + 0.5 - K[0, 2]) / K[0, 0] * z, (v[ok] + 0.5 - K[1, 2]) / K[1, 1] * z, z], axis=1)
        pw = pc @ frame.T_world_cam[:3, :3].T + frame.T_world_cam[:3, 3]
        ijk = np.unique(np.floor(pw / self.voxel).astype(np.int32), axis=0)
        new = [tuple(x) for x in ijk.tolist() if tuple(x) not in self._seen]
        if new:
            self._seen.update(new)
            self._ijk = np.unique(np.concatenate([self._ijk, np.array(new, np.int32)]), axis=0)
        render_alpha = (r.depth_m > 0).astype(np.float32)
        mapping = MappingOut(r.rgb, r.depth_m.astype(np.float32), render_alpha, self._ijk.copy(), self.voxel,
                             len(self._ijk), len(new), 0, float("nan"), False)
        return PerceptionOut(beta, float("nan"), False), mapping
