"""Simulator speed: scene generation, free-space map, RGB-D render per frame, crowd step.

    python benchmarks/bench_sim.py [--scenes apartment-00,house-00] [--frames 40]

Prints one table. Render times are per frame with the scene's people in it, measured along
the scripted tour (so the frames are typical views, not a fixed pose); "static" renders
have no people. Goals (issue 2): <= 5 ms at 160x92 and <= 15 ms at 320x184 on 2 cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import numpy as np

from dynactivegs.config import CameraConfig, SimConfig
from dynactivegs.rng import derive_rng
from dynactivegs.sim import procedural, scenes
from dynactivegs.sim.scripted import ScriptedDriver
from dynactivegs.sim.world import Simulator


def _median_ms(xs: list[float]) -> float:
    return 1000.0 * float(np.median(xs))


def bench_scene(name: str, frames: int) -> dict[str, float | str | int]:
    t = time.perf_counter()
    scene = procedural.make_scene(name)
    gen_s = time.perf_counter() - t
    renderer = scenes.scene_renderer(scene)
    t = time.perf_counter()
    scenes.scene_freespace(scene, renderer, 0.05, 1.5)
    fs_s = time.perf_counter() - t
    row: dict[str, float | str | int] = {"scene": name, "faces": scene.n_faces, "gen_s": gen_s, "freespace_s": fs_s}

    sim = Simulator(SimConfig(scene=name), seed=0)
    row["people"] = len(sim.crowd.positions_xy_m)
    driver = ScriptedDriver(sim.freespace, 0.18, derive_rng(0, "bench"))
    poses, people = [], []
    crowd_ms = []
    for _ in range(frames):
        _, truth = sim.observation()
        poses.append(sim.camera_pose())
        people.append(sim.people_mesh())
        a = driver.act(truth.robot.x_m, truth.robot.y_m, truth.robot.yaw_rad, truth.collided)
        xy = np.array([truth.robot.x_m, truth.robot.y_m])
        t = time.perf_counter()
        sim.crowd.step(sim.cfg.dt_s, xy, np.zeros(2), 0.18)
        crowd_ms.append(time.perf_counter() - t)
        sim.step(a)
    row["crowd_step_ms"] = _median_ms(crowd_ms)
    t = time.perf_counter()
    for _ in range(20):
        sim.people_mesh()
    row["people_mesh_ms"] = 1000 * (time.perf_counter() - t) / 20
    for w, h in ((160, 92), (320, 184)):
        cam = dataclasses.replace(CameraConfig(), width_px=w, height_px=h)
        K = np.array([[cam.fx, 0, w / 2], [0, cam.fy, h / 2], [0, 0, 1.0]])
        renderer.render(poses[0], K, w, h, people=people[0])  # warm-up (numba, ray cache)
        ts, ts_static, in_view = [], [], 0
        for T, pm in zip(poses, people):
            t = time.perf_counter()
            out = renderer.render(T, K, w, h, people=pm)
            ts.append(time.perf_counter() - t)
            in_view += int(out.people_mask.any())
            t = time.perf_counter()
            renderer.render(T, K, w, h)
            ts_static.append(time.perf_counter() - t)
        row[f"render_{w}x{h}_ms"] = _median_ms(ts)
        row[f"static_{w}x{h}_ms"] = _median_ms(ts_static)
        row["frames_with_people"] = in_view
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="apartment-00,apartment-01,house-00,house-01")
    ap.add_argument("--frames", type=int, default=40)
    a = ap.parse_args()
    rows = [bench_scene(n, a.frames) for n in a.scenes.split(",")]
    cols = ["scene", "faces", "people", "gen_s", "freespace_s", "render_160x92_ms", "static_160x92_ms",
            "render_320x184_ms", "static_320x184_ms", "crowd_step_ms", "people_mesh_ms", "frames_with_people"]
    print(f"# simulator benchmark ({os.cpu_count()} CPUs, {a.frames} frames per scene, median times; "
          "render = RGB-D with people; crowd step = one 0.5 s simulator step)")
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for r in rows:
        cells = [f"{r[c]:.2f}" if isinstance(r[c], float) else str(r[c]) for c in cols]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
