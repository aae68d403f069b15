"""LPIPS (Zhang et al. 2018, AlexNet variant, v0.1) in plain torch, from a local weights file.

LPIPS needs trained network weights (the AlexNet trunk and the linear calibration layers).
They are never downloaded here: :func:`load_lpips` reads them from a path the user gives
(``EvalConfig.lpips_weights_path``) and otherwise returns no model with the reason, so that
the metric is reported as "n/a" rather than estimated.

The weights file is a torch state dict with the key layout of the ``lpips`` package, e.g.
``torch.save(lpips.LPIPS(net="alex").state_dict(), "lpips_alex.pth")``:

- trunk: ``net.slice{1..5}.{i}.weight|bias`` for AlexNet feature layers i = 0, 3, 6, 8, 10
  (torchvision's ``features.{i}.weight|bias`` keys are accepted too);
- linear layers: ``lin{0..4}.model.1.weight`` (1, C, 1, 1) (``model.0`` when saved without dropout).

The forward pass follows the ``lpips`` package: inputs in [-1, 1], the fixed scaling layer,
the five ReLU outputs, channel-wise unit normalisation, squared differences weighted by the
linear layers, spatial mean, sum over layers.
"""

from __future__ import annotations

import re
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

ALEX_CONVS = ((0, 3, 64, 11, 4, 2), (3, 64, 192, 5, 1, 2), (6, 192, 384, 3, 1, 1), (8, 384, 256, 3, 1, 1),
              (10, 256, 256, 3, 1, 1))
"""AlexNet feature convolutions: (torchvision index, in channels, out channels, kernel, stride, padding)."""
LPIPS_MIN_PX = 31
"""Smallest image side the AlexNet trunk accepts (its third pooling stage needs a 3 x 3 input)."""
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)


class LpipsAlex(nn.Module):
    """LPIPS distance with the AlexNet trunk; ``forward(a, b)`` takes (B, 3, H, W) images in [0, 1]."""

    def __init__(self) -> None:
        super().__init__()
        self.convs = nn.ModuleList(nn.Conv2d(ci, co, k, stride=s, padding=p) for _, ci, co, k, s, p in ALEX_CONVS)
        self.lins = nn.ModuleList(nn.Conv2d(co, 1, 1, bias=False) for *_, co, _k, _s, _p in ALEX_CONVS)
        self.register_buffer("shift", torch.tensor(SHIFT)[None, :, None, None])
        self.register_buffer("scale", torch.tensor(SCALE)[None, :, None, None])

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The five ReLU outputs (relu1..relu5) for scaled input x."""
        out = []
        for k, conv in enumerate(self.convs):
            if k in (1, 2):                       # max-pool before conv2 and conv3
                x = F.max_pool2d(x, kernel_size=3, stride=2)
            x = F.relu(conv(x))
            out.append(x)
        return out

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        """(B,) LPIPS distance of images a, b (B, 3, H, W) in [0, 1]."""
        assert a.shape == b.shape and a.dim() == 4 and a.shape[1] == 3
        fa = self.features(((2 * a - 1) - self.shift) / self.scale)
        fb = self.features(((2 * b - 1) - self.shift) / self.scale)
        total = torch.zeros(a.shape[0], dtype=a.dtype, device=a.device)
        for x, y, lin in zip(fa, fb, self.lins):
            x = x / (torch.sqrt((x * x).sum(dim=1, keepdim=True)) + 1e-10)
            y = y / (torch.sqrt((y * y).sum(dim=1, keepdim=True)) + 1e-10)
            total = total + lin((x - y) ** 2).mean(dim=(1, 2, 3))
        return total


def _remap(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The ``lpips``-package / torchvision keys of ``state`` renamed to :class:`LpipsAlex`'s."""
    conv_of = {idx: k for k, (idx, *_rest) in enumerate(ALEX_CONVS)}
    out: dict[str, torch.Tensor] = {}
    for key, val in state.items():
        m = re.fullmatch(r"(?:net\.slice\d\.|features\.)(\d+)\.(weight|bias)", key)
        if m and int(m.group(1)) in conv_of:
            out[f"convs.{conv_of[int(m.group(1))]}.{m.group(2)}"] = val
            continue
        m = re.fullmatch(r"lin(\d)\.model\.\d\.weight", key)
        if m:
            out[f"lins.{m.group(1)}.weight"] = val
    return out


def load_lpips(path: str) -> tuple[LpipsAlex | None, str]:
    """The LPIPS model from a local weights file, or (None, why it is unavailable).

    The model is in eval mode, float32, on the CPU. Missing or malformed weights give None
    and a one-line reason; nothing is downloaded and nothing is guessed.
    """
    if not path:
        return None, "no LPIPS weights configured (eval.lpips_weights_path)"
    p = Path(path).expanduser()
    if not p.is_file():
        return None, f"LPIPS weights not found at {p}"
    try:
        state = torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # a corrupt or foreign file is reported, not raised
        return None, f"LPIPS weights at {p} could not be read ({type(exc).__name__})"
    if not isinstance(state, dict):
        return None, f"LPIPS weights at {p} are not a state dict"
    model = LpipsAlex()
    mapped = _remap(state)
    need = {k for k in model.state_dict() if k not in ("shift", "scale")}
    missing = sorted(need - set(mapped))
    if missing:
        return None, (f"LPIPS weights at {p} lack {len(missing)} tensors (e.g. {missing[0]}); "
                      "expected the lpips AlexNet layout")
    try:
        model.load_state_dict(mapped, strict=False)
    except RuntimeError:
        return None, f"LPIPS weights at {p} have the wrong shapes for the AlexNet variant"
    return model.eval(), f"LPIPS (AlexNet) from {p}"
