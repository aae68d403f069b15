"""Crowd speed: one 0.5 s simulator step, one substep, ORCA alone, and the people mesh.

Scene: a hand-made 16 m x 10 m floor (res 0.05 m) with four rooms joined by 0.9 m doors,
a pillar and two furniture blocks. A static robot stands in one room.

    python benchmarks/bench_crowd.py
"""

from __future__ import annotations

import time

import numpy as np

from dynactivegs.config import CrowdConfig
from dynactivegs.sim.crowd import Crowd
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.humans import TRIANGLES_PER_PERSON

RES = 0.05


def four_rooms() -> FreeSpace:
    w, h = int(16 / RES) + 2, int(10 / RES) + 2
    occ = np.zeros((h, w), bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    cx, cy = w // 2, h // 2
    occ[:, cx - 1:cx + 1] = True
    occ[cy - 1:cy + 1, :] = True
    door = int(0.9 / RES)
    for r0 in (int(2.0 / RES), int(7.0 / RES)):           # doors in the vertical wall
        occ[r0:r0 + door, cx - 1:cx + 1] = False
    for c0 in (int(3.0 / RES), int(12.0 / RES)):          # doors in the horizontal wall
        occ[cy - 1:cy + 1, c0:c0 + door] = False
    occ[int(2.0 / RES):int(2.8 / RES), int(11.0 / RES):int(11.8 / RES)] = True    # pillar
    occ[int(6.5 / RES):int(7.5 / RES), int(2.0 / RES):int(4.0 / RES)] = True      # table
    occ[int(8.8 / RES):int(9.9 / RES), int(12.0 / RES):int(15.0 / RES)] = True    # sofa
    return FreeSpace.from_grid(occ, RES)


def bench(fs: FreeSpace, count: int, steps: int = 200) -> dict[str, float]:
    cfg = CrowdConfig(count=count)
    robot = np.array([1.0, 1.0])
    t = time.perf_counter()
    crowd = Crowd(cfg, fs, np.random.default_rng(0), robot, 0.18)
    init_ms = 1e3 * (time.perf_counter() - t)
    for _ in range(20):                                   # warm up (numba cache, first plans)
        crowd.step(0.5, robot, np.zeros(2), 0.18)
    step_s = []
    for _ in range(steps):
        t = time.perf_counter()
        crowd.step(0.5, robot, np.zeros(2), 0.18)
        step_s.append(time.perf_counter() - t)
    mesh_s = []
    for _ in range(200):
        t = time.perf_counter()
        crowd.mesh()
        mesh_s.append(time.perf_counter() - t)
    n_sub = int(np.ceil(0.5 / cfg.substep_s))
    step_ms = 1e3 * np.array(step_s)
    return dict(people=len(crowd), init_ms=init_ms, step_median_ms=float(np.median(step_ms)),
                step_mean_ms=float(step_ms.mean()), step_p95_ms=float(np.percentile(step_ms, 95)),
                substep_mean_ms=float(step_ms.mean() / n_sub),
                mesh_ms=1e3 * float(np.median(mesh_s)), triangles=len(crowd) * TRIANGLES_PER_PERSON,
                goals_per_person=float(crowd.goals_reached.mean()))


def main() -> None:
    fs = four_rooms()
    print(f"scene: four rooms, {fs.free_area_m2():.1f} m^2 free, grid {fs.shape[1]}x{fs.shape[0]} at {RES} m")
    print("crowd step = 0.5 s of simulated time (5 substeps of 0.1 s); mean includes replanning")
    cols = ["people", "init_ms", "step_median_ms", "step_mean_ms", "step_p95_ms", "substep_mean_ms", "mesh_ms",
            "triangles", "goals_per_person"]
    print(" ".join(f"{c:>16}" for c in cols))
    for count in (12, 30):
        row = bench(fs, count)
        print(" ".join(f"{row[c]:>16.3f}" if isinstance(row[c], float) else f"{row[c]:>16}" for c in cols))


if __name__ == "__main__":
    main()
