"""Procedural, tileable surface textures for the generated scenes.

Every surface of a generated scene carries a pattern (bricks, planks, tiles, stripes,
checks, dots, weave, cloudy noise, ...) rather than a flat colour, so that photometric
metrics (PSNR, SSIM) and the renders a Gaussian map is fitted to have real structure.
All patterns are periodic on the tile so that world-space tiling shows no seams.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TEXTURE_PX = 128
"""Side of every texture tile in texels."""

PATTERNS = ("noise", "stripes", "checker", "bricks", "tiles", "planks", "dots", "weave", "diamonds", "marble")


@dataclass(frozen=True)
class Material:
    """A texture tile and its world size."""

    name: str
    texture: np.ndarray           # uint8 (TEXTURE_PX, TEXTURE_PX, 3)
    tile_m: float                 # world size of the tile in metres


def _grid(t: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel centre coordinates in [0, 1), rows (v) and columns (u)."""
    c = (np.arange(t) + 0.5) / t
    return np.meshgrid(c, c, indexing="ij")


def periodic_noise(rng: np.random.Generator, t: int, beta: float = 2.0) -> np.ndarray:
    """Tileable fractal noise in [0, 1] with power spectrum ~ 1/f^beta (periodic by construction, via FFT)."""
    f = np.fft.fftfreq(t)
    fr = np.sqrt(f[:, None] ** 2 + f[None, :] ** 2)
    fr[0, 0] = 1.0
    spectrum = (rng.normal(size=(t, t)) + 1j * rng.normal(size=(t, t))) / fr ** (beta / 2)
    spectrum[0, 0] = 0.0
    img = np.real(np.fft.ifft2(spectrum))
    img -= img.min()
    return img / max(img.max(), 1e-12)


def _pattern(kind: str, rng: np.random.Generator, t: int) -> np.ndarray:
    """A scalar pattern in [0, 1], shape (t, t), periodic on the tile."""
    v, u = _grid(t)
    noise = periodic_noise(rng, t, beta=2.5)
    if kind == "noise":
        return periodic_noise(rng, t, beta=float(rng.uniform(1.5, 3.0)))
    if kind == "stripes":
        n = int(rng.integers(3, 9))
        coord = u if rng.random() < 0.5 else v
        duty = rng.uniform(0.3, 0.7)
        return ((coord * n) % 1.0 < duty).astype(float) * 0.8 + 0.2 * noise
    if kind == "checker":
        n = int(rng.choice([2, 4, 6, 8]))
        return (((np.floor(u * n) + np.floor(v * n)) % 2) * 0.85 + 0.15 * noise)
    if kind in ("bricks", "tiles"):
        rows = int(rng.integers(4, 9)) if kind == "bricks" else int(rng.choice([2, 4, 5, 8]))
        cols = rows // 2 if kind == "bricks" else rows
        cols = max(cols, 1)
        shift = (np.floor(v * rows) % 2) * 0.5 if kind == "bricks" else 0.0
        uu = (u * cols + shift) % 1.0
        vv = (v * rows) % 1.0
        mortar = rng.uniform(0.04, 0.09)
        joint = (uu < mortar) | (vv < mortar * cols / rows * (2 if kind == "bricks" else 1))
        cell_id = (np.floor(v * rows) * 97 + np.floor(u * cols + shift) * 13) % 7 / 7.0
        body = 0.55 + 0.3 * cell_id + 0.15 * noise
        return np.where(joint, 0.05 + 0.1 * noise, body)
    if kind == "planks":
        n = int(rng.integers(3, 7))
        plank = np.floor(v * n)
        grain = 0.5 + 0.5 * np.sin(2 * np.pi * (u * int(rng.integers(1, 4)) + 3.0 * noise) * 6 + plank * 1.7)
        seam = ((v * n) % 1.0) < 0.04
        tone = (plank * 37 % 5) / 5.0
        return np.where(seam, 0.05, 0.35 + 0.35 * grain * 0.6 + 0.25 * tone)
    if kind == "dots":
        n = int(rng.choice([2, 3, 4, 6]))
        du = (u * n) % 1.0 - 0.5
        dv = (v * n) % 1.0 - 0.5
        r = rng.uniform(0.18, 0.35)
        return np.where(du ** 2 + dv ** 2 < r ** 2, 1.0, 0.15) * 0.85 + 0.15 * noise
    if kind == "weave":
        n = int(rng.choice([8, 16]))
        a = 0.5 + 0.5 * np.sin(2 * np.pi * u * n)
        b = 0.5 + 0.5 * np.sin(2 * np.pi * v * n)
        over = ((np.floor(u * n) + np.floor(v * n)) % 2).astype(bool)
        return np.where(over, a, b) * 0.7 + 0.3 * noise
    if kind == "diamonds":
        n = int(rng.choice([2, 3, 4]))
        d = np.abs((u * n) % 1.0 - 0.5) + np.abs((v * n) % 1.0 - 0.5)
        return (d < 0.35).astype(float) * 0.7 + 0.3 * (d < 0.2) * noise + 0.15 * noise
    if kind == "marble":
        vein = np.abs(np.sin(2 * np.pi * (u + v + 2.5 * periodic_noise(rng, t, 2.2))))
        return 1.0 - 0.7 * (1.0 - vein) ** 6 - 0.1 * noise
    raise ValueError(f"unknown pattern {kind!r}; known: {', '.join(PATTERNS)}")


# Colour families (RGB in [0, 1]) per surface category: a base colour is drawn from the family
# and a second, contrasting one is derived from it.
FAMILIES = {
    "wall": [(0.86, 0.82, 0.74), (0.75, 0.82, 0.86), (0.86, 0.76, 0.72), (0.78, 0.85, 0.74), (0.9, 0.88, 0.82),
             (0.72, 0.7, 0.8), (0.88, 0.8, 0.62)],
    "floor": [(0.55, 0.38, 0.22), (0.68, 0.52, 0.34), (0.45, 0.45, 0.47), (0.72, 0.7, 0.66), (0.4, 0.28, 0.18),
              (0.6, 0.58, 0.5)],
    "ceiling": [(0.93, 0.93, 0.9), (0.88, 0.9, 0.92), (0.92, 0.9, 0.86)],
    "wood": [(0.52, 0.34, 0.18), (0.7, 0.52, 0.32), (0.36, 0.23, 0.13), (0.82, 0.7, 0.52)],
    "fabric": [(0.3, 0.38, 0.6), (0.62, 0.2, 0.2), (0.35, 0.55, 0.35), (0.75, 0.68, 0.5), (0.5, 0.5, 0.55),
               (0.8, 0.5, 0.3), (0.45, 0.3, 0.5)],
    "metal": [(0.62, 0.63, 0.66), (0.3, 0.31, 0.33), (0.8, 0.8, 0.78)],
    "paint": [(0.9, 0.9, 0.88), (0.2, 0.22, 0.25), (0.75, 0.2, 0.15), (0.15, 0.4, 0.6), (0.9, 0.75, 0.2),
              (0.3, 0.6, 0.45)],
    "plant": [(0.2, 0.45, 0.18), (0.28, 0.55, 0.25), (0.16, 0.36, 0.2)],
}

CATEGORY_PATTERNS = {
    "wall": ("noise", "stripes", "diamonds", "bricks", "dots", "weave", "marble"),
    "floor": ("planks", "tiles", "checker", "marble", "noise"),
    "ceiling": ("noise", "tiles"),
    "wood": ("planks", "noise"),
    "fabric": ("weave", "checker", "stripes", "dots", "noise"),
    "metal": ("noise", "stripes"),
    "paint": ("noise", "stripes", "checker", "dots", "diamonds", "marble"),
    "plant": ("noise", "weave"),
}

CATEGORY_TILE_M = {
    "wall": (0.8, 1.6), "floor": (0.8, 1.6), "ceiling": (1.0, 2.0), "wood": (0.5, 1.0),
    "fabric": (0.3, 0.6), "metal": (0.4, 0.8), "paint": (0.3, 0.8), "plant": (0.2, 0.4),
}


def make_material(category: str, rng: np.random.Generator, t: int = TEXTURE_PX) -> Material:
    """A random material of ``category`` (wall, floor, ceiling, wood, fabric, metal, paint, plant)."""
    fam = FAMILIES[category]
    base = np.array(fam[int(rng.integers(len(fam)))]) * rng.uniform(0.85, 1.1, size=3)
    kind = str(rng.choice(CATEGORY_PATTERNS[category]))
    contrast = rng.uniform(0.25, 0.55)
    darker_or_lighter = base * (1.0 - contrast) if base.mean() > 0.5 else np.clip(base + contrast, 0, 1)
    other = np.array(fam[int(rng.integers(len(fam)))]) if rng.random() < 0.35 else darker_or_lighter
    if np.abs(other - base).mean() < 0.12:  # too close to read as a pattern
        other = darker_or_lighter
    p = _pattern(kind, rng, t)[..., None]
    img = (1.0 - p) * other + p * base
    img = np.clip(img, 0.0, 1.0)
    lo, hi = CATEGORY_TILE_M[category]
    return Material(name=f"{category}/{kind}", texture=(img * 255 + 0.5).astype(np.uint8),
                    tile_m=float(rng.uniform(lo, hi)))
