import numpy as np

from dynactivegs.eval.classification import auroc


def test_auroc_matches_pairwise_definition():
    rng = np.random.default_rng(0)
    s = np.round(rng.normal(size=300), 1)          # with ties
    y = rng.random(300) < 0.3
    pos, neg = s[y], s[~y]
    pairwise = ((pos[:, None] > neg[None]).sum() + 0.5 * (pos[:, None] == neg[None]).sum()) / (len(pos) * len(neg))
    assert abs(auroc(s, y) - pairwise) < 1e-12
    assert auroc(np.arange(10), np.arange(10) >= 5) == 1.0
    assert np.isnan(auroc(np.arange(4), np.zeros(4, bool)))
