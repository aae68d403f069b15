"""The uncertainty predictor separates moving people from the static scene.

The map is the simulator's static render at each pose (a perfect static map), so the test
isolates perception: features, MLP, loss and online training.
"""

from __future__ import annotations

import numpy as np
import pytest

from dynactivegs.config import CameraConfig, CrowdConfig, SimConfig
from dynactivegs.errors import ConfigError, DagsError
from dynactivegs.eval.classification import auroc
from dynactivegs.perception.features import FeatureConfig, make_extractor
from dynactivegs.perception.uncertainty import UncertaintyConfig, init_state, update
from dynactivegs.rng import derive_rng
from dynactivegs.sim.scripted import ScriptedDriver
from dynactivegs.sim.world import Simulator


def tour(scene: str, steps: int, crowd: CrowdConfig, backend: str = "filters", seed: int = 0):
    """Runs perception online along a scripted tour; yields (step, result, truth, frame)."""
    sim = Simulator(SimConfig(scene=scene, crowd=crowd, camera=CameraConfig()), seed)
    drv = ScriptedDriver(sim.freespace, 0.18, derive_rng(seed, "driver"))
    extractor = make_extractor(FeatureConfig(backend=backend), seed)
    cfg = UncertaintyConfig()
    state = init_state(cfg, extractor.channels, seed)
    rng = derive_rng(seed, "perception")
    for k in range(steps):
        frame, truth = sim.observation()
        gt = sim.render_static(frame.T_world_cam)
        res = update(cfg, state, extractor(frame.rgb), frame.rgb, frame.depth_m, gt.rgb / 255.0, gt.depth_m,
                     (gt.depth_m > 0).astype(np.float32), rng)
        state = res.state
        yield k, res, truth, frame
        sim.step(drv.act(truth.robot.x_m, truth.robot.y_m, truth.robot.yaw_rad, truth.collided))


@pytest.mark.parametrize("backend", ["filters", "random_conv"])
def test_beta_separates_people_from_static_pixels(backend):
    scores, labels = [], []
    for k, res, truth, frame in tour("apartment-00", 70, CrowdConfig(), backend):
        if k >= 30:                       # warm-up
            valid = frame.depth_m > 0
            scores.append(res.beta_before[valid])   # predicted before training on this frame
            labels.append(truth.people_mask[valid])
    y = np.concatenate(labels)
    a = auroc(np.concatenate(scores), y)
    assert y.mean() > 0.01, "people must be in view for the test to mean anything"
    assert a >= 0.85, f"{backend}: AUROC of beta vs people mask {a:.3f} < 0.85"


def test_beta_stays_low_without_people():
    betas = [res.beta for k, res, _, _ in tour("apartment-01", 40, CrowdConfig(count=0)) if k >= 20]
    b = np.concatenate([x.ravel() for x in betas])
    assert np.percentile(b, 95) < 0.2, f"95th percentile of beta with no people: {np.percentile(b, 95):.3f}"


def test_same_inputs_and_seed_give_identical_beta():
    a = [res.beta.tobytes() for _, res, _, _ in tour("tiny-00", 8, CrowdConfig(count=2))]
    b = [res.beta.tobytes() for _, res, _, _ in tour("tiny-00", 8, CrowdConfig(count=2))]
    assert a == b


def test_bad_feature_config_is_a_one_line_error(tmp_path):
    with pytest.raises(ConfigError, match="unknown feature backend 'dino'"):
        FeatureConfig(backend="dino")
    with pytest.raises(DagsError, match="checkpoint directory not found") as e:
        make_extractor(FeatureConfig(backend="dinov2", checkpoint_dir=str(tmp_path / "nope")), 0)
    assert "\n" not in str(e.value)
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(DagsError, match="incomplete: expected config.json and model.safetensors"):
        make_extractor(FeatureConfig(backend="dinov2", checkpoint_dir=str(tmp_path)), 0)
    with pytest.raises(ConfigError, match="perception.uncertainty.lr"):
        UncertaintyConfig(lr=0.0)
