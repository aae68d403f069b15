"""The crowd: spawning, count rule, determinism, no collisions over long runs, progress, gait and heading."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynactivegs.config import CrowdConfig
from dynactivegs.errors import ConfigError
from dynactivegs.sim.crowd import Crowd, _segment_clear
from dynactivegs.sim.freespace import FreeSpace
from dynactivegs.sim.humans import VERTICES_PER_PERSON, stride_length_m

RES = 0.05
ROBOT_R = 0.18


def _walled(w_m: float, h_m: float) -> np.ndarray:
    occ = np.zeros((int(round(h_m / RES)) + 2, int(round(w_m / RES)) + 2), bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return occ


def two_rooms() -> FreeSpace:
    """Two 6 m x 6 m rooms joined by a 0.9 m door in a 0.1 m wall at x = 6 m; a 1 m pillar in the right room."""
    occ = _walled(12.0, 6.0)
    c = occ.shape[1] // 2
    occ[:, c - 1:c + 1] = True
    d0 = int(2.55 / RES)
    occ[d0:d0 + int(round(0.9 / RES)), c - 1:c + 1] = False
    occ[int(2.5 / RES):int(3.5 / RES), int(8.5 / RES):int(9.5 / RES)] = True
    return FreeSpace.from_grid(occ, RES)


def pillar_room() -> FreeSpace:
    """An 8 m x 6 m room with a 1 m square pillar in the middle and a table-sized block near a wall."""
    occ = _walled(8.0, 6.0)
    occ[int(2.5 / RES):int(3.5 / RES), int(3.5 / RES):int(4.5 / RES)] = True
    occ[int(0.8 / RES):int(1.6 / RES), int(6.0 / RES):int(7.2 / RES)] = True
    return FreeSpace.from_grid(occ, RES)


def corridor() -> FreeSpace:
    """A 10 m x 1.6 m corridor."""
    return FreeSpace.from_grid(_walled(10.0, 1.6), RES)


def _pair_gaps(xy: np.ndarray, radius: float) -> np.ndarray:
    d = np.hypot(*(xy[:, None] - xy[None]).transpose(2, 0, 1))
    return d[np.triu_indices(len(xy), 1)] - 2 * radius


def _run(fs: FreeSpace, cfg: CrowdConfig, seed: int, steps: int, robot_xy=(1.0, 1.0), dt=0.5):
    crowd = Crowd(cfg, fs, np.random.default_rng(seed), np.array(robot_xy), ROBOT_R)
    track = [crowd.positions_xy_m]
    for _ in range(steps):
        crowd.step(dt, np.array(robot_xy), np.zeros(2), ROBOT_R)
        track.append(crowd.positions_xy_m)
    return crowd, np.array(track)


def test_count_rule():
    fs = two_rooms()
    area = fs.free_area_m2()
    crowd = Crowd(CrowdConfig(), fs, np.random.default_rng(0), np.array([1.0, 1.0]), ROBOT_R)
    assert len(crowd) == max(1, math.floor(area / 8.0)), f"{len(crowd)} people for {area:.1f} m^2"
    crowd = Crowd(CrowdConfig(area_per_person_m2=5.0), fs, np.random.default_rng(0), np.array([1.0, 1.0]), ROBOT_R)
    assert len(crowd) == math.floor(area / 5.0), f"{len(crowd)} people for {area:.1f} m^2 at 5 m^2 each"
    small = FreeSpace.from_grid(_walled(2.0, 2.0), RES)
    crowd = Crowd(CrowdConfig(min_goal_dist_m=3.0), small, np.random.default_rng(0), np.array([-5.0, -5.0]), 0.0)
    assert len(crowd) == 1, f"{small.free_area_m2():.1f} m^2 should still hold one person, got {len(crowd)}"
    crowd.step(0.5, np.array([-5.0, -5.0]), np.zeros(2), 0.0)   # goals exist even if none is 3 m away
    assert len(Crowd(CrowdConfig(count=0), fs, np.random.default_rng(0), np.zeros(2), ROBOT_R)) == 0


def test_empty_crowd_steps_and_meshes():
    crowd = Crowd(CrowdConfig(count=0), two_rooms(), np.random.default_rng(0), np.zeros(2), ROBOT_R)
    crowd.step(0.5, np.zeros(2), np.zeros(2), ROBOT_R)
    v, f, c = crowd.mesh()
    assert v.shape == (0, 3) and f.shape == (0, 3) and crowd.time_s == 0.5
    assert not crowd.overlaps_disc(np.zeros(2), 1.0)
    closet = FreeSpace.from_grid(_walled(0.4, 0.4), RES)          # too narrow for anybody
    assert len(Crowd(CrowdConfig(count=0), closet, np.random.default_rng(0), np.zeros(2), ROBOT_R)) == 0
    with pytest.raises(ConfigError, match="radius"):
        Crowd(CrowdConfig(count=1), closet, np.random.default_rng(0), np.zeros(2), ROBOT_R)


def test_too_many_people_is_a_clear_error():
    with pytest.raises(ConfigError, match="crowd.count=60"):
        Crowd(CrowdConfig(count=60), FreeSpace.from_grid(_walled(3.0, 3.0), RES), np.random.default_rng(0),
              np.zeros(2), 0.0)


def test_spawn_is_navigable_apart_and_off_the_robot():
    fs = pillar_room()
    robot = np.array([2.0, 3.0])
    for seed in range(5):
        crowd = Crowd(CrowdConfig(count=8), fs, np.random.default_rng(seed), robot, 0.5)
        xy = crowd.positions_xy_m
        assert fs.is_navigable(xy, 0.3).all(), f"seed {seed}: a person spawned where it does not fit"
        gap = _pair_gaps(xy, 0.3).min()
        assert gap >= 0.0, f"seed {seed}: two people spawned overlapping by {-gap:.3f} m"
        robot_gap = (np.hypot(*(xy - robot).T) - 0.3 - 0.5).min()
        assert robot_gap >= 0.0, f"seed {seed}: a person spawned {-robot_gap:.3f} m into the avoid disc"
        speeds = crowd.preferred_speeds_mps
        assert ((speeds >= 0.4) & (speeds <= 0.6)).all(), f"speeds {speeds} outside 0.5 x [0.8, 1.2]"
        goal_d = np.hypot(*(crowd.goals_xy_m - xy).T)
        assert (goal_d >= 3.0).all(), f"seed {seed}: goals only {goal_d.min():.2f} m away (min 3 m)"
        assert fs.is_navigable(crowd.goals_xy_m, 0.3).all(), f"seed {seed}: a goal is not navigable"
        h = crowd.heights_m
        assert ((h >= 1.6) & (h <= 1.9)).all(), h


def test_same_seed_bit_identical_tracks_different_seed_differs():
    fs = two_rooms()
    cfg = CrowdConfig(count=6)
    _, a = _run(fs, cfg, 7, 60)
    ca, _ = _run(fs, cfg, 7, 0)
    _, b = _run(fs, cfg, 7, 60)
    _, c = _run(fs, cfg, 8, 60)
    assert a.tobytes() == b.tobytes(), "same seed gave different tracks"
    assert np.abs(a - c).max() > 1.0, "different seeds gave (nearly) the same tracks"
    cb, _ = _run(fs, cfg, 7, 0)
    assert [lk for lk in ca.looks] == [lk for lk in cb.looks]


@pytest.mark.parametrize("scene", [two_rooms, pillar_room])
def test_500_steps_no_walls_no_overlaps_and_progress(scene):
    """People never leave free space nor overlap each other or a static robot, and keep walking."""
    fs = scene()
    robot = np.array([2.0, 3.5])          # stands in everyone's way in the left room / beside the pillar
    cfg = CrowdConfig(count=8)
    crowd, track = _run(fs, cfg, 3, 500, robot_xy=robot)
    steps, p = track.shape[:2]
    inside = fs.is_navigable(track.reshape(-1, 2), cfg.radius_m - 0.01).reshape(steps, p)
    assert inside.all(), f"{(~inside).sum()} person-steps inside walls or obstacles (first at step " \
                         f"{np.argwhere(~inside)[0][0]})"
    worst_pair = min(_pair_gaps(xy, cfg.radius_m).min() for xy in track)
    assert worst_pair > -0.02, f"two people overlapped by {-worst_pair:.3f} m"
    worst_robot = (np.hypot(*(track - robot).transpose(2, 0, 1)) - cfg.radius_m - ROBOT_R).min()
    assert worst_robot >= 0.0, f"a person came {-worst_robot:.3f} m into the robot"
    # progress: 250 s of walking at 0.4-0.6 m/s with goals >= 3 m apart
    sim_s = 500 * 0.5
    walked = crowd.distance_walked_m
    ideal = crowd.preferred_speeds_mps * sim_s
    assert (walked <= ideal * 1.001).all(), f"someone walked faster than their speed: {walked / ideal}"
    assert (walked / ideal).mean() > 0.4, f"people walked only {(walked / ideal).mean():.2f} of the time on average"
    assert (crowd.goals_reached >= 2).all(), f"goals reached per person: {crowd.goals_reached}"
    step_len = np.hypot(*np.diff(track, axis=0).transpose(2, 0, 1))
    assert np.isclose(step_len.sum(axis=0), walked, rtol=0.25).all() and (step_len <= 0.6 * 0.5 + 1e-9).all()


def test_people_pass_each_other_in_a_corridor():
    fs = corridor()
    crowd, track = _run(fs, CrowdConfig(count=4, min_goal_dist_m=6.0), 1, 300, robot_xy=(-5.0, -5.0))
    assert fs.is_navigable(track.reshape(-1, 2), 0.29).all(), "someone left the corridor"
    worst_pair = min(_pair_gaps(xy, 0.3).min() for xy in track)
    assert worst_pair > -0.02, f"two people overlapped by {-worst_pair:.3f} m"
    assert (crowd.goals_reached >= 3).all(), f"goals reached along the corridor: {crowd.goals_reached}"


def _one_person(cfg: CrowdConfig, fs: FreeSpace, robot: np.ndarray, seeds: int, wanted, why: str) -> Crowd:
    """The crowd of one person from the first of ``seeds`` seeds whose start and first goal pass
    ``wanted(start, goal)``; the test fails with ``why`` when none does."""
    for seed in range(seeds):
        crowd = Crowd(cfg, fs, np.random.default_rng(seed), robot, ROBOT_R)
        if wanted(crowd.positions_xy_m[0], crowd.goals_xy_m[0]):
            return crowd
    pytest.fail(why)


def test_a_blocked_person_picks_a_new_goal():
    """The robot parks in a 1 m corridor; whoever wants past it gives up after stuck_timeout_s."""
    occ = _walled(8.0, 1.0)
    fs = FreeSpace.from_grid(occ, RES)
    robot = np.array([4.0, 0.55])
    cfg = CrowdConfig(count=1, min_goal_dist_m=5.0, stuck_timeout_s=4.0)
    crowd = _one_person(cfg, fs, robot, 20, lambda start, goal: (start[0] - robot[0]) * (goal[0] - robot[0]) < 0,
                        "no seed put the person and its goal on opposite sides of the robot")
    start, first_goal = crowd.positions_xy_m[0], crowd.goals_xy_m[0]
    for _ in range(60):
        crowd.step(0.5, robot, np.zeros(2), ROBOT_R)
        gap = np.hypot(*(crowd.positions_xy_m[0] - robot)) - 0.3 - ROBOT_R
        assert gap >= 0.0, f"the person came {-gap:.3f} m into the robot"
    assert crowd.goals_reached[0] >= 1 or not np.array_equal(crowd.goals_xy_m[0], first_goal), \
        "the blocked person kept its unreachable goal for 30 s"
    assert (crowd.positions_xy_m[0, 0] - robot[0]) * (start[0] - robot[0]) > 0, "the person went through the robot"


def _follow_a_creeping_robot(frac: float) -> tuple[float | None, float]:
    """A person walks up behind the robot, which creeps along a 1 m corridor toward the person's goal at 5 cm/s
    for 30 s: (seconds from catching up with the robot to giving up the first goal, None if it kept it; how far
    back, in metres, the person went from where it caught up)."""
    fs = FreeSpace.from_grid(_walled(10.0, 1.0), RES)
    cfg = CrowdConfig(count=1, min_goal_dist_m=5.0, stuck_speed_frac=frac)
    robot = np.array([3.0, 0.55])
    # the robot stays between the person and its goal for the whole 30 s
    crowd = _one_person(cfg, fs, robot, 40, lambda start, goal: start[0] < 2.5 and goal[0] > 6.5,
                        "no seed put the person left of the robot with a goal far right of it")
    first_goal, caught_up, gave_up, back_m = crowd.goals_xy_m[0], None, None, 0.0
    for k in range(60):
        moved = robot + np.array([0.025, 0.0])
        crowd.step(0.5, moved, (moved - robot) / 0.5, ROBOT_R)
        robot = moved
        x = crowd.positions_xy_m[0, 0]
        gap = np.hypot(*(crowd.positions_xy_m[0] - robot)) - 0.3 - ROBOT_R
        assert gap >= 0.0, f"the person came {-gap:.3f} m into the robot"
        if caught_up is None and gap < 0.05:
            caught_up = (k, x)
        if caught_up is not None:
            back_m = max(back_m, caught_up[1] - x)
            if gave_up is None and not np.array_equal(crowd.goals_xy_m[0], first_goal):
                gave_up = 0.5 * (k - caught_up[0])
    assert caught_up is not None, "the person never caught up with the robot"
    return gave_up, back_m


def test_a_person_inching_behind_the_robot_picks_a_new_goal():
    """Progress counts only at stuck_speed_frac of the person's speed: following the robot at 5 cm/s (a tenth of
    walking speed) is being stuck, so the person soon gives up its goal and walks back; counting any shortening of
    its path as progress (stuck_speed_frac 0), it follows the robot for the whole 30 s."""
    gave_up, back_m = _follow_a_creeping_robot(0.25)
    assert gave_up is not None and gave_up <= 3.0 + 2.0, f"the person inched behind the robot until {gave_up} s"
    assert back_m > 1.0, f"the person went only {back_m:.2f} m back from the robot"
    gave_up, back_m = _follow_a_creeping_robot(0.0)
    assert gave_up is None and back_m < 0.1, "with stuck_speed_frac 0 the person should follow the robot"


def test_gait_phase_follows_distance_and_heading_turns_smoothly():
    fs = pillar_room()
    crowd = Crowd(CrowdConfig(count=5), fs, np.random.default_rng(2), np.array([1.0, 1.0]), ROBOT_R)
    stride = stride_length_m(crowd.heights_m)
    phase0, walked0 = crowd.gait_phase_rad, crowd.distance_walked_m
    max_turn = 0.0
    heading = crowd.headings_rad
    aligned = []
    for _ in range(80):
        crowd.step(0.1, np.array([1.0, 1.0]), np.zeros(2), ROBOT_R)
        new_heading = crowd.headings_rad
        max_turn = max(max_turn, np.abs(np.angle(np.exp(1j * (new_heading - heading)))).max())
        heading = new_heading
        v = crowd.velocities_mps
        moving = np.hypot(*v.T) > 0.3
        aligned.extend(np.cos(np.arctan2(v[moving, 1], v[moving, 0]) - heading[moving]))
    expected = np.mod(phase0 + 2 * np.pi * (crowd.distance_walked_m - walked0) / stride, 2 * np.pi)
    err = np.abs(np.angle(np.exp(1j * (crowd.gait_phase_rad - expected)))).max()
    assert err < 1e-6, f"gait phase is off the walked distance by {err:.2e} rad"
    assert max_turn <= np.pi * 0.1 + 1e-9, f"heading jumped {max_turn:.3f} rad in 0.1 s"
    assert np.median(aligned) > 0.95, f"walkers face their direction of motion poorly (median cos {np.median(aligned):.2f})"


def test_mesh_and_overlaps_disc_match_the_state():
    crowd, _ = _run(pillar_room(), CrowdConfig(count=4), 4, 10)
    v, f, c = crowd.mesh()
    assert v.shape == (4 * VERTICES_PER_PERSON, 3) and f.shape[0] == c.shape[0]
    per = v.reshape(4, VERTICES_PER_PERSON, 3)
    d = np.hypot(*(per[..., :2] - crowd.positions_xy_m[:, None]).transpose(2, 0, 1)).max()
    assert d < 0.5, f"a mesh vertex is {d:.2f} m from its person"
    top = per[..., 2].max(axis=1)
    assert (np.abs(top - crowd.heights_m) < 0.05 * crowd.heights_m).all(), (top, crowd.heights_m)
    p0 = crowd.positions_xy_m[0]
    assert crowd.overlaps_disc(p0 + np.array([0.4, 0.0]), 0.18)
    assert not crowd.overlaps_disc(np.array([-50.0, -50.0]), 0.18)


def test_line_of_sight_kernel_matches_freespace():
    """_segment_clear is the compiled twin of FreeSpace.segment_navigable (same samples, same cells)."""
    fs = two_rooms()
    nav = np.ascontiguousarray(fs.navigable(0.3))
    rng = np.random.default_rng(9)
    a = rng.uniform(-0.5, 12.5, (400, 2))
    b = a + rng.normal(0, 2.0, (400, 2))
    got = np.array([_segment_clear(nav, 0.0, 0.0, RES, *p, *q) for p, q in zip(a, b)])
    ref = np.array([fs.segment_navigable(p, q, 0.3) for p, q in zip(a, b)])
    assert got.sum() > 50 and (~got).sum() > 50, "the random segments should test both outcomes"
    assert (got == ref).mean() >= 0.995, f"{(got != ref).sum()} of 400 segments disagree"
