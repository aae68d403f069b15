"""Checkpoints of a step budget and the cheap coverage metric."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from dynactivegs.eval.progress import CoverageProbe, checkpoint_steps
from dynactivegs.splat import Gaussians


def test_checkpoints_are_the_quarter_steps_of_the_budget():
    assert checkpoint_steps(1000) == (250, 500, 750, 1000)
    assert checkpoint_steps(10) == (3, 5, 8, 10)
    assert checkpoint_steps(3) == (1, 2, 3, 3)
    assert checkpoint_steps(1) == (1, 1, 1, 1)
    assert checkpoint_steps(200, (0.1, 1.0)) == (20, 200)
    with pytest.raises(ValueError):
        checkpoint_steps(0)


def test_coverage_is_the_share_of_ground_truth_near_the_reconstruction():
    gt = np.random.default_rng(0).random((50_000, 3)) * [4.0, 4.0, 0.0]
    probe = CoverageProbe.from_ground_truth(gt, 5_000, 5.0, seed=0)
    assert probe.points_m.shape == (5_000, 3)
    np.testing.assert_array_equal(probe.points_m, CoverageProbe.from_ground_truth(gt, 5_000, 5.0, seed=0).points_m)
    assert probe(gt) == 100.0
    assert 47.0 < probe(gt[gt[:, 0] < 2.0]) < 53.0
    assert probe(np.zeros((0, 3))) == 0.0
    assert probe(gt + [0.0, 0.0, 0.06]) == 0.0                  # 6 cm away: beyond the 5 cm threshold
    # From a Gaussian map: only opaque Gaussians count.
    means = torch.as_tensor(gt[gt[:, 0] < 2.0])
    n = len(means)
    opacity = torch.full((n,), 0.9, dtype=torch.float64)
    g = Gaussians.from_params(means, torch.full((n, 3), 0.01, dtype=torch.float64),
                              torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64).repeat(n, 1), opacity,
                              torch.full((n, 3), 0.5, dtype=torch.float64))
    assert probe.of_gaussians(g) == pytest.approx(probe(gt[gt[:, 0] < 2.0]))
    assert probe.of_gaussians(g, opacity_min=0.95) == 0.0
