"""How much of each room a run's fields hold as seen, and what eq. (8) still offers there, at chosen steps of its log.

    python benchmarks/room_gain.py runs/full/apartment-03-seed2.mcap --room bathroom-4 --steps 300,431,569,999

For each room of a procedural scene (or the ``--room`` named) and each step asked for, from the log's ``/fields``
grid of that step (the voxel query set Omega, eq. (4)'s n_t and U_s):

- the room's voxels 0.1 m above the floor up to 0.3 m under the walls' top, split into the **walls' band** (within
  ``--band`` metres of the room's inner wall faces) and the **interior** (the rest): the share with n_t > 0 (the
  band's also per wall, south / north / west / east, each voxel to its nearest wall; "-" where the grid holds none
  of a wall's band yet) and their summed U_s x voxel volume (eq. (8)'s units), and
- from the latest ``/selection`` scoring at or before the step: the best candidate view's I_s (eq. (8)) at a graph
  node inside the room and anywhere, and the room's node count;
- last, per room, how many of the run's new targets up to the last step asked for lay inside it, the first step
  the robot stood in it (its centre ``ENTER_DEPTH_M`` inside the walls; "-" never), and at the last step asked for
  the band's share on the walls that hold a door (``scene.doors``) and on the others.

A look through a door observes a room's volume but not the inner faces of the wall the door is in: this tells a
room whose volume was seen that way (interior share high, the door walls' band low) from one the robot entered.
Over several logs it counts the rooms **seen through their door only**: at least ``SEEN_PCT`` % of the interior
observed by the last step asked for, never entered. Open loop, read from the log only.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from psnr_breakdown import logged_config  # noqa: E402  (the same reading of a run log)

FLOOR_GAP_M = 0.1
"""Voxels lower than this over the floor are left out (the floor's own layer)."""
TOP_GAP_M = 0.3
"""... and voxels higher than this under the walls' top (the ceiling's)."""
ENTER_DEPTH_M = 0.3
"""The robot entered a room when its centre stood this far inside the room's wall lines."""
SEEN_PCT = 50.0
"""A room counts as seen (for the count of rooms seen through their door only) from this share of its interior."""


@dataclass
class RoomAt:
    """One room at one step (module docstring)."""

    step: int
    room: str
    interior_seen_pct: float
    band_seen_pct: float
    side_seen_pct: tuple[float, float, float, float]   # the band's per wall: south, north, west, east
    interior_us: float            # summed U_s x voxel volume (m^3)
    band_us: float
    best_gain_room: float         # nan when no candidate view lies in the room
    best_gain_any: float
    nodes: int
    selection_step: int           # the step of the scoring the gains are from; -1: none yet
    door_band_seen_pct: float     # the band's share on the walls that hold a door (nan: none in the grid yet)
    other_band_seen_pct: float    # ... on the other walls


@dataclass
class RoomRun:
    """One room over a run up to the last step asked for (module docstring)."""

    targets: int = 0              # new targets inside
    entered_step: int = -1        # first step the robot stood inside; -1 never


def voxel_masks(fields, room, wall_height_m: float, band_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The room's walls' band and interior voxels of a ``FieldsOut`` grid (bool (X, Y, Z) each, module docstring)
    and each voxel's nearest wall (int8 (X, Y, Z): 0 south, 1 north, 2 west, 3 east)."""
    from dynactivegs.sim.procedural import WALL_T_M

    x0, y0, x1, y1 = room.inner(WALL_T_M / 2)
    x, y, z = (fields.origin_m[i] + (np.arange(n) + 0.5) * fields.voxel_m for i, n in enumerate(fields.u_s.shape))
    inside_x, inside_y = (x > x0) & (x < x1), (y > y0) & (y < y1)
    deep_x, deep_y = (x > x0 + band_m) & (x < x1 - band_m), (y > y0 + band_m) & (y < y1 - band_m)
    zs = (z > FLOOR_GAP_M) & (z < wall_height_m - TOP_GAP_M)
    room_xy = inside_x[:, None] & inside_y[None, :]
    deep_xy = deep_x[:, None] & deep_y[None, :]
    band = (room_xy & ~deep_xy)[:, :, None] & zs[None, None, :]
    interior = deep_xy[:, :, None] & zs[None, None, :]
    gaps = np.stack(np.broadcast_arrays((y - y0)[None, :], (y1 - y)[None, :], (x - x0)[:, None], (x1 - x)[:, None]))
    side = np.broadcast_to(np.argmin(gaps, axis=0).astype(np.int8)[:, :, None], band.shape)
    return band, interior, side


def room_gains(mcap: Path, steps: list[int], room_name: str | None = None,
               band_m: float = 0.3) -> tuple[str, list[RoomAt], dict[str, RoomRun]]:
    """(a label, a :class:`RoomAt` per asked step (in order) and room, {room: its :class:`RoomRun`}) for the run
    logged in ``mcap``."""
    from dynactivegs.errors import DagsError
    from dynactivegs.sim.scenes import is_procedural_name, load_scene
    from replay.source import LogReader

    reader = LogReader(mcap)
    cfg = logged_config(reader, mcap)
    if not is_procedural_name(cfg.sim.scene):
        raise DagsError(f"{mcap}: scene {cfg.sim.scene!r} is a mesh and has no rooms; pass the log of a run on a "
                        "procedural scene (apartment-NN, loop-NN, ...)")
    scene = load_scene(cfg.sim)
    rooms = [r for r in scene.rooms if room_name is None or r.name == room_name]
    if not rooms:
        raise DagsError(f"no room {room_name!r} in {cfg.sim.scene}: use one of "
                        f"{', '.join(r.name for r in scene.rooms)}")
    wanted = sorted(set(steps))
    out: list[RoomAt] = []
    runs = {r.name: RoomRun() for r in rooms}
    doors = [r.door_sides(scene.doors, scene.rooms) for r in rooms]
    last_sel, last_sel_step = None, -1
    for st in reader.steps():
        if st.step > wanted[-1]:
            break
        robot = st["/truth"].robot
        for r in rooms:
            x0, y0, x1, y1 = r.inner(ENTER_DEPTH_M)
            if runs[r.name].entered_step < 0 and x0 < robot.x_m < x1 and y0 < robot.y_m < y1:
                runs[r.name].entered_step = st.step
        sel = st.get("/selection")
        if sel is not None and sel.target_node >= 0 and sel.target_reason != "keep":      # a new target
            xy = sel.node_xy_m[sel.target_node][None]
            for r in rooms:
                runs[r.name].targets += int(r.contains(xy)[0])
        if sel is not None and len(sel.cand_node):
            last_sel, last_sel_step = sel, st.step
        if st.step not in wanted:
            continue
        f = st.get("/fields")
        if f is None:
            raise DagsError(f"{mcap}: step {st.step} has no /fields record; pass a log written with the fields "
                            "stage on")
        vol = f.voxel_m ** 3
        pct = (lambda m: 100.0 * float((f.n_obs[m] > 0).mean()) if m.any() else float("nan"))   # % with n_t > 0
        for r, door in zip(rooms, doors):
            band, interior, side = voxel_masks(f, r, scene.wall_height_m, band_m)
            on_door = np.isin(side, list(door))
            g_room = g_any = float("nan")
            nodes = 0
            if last_sel is not None:
                node_in = r.contains(last_sel.node_xy_m)
                nodes = int(node_in.sum())
                cand_in = node_in[last_sel.cand_node]
                g_any = float(last_sel.cand_gain.max())
                g_room = float(last_sel.cand_gain[cand_in].max()) if cand_in.any() else float("nan")
            sides = tuple(pct(band & (side == k)) for k in range(4))
            out.append(RoomAt(st.step, r.name, pct(interior), pct(band), sides, float(f.u_s[interior].sum()) * vol,
                              float(f.u_s[band].sum()) * vol, g_room, g_any, nodes, last_sel_step,
                              pct(band & on_door), pct(band & ~on_door)))
    missing = sorted(set(wanted) - {r.step for r in out})
    if missing:
        raise DagsError(f"{mcap}: the log holds no step {missing[0]}; ask for steps the run took (--steps)")
    label = f"{reader.metadata.get('preset', '?')} {cfg.sim.scene} seed {cfg.seed}"
    return label, out, runs


def _steps(text: str) -> list[int]:
    try:
        steps = [int(s) for s in text.split(",")]
    except ValueError:
        sys.exit(f"error: bad --steps {text!r}: give step numbers separated by commas, e.g. 250,500,999")
    if not steps or min(steps) < 0:
        sys.exit(f"error: bad --steps {text!r}: steps must be >= 0")
    return steps


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mcap", nargs="+", type=Path, help="run logs (dagsrun --record, or dagsbench's OUT/runs/PRESET/)")
    ap.add_argument("--room", default=None, help="one room by name (e.g. bathroom-4); default every room")
    ap.add_argument("--steps", default="249,499,749,999", help="comma list of steps (default 249,499,749,999)")
    ap.add_argument("--band", type=float, default=0.3, help="depth of the walls' band in metres (default 0.3)")
    args = ap.parse_args(argv)
    steps = _steps(args.steps)
    if not np.isfinite(args.band) or args.band <= 0.0:
        sys.exit(f"error: bad --band {args.band}: give a depth in metres > 0, e.g. 0.3")
    from dynactivegs.errors import DagsError

    print("| run | step | room | interior seen % | walls' band seen %: all (S / N / W / E) | U_s m^3: interior / band "
          "| best I_s: room / anywhere (scored at step) | nodes in room |\n" + "|---" * 8 + "|", flush=True)
    fmt = (lambda v: f"{v:.0f}" if np.isfinite(v) else "-")           # "-": none of it in the grid yet
    last = max(steps)
    summary = []                  # (label, room, RoomRun, its RoomAt at the last step)
    for path in args.mcap:
        try:
            label, rows, runs = room_gains(path, steps, args.room, args.band)
        except (DagsError, ValueError) as e:
            sys.exit(f"error: {e}")
        for r in rows:
            sides = " / ".join(fmt(v) for v in r.side_seen_pct)
            print(f"| {label} | {r.step} | {r.room} | {r.interior_seen_pct:.0f} | {r.band_seen_pct:.0f} ({sides}) | "
                  f"{r.interior_us:.2f} / {r.band_us:.2f} | {r.best_gain_room:.1f} / {r.best_gain_any:.1f} "
                  f"({r.selection_step}) | {r.nodes} |", flush=True)
        summary += [(label, r.room, runs[r.room], r) for r in rows if r.step == last]
    print(f"\n| run | room | entered at step | new targets inside | at step {last}: interior seen % | walls' band "
          "seen %: door walls / others |\n" + "|---" * 6 + "|")
    for label, room, run, r in summary:
        entered = str(run.entered_step) if run.entered_step >= 0 else "-"
        print(f"| {label} | {room} | {entered} | {run.targets} | {fmt(r.interior_seen_pct)} | "
              f"{fmt(r.door_band_seen_pct)} / {fmt(r.other_band_seen_pct)} |")
    through = [(label, room, r) for label, room, run, r in summary
               if run.entered_step < 0 and r.interior_seen_pct >= SEEN_PCT]
    door_seen = [r.door_band_seen_pct for _, _, run, r in summary
                 if run.entered_step >= 0 and np.isfinite(r.door_band_seen_pct)]
    print(f"\nseen through their door only (interior >= {SEEN_PCT:.0f} % seen by step {last}, never entered): "
          f"{len(through)} of {len(summary)} rooms in {len(args.mcap)} runs")
    for label, room, r in through:
        print(f"- {label} {room}: interior {r.interior_seen_pct:.0f} %, walls' band door walls "
              f"{fmt(r.door_band_seen_pct)} / others {fmt(r.other_band_seen_pct)} %")
    if door_seen:
        print(f"the entered rooms' door walls' band: {np.mean(door_seen):.0f} % seen on average ({len(door_seen)} "
              "rooms with a door)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
