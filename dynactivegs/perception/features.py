"""Per-pixel image features for the uncertainty predictor.

Every extractor maps an RGB image to a low-resolution feature map ``(C, H/s, W/s)`` at a fixed
stride ``s``. Three backends:

- ``"filters"`` (default): a fixed, hand-designed filter bank computed with OpenCV: CIE Lab
  colour and its local spread, gradient magnitude and structure-tensor (orientation) energy at
  two scales, and band-pass (difference of Gaussians) responses. No weights, no download, a few
  milliseconds per frame on a CPU. These describe *what a surface looks like* (its colour and
  texture), which is what lets the predictor generalise from pixels where it saw large render
  residuals (people's skin and plain clothes) to other pixels that look alike.
- ``"random_conv"``: a small 3-layer convolutional network with fixed random weights drawn
  from the run's seed (random features), for comparison.
- ``"dinov2"``: a DINOv2 / DINOv3 vision transformer loaded from a local checkpoint directory
  with ``transformers`` (``local_files_only``); patch tokens reshaped to a feature map.

:func:`make_extractor` builds one from :class:`FeatureConfig` and fails with a one-line
:class:`DagsError` for an unknown backend or a missing / incomplete checkpoint.
"""

from __future__ import annotations


from pathlib import Path
from typing import Protocol

import cv2
import kornia
import numpy as np
import torch
import torch.nn.functional as F

from dynactivegs.errors import DagsError
from dynactivegs.perception.config import BACKENDS, FeatureConfig  # noqa: F401  (re-exported)

class FeatureExtractor(Protocol):
    stride: int
    channels: int

    def __call__(self, rgb: np.ndarray) -> torch.Tensor:
        """uint8 (H, W, 3) -> float32 (C, ceil(H/s), ceil(W/s))."""
        ...


def _to_tensor(rgb: np.ndarray) -> torch.Tensor:
    assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3, f"rgb must be uint8 (H, W, 3), got {rgb.shape}"
    return torch.tensor(rgb).permute(2, 0, 1)[None].float() / 255.0


class FilterBankFeatures:
    """Fixed colour / gradient / texture filter bank (the default), computed with OpenCV."""

    channels = 14

    def __init__(self, stride: int = 4) -> None:
        self.stride = stride

    def _pool(self, x: np.ndarray, h: int, w: int) -> np.ndarray:
        """Average over stride x stride blocks: (H, W[, C]) -> (h, w[, C])."""
        return cv2.resize(x, (w, h), interpolation=cv2.INTER_AREA)

    def __call__(self, rgb: np.ndarray) -> torch.Tensor:
        assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3, f"rgb must be uint8 (H, W, 3), got {rgb.shape}"
        H, W = rgb.shape[:2]
        h, w = -(-H // self.stride), -(-W // self.stride)
        lab = cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB) / np.array([100.0, 128.0, 128.0],
                                                                                           np.float32)
        mean = self._pool(lab, h, w)
        spread = np.sqrt(np.maximum(self._pool(lab * lab, h, w) - mean * mean, 0.0))
        gray = np.ascontiguousarray(lab[..., 0])
        feats = [mean, spread * 4.0]
        for sigma in (1.0, 2.0):
            g = cv2.GaussianBlur(gray, (0, 0), sigma)
            gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8.0
            gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8.0
            # structure-tensor energies: gradient strength and its orientation content
            feats += [self._pool(np.sqrt(gx * gx + gy * gy), h, w)[..., None] * 8.0,
                      self._pool(gx * gx - gy * gy, h, w)[..., None] * 40.0,
                      self._pool(2 * gx * gy, h, w)[..., None] * 40.0]
        for s1, s2 in ((1.0, 2.0), (2.0, 4.0)):   # band-pass (difference of Gaussians) energy
            dog = cv2.GaussianBlur(gray, (0, 0), s1) - cv2.GaussianBlur(gray, (0, 0), s2)
            feats += [self._pool(np.abs(dog), h, w)[..., None] * 10.0]
        out = np.concatenate(feats, axis=2).astype(np.float32)
        assert out.shape == (h, w, self.channels)
        return torch.from_numpy(out).permute(2, 0, 1).contiguous()


class RandomConvFeatures:
    """A small random CNN: 3 conv layers (stride 2, 2, 1 for s = 4) with weights drawn from ``seed``."""

    channels = 32

    def __init__(self, stride: int, seed: int) -> None:
        self.stride = stride
        g = torch.Generator().manual_seed(seed)
        chans = [3, 16, 32, self.channels]
        self.weights = []
        for cin, cout in zip(chans[:-1], chans[1:]):
            w = torch.randn(cout, cin, 3, 3, generator=g) * (2.0 / (cin * 9)) ** 0.5
            self.weights.append(w)

    @torch.no_grad()
    def __call__(self, rgb: np.ndarray) -> torch.Tensor:
        x = _to_tensor(rgb) - 0.5
        for k, w in enumerate(self.weights):
            x = F.relu(F.conv2d(x, w, padding=1))
            if k < 2:
                x = F.avg_pool2d(x, 2, 2, ceil_mode=True)
        if self.stride != 4:
            h, w_ = rgb.shape[0], rgb.shape[1]
            x = F.interpolate(x, size=(-(-h // self.stride), -(-w_ // self.stride)), mode="bilinear", align_corners=False)
        return x[0]


class DinoFeatures:
    """Patch tokens of a DINOv2 / DINOv3 checkpoint loaded from a local directory."""

    REQUIRED = ("config.json",)
    WEIGHTS = ("model.safetensors", "pytorch_model.bin")

    def __init__(self, checkpoint_dir: str) -> None:
        path = Path(checkpoint_dir)
        if not checkpoint_dir or not path.is_dir():
            raise DagsError(f"DINO checkpoint directory not found: {checkpoint_dir!r}; set "
                            "perception.features.checkpoint_dir to a folder with config.json and model.safetensors")
        missing = [f for f in self.REQUIRED if not (path / f).is_file()]
        if missing or not any((path / f).is_file() for f in self.WEIGHTS):
            raise DagsError(f"DINO checkpoint at {path} is incomplete: expected config.json and "
                            "model.safetensors (or pytorch_model.bin)")
        try:
            import transformers
        except ImportError as e:
            raise DagsError("the dinov2 feature backend needs transformers: pip install -e \".[dino]\"") from e
        try:
            self.model = transformers.AutoModel.from_pretrained(str(path), local_files_only=True).eval()
        except Exception as e:  # a corrupt or foreign checkpoint
            raise DagsError(f"cannot load the DINO checkpoint at {path}: {type(e).__name__}; "
                            "check that it is a transformers DINOv2/DINOv3 model") from e
        self.stride = int(getattr(self.model.config, "patch_size", 14))
        self.channels = int(self.model.config.hidden_size)
        self.n_register = int(getattr(self.model.config, "num_register_tokens", 0))

    @torch.no_grad()
    def __call__(self, rgb: np.ndarray) -> torch.Tensor:
        x = _to_tensor(rgb)
        h, w = x.shape[-2:]
        p = self.stride
        hp, wp = -(-h // p), -(-w // p)
        x = F.interpolate(x, size=(hp * p, wp * p), mode="bilinear", align_corners=False)
        x = kornia.enhance.normalize(x, torch.tensor([0.485, 0.456, 0.406]), torch.tensor([0.229, 0.224, 0.225]))
        tokens = self.model(pixel_values=x).last_hidden_state[0, 1 + self.n_register:]
        return tokens.T.reshape(self.channels, hp, wp).float()


def make_extractor(cfg: FeatureConfig, seed: int) -> FeatureExtractor:
    """The extractor named by ``cfg.backend``."""
    if cfg.backend == "filters":
        return FilterBankFeatures(cfg.stride)
    if cfg.backend == "random_conv":
        return RandomConvFeatures(cfg.stride, seed)
    return DinoFeatures(cfg.checkpoint_dir)
