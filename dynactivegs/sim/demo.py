"""Drive the robot through a scene on the scripted tour and write what it sees as pictures.

Writes, under ``out_dir``:

- ``frames/rgb_NNNN.png``, ``frames/depth_NNNN.png`` (turbo colour map, black = no return),
  ``frames/people_NNNN.png`` (the ground-truth people mask);
- ``floorplan.png``: the free-space map with rooms, the robot's trajectory and the people's tracks;
- ``contact_sheet.png``: a grid of RGB / depth / mask for a few frames.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from dynactivegs.config import DagsConfig
from dynactivegs.records import Frame, SimTruth
from dynactivegs.rng import derive_rng
from dynactivegs.sim.scripted import ScriptedDriver
from dynactivegs.sim.world import Simulator


@dataclass(frozen=True)
class DemoSummary:
    steps: int
    seconds: float
    collisions: int
    people: int
    frames_with_people: int
    out_dir: Path
    floorplan_png: Path
    contact_sheet_png: Path

    @property
    def steps_per_s(self) -> float:
        return self.steps / max(self.seconds, 1e-9)


def depth_to_color(depth_m: np.ndarray, max_m: float = 10.0) -> np.ndarray:
    """uint8 (H, W, 3) RGB visualisation of a depth map: turbo colour map, black where depth is 0."""
    d = np.clip(depth_m / max_m, 0.0, 1.0)
    bgr = cv2.applyColorMap((d * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    rgb = bgr[..., ::-1].copy()
    rgb[depth_m <= 0] = 0
    return rgb


def _save_rgb(path: Path, rgb: np.ndarray) -> None:
    cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1]))


def frame_panels(frame: Frame, truth: SimTruth) -> np.ndarray:
    """uint8 (H, 3W, 3): RGB | depth | people mask side by side."""
    mask = np.repeat((truth.people_mask.astype(np.uint8) * 255)[..., None], 3, axis=2)
    return np.concatenate([frame.rgb, depth_to_color(frame.depth_m), mask], axis=1)


def plot_floorplan(sim: Simulator, robot_xy: np.ndarray, people_tracks: np.ndarray, path: Path) -> None:
    """Top-down PNG: free space (grey), obstacles (dark), rooms, robot trajectory, people's tracks."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fs = sim.freespace
    h, w = fs.shape
    img = np.full((h, w, 3), 1.0)
    img[fs.floor] = (0.85, 0.85, 0.85)
    img[fs.navigable(sim.cfg.robot.radius_m)] = (0.97, 0.97, 0.97)
    img[fs.occupied & fs.floor] = (0.35, 0.35, 0.4)
    x0, y0 = fs.origin_xy_m
    extent = (x0, x0 + w * fs.res_m, y0, y0 + h * fs.res_m)
    fig, ax = plt.subplots(figsize=(8, 8 * h / max(w, 1) + 0.6), dpi=110)
    ax.imshow(img, origin="lower", extent=extent, interpolation="nearest")
    for room in sim.scene.rooms:
        ax.text((room.x0 + room.x1) / 2, (room.y0 + room.y1) / 2, room.kind, ha="center", va="center",
                fontsize=8, color="0.45")
    cmap = plt.get_cmap("tab20")
    for p in range(people_tracks.shape[1]):
        tr = people_tracks[:, p]
        ax.plot(tr[:, 0], tr[:, 1], "-", lw=1.0, color=cmap(p % 20), alpha=0.8)
        ax.plot(tr[-1, 0], tr[-1, 1], "o", ms=5, color=cmap(p % 20))
    ax.plot(robot_xy[:, 0], robot_xy[:, 1], "-", lw=2.2, color="crimson", label="robot")
    ax.plot(robot_xy[0, 0], robot_xy[0, 1], "s", ms=7, color="crimson")
    ax.plot(robot_xy[-1, 0], robot_xy[-1, 1], "^", ms=9, color="crimson")
    ax.set_title(f"{sim.scene.name}: robot (red) and {people_tracks.shape[1]} people over {len(robot_xy) - 1} steps")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def drive_and_render(cfg: DagsConfig, steps: int, out_dir: Path, *, save_every: int = 1,
                     progress: bool = True) -> DemoSummary:
    """Run the simulator for ``steps`` scripted actions and write frames and plots to ``out_dir``."""
    out_dir = Path(out_dir)
    frames_dir = out_dir / "frames"
    frames_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    sim = Simulator(cfg.sim, cfg.seed)
    driver = ScriptedDriver(sim.freespace, cfg.sim.robot.radius_m, derive_rng(cfg.seed, "scripted-driver"),
                            turn_step_rad=np.radians(cfg.sim.robot.turn_step_deg))
    frame, truth = sim.observation()
    robot_xy = [np.array([truth.robot.x_m, truth.robot.y_m])]
    tracks = [truth.people_xy_m.copy()]
    sheet: list[np.ndarray] = []
    sheet_every = max(1, steps // 8)
    collisions = 0
    with_people = 0
    bar = tqdm(total=steps, unit="step", disable=not progress, desc=f"{cfg.sim.scene}")
    for k in range(steps + 1):
        if k % save_every == 0:
            _save_rgb(frames_dir / f"rgb_{k:04d}.png", frame.rgb)
            _save_rgb(frames_dir / f"depth_{k:04d}.png", depth_to_color(frame.depth_m, cfg.sim.camera.max_depth_m))
            cv2.imwrite(str(frames_dir / f"people_{k:04d}.png"), truth.people_mask.astype(np.uint8) * 255)
        if k % sheet_every == 0 and len(sheet) < 9:
            sheet.append(frame_panels(frame, truth))
        with_people += int(truth.people_mask.any())
        if k == steps:
            break
        action = driver.act(truth.robot.x_m, truth.robot.y_m, truth.robot.yaw_rad, blocked=truth.collided)
        frame, truth = sim.step(action)
        collisions += int(truth.collided)
        robot_xy.append(np.array([truth.robot.x_m, truth.robot.y_m]))
        tracks.append(truth.people_xy_m.copy())
        bar.update(1)
        bar.set_postfix(collisions=collisions, people_in_view=with_people)
    bar.close()
    seconds = time.perf_counter() - t0
    floorplan = out_dir / "floorplan.png"
    plot_floorplan(sim, np.array(robot_xy), np.array(tracks), floorplan)
    contact = out_dir / "contact_sheet.png"
    _save_rgb(contact, np.concatenate(sheet, axis=0))
    return DemoSummary(steps=steps, seconds=seconds, collisions=collisions, people=len(tracks[0]),
                       frames_with_people=with_people, out_dir=out_dir, floorplan_png=floorplan,
                       contact_sheet_png=contact)
