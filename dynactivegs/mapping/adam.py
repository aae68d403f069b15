"""Adam over the Gaussian map's raw parameters, with its moments kept in explicit state.

The optimiser state is part of the mapping stage's state (so a run can be snapshotted and
replayed), and it must follow the map when Gaussians are added (zero moments) or pruned (rows
dropped), which ``torch.optim.Adam``'s opaque per-parameter state makes awkward.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from dynactivegs.splat.gaussians import Gaussians

BETA1, BETA2, EPS = 0.9, 0.999, 1e-15


@dataclass(frozen=True)
class AdamState:
    """First and second moments for each raw parameter of a :class:`Gaussians` set, and the step count."""

    m: tuple[torch.Tensor, ...]       # like Gaussians.tensors()
    v: tuple[torch.Tensor, ...]
    t: int

    @staticmethod
    def zeros_like(g: Gaussians) -> "AdamState":
        z = tuple(torch.zeros_like(p) for p in g.tensors())
        return AdamState(z, tuple(torch.zeros_like(p) for p in g.tensors()), 0)

    def cat(self, added: Gaussians) -> "AdamState":
        """Moments for the map with ``added`` appended (new rows start at zero)."""
        return AdamState(tuple(torch.cat([a, torch.zeros_like(b)]) for a, b in zip(self.m, added.tensors())),
                         tuple(torch.cat([a, torch.zeros_like(b)]) for a, b in zip(self.v, added.tensors())), self.t)

    def masked(self, keep: torch.Tensor) -> "AdamState":
        return AdamState(tuple(a[keep] for a in self.m), tuple(a[keep] for a in self.v), self.t)


def adam_step(g: Gaussians, grads: tuple[torch.Tensor, ...], state: AdamState,
              lrs: tuple[float, ...]) -> tuple[Gaussians, AdamState]:
    """One Adam update of every raw parameter with its own learning rate; returns new tensors."""
    assert len(grads) == len(lrs) == len(state.m) == 5
    t = state.t + 1
    c1, c2 = 1 - BETA1 ** t, 1 - BETA2 ** t
    params, ms, vs = [], [], []
    for p, gr, m, v, lr in zip(g.tensors(), grads, state.m, state.v, lrs):
        m = BETA1 * m + (1 - BETA1) * gr
        v = BETA2 * v + (1 - BETA2) * gr * gr
        params.append(p.detach() - lr * (m / c1) / (torch.sqrt(v / c2) + EPS))
        ms.append(m)
        vs.append(v)
    return Gaussians(*params), AdamState(tuple(ms), tuple(vs), t)
