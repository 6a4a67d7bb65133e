"""Procedural surface textures (numpy only), seeded, tileable.

Each generator returns an (S, S, 3) uint8 RGB image that tiles seamlessly (noise is
built from periodic octaves), so planar world-space UVs with wrap-around show no
seams. Used by floor-plan extrusion and the procedural scene generator.
"""

from __future__ import annotations

import numpy as np


def _periodic_noise(rng: np.random.Generator, size: int, octaves: int = 4) -> np.ndarray:
    """(size, size) float32 in [0, 1], tileable value noise (sum of upsampled random grids)."""
    import cv2

    out = np.zeros((size, size), np.float32)
    amplitude, total = 1.0, 0.0
    for octave in range(octaves):
        cells = 2 ** (octave + 2)
        grid = rng.random((cells, cells)).astype(np.float32)
        tiled = np.tile(grid, (3, 3))  # wrap so interpolation is periodic
        big = cv2.resize(tiled, (3 * size, 3 * size), interpolation=cv2.INTER_CUBIC)
        out += amplitude * big[size:2 * size, size:2 * size]
        total += amplitude
        amplitude *= 0.5
    out /= total
    return (out - out.min()) / max(float(out.max() - out.min()), 1e-6)


def _shade(base_color, intensity: np.ndarray) -> np.ndarray:
    """Modulate an RGB colour by an (S, S) intensity field around 1."""
    base = np.asarray(base_color, np.float32).reshape(1, 1, 3)
    return np.clip(base * intensity[..., None], 0, 255).astype(np.uint8)


def plaster(rng, base_color, size: int = 64) -> np.ndarray:
    """Painted wall: faint low-frequency mottling."""
    return _shade(base_color, 0.92 + 0.12 * _periodic_noise(rng, size, 3))


def paint(rng, base_color, size: int = 64) -> np.ndarray:
    """Smooth painted surface: very faint large-scale mottling (walls, ceilings)."""
    return _shade(base_color, 0.96 + 0.05 * _periodic_noise(rng, size, 2))


def wood(rng, base_color, size: int = 128) -> np.ndarray:
    """Floor boards: planks along u with grain and per-plank tone."""
    planks = int(rng.integers(4, 9))
    v = np.arange(size)[:, None] * planks // size
    tone = 0.8 + 0.35 * rng.random(planks)[v]
    u = np.arange(size)[None, :] / size
    grain = 0.9 + 0.1 * np.sin(2 * np.pi * (u * rng.integers(2, 6) + 0.3 * _periodic_noise(rng, size, 3)) * 4)
    seams = np.where((np.arange(size)[:, None] * planks) % size < planks, 0.6, 1.0)
    return _shade(base_color, tone * grain * seams)


def tiles(rng, base_color, size: int = 128) -> np.ndarray:
    """Square tiles with grout lines."""
    count = int(rng.integers(2, 6))
    step = size // count
    y, x = np.mgrid[:size, :size]
    grout = ((x % step) < 2) | ((y % step) < 2)
    tone = 0.9 + 0.15 * rng.random((count + 1, count + 1))[y // step, x // step]
    intensity = np.where(grout, 0.75, tone * (0.95 + 0.08 * _periodic_noise(rng, size, 2)))
    return _shade(base_color, intensity)


def carpet(rng, base_color, size: int = 64) -> np.ndarray:
    """Carpet: fine high-frequency speckle."""
    return _shade(base_color, 0.8 + 0.3 * rng.random((size, size)).astype(np.float32))


def wallpaper(rng, base_color, size: int = 128) -> np.ndarray:
    """Vertical stripes in two tones."""
    stripes = int(rng.integers(3, 10))
    u = np.arange(size)[None, :].repeat(size, 0)
    intensity = np.where((u * stripes // size) % 2 == 0, 1.0, 0.82) * (0.95 + 0.08 * _periodic_noise(rng, size, 2))
    return _shade(base_color, intensity)


def brick(rng, base_color, size: int = 128) -> np.ndarray:
    """Running-bond brick with mortar."""
    rows = int(rng.integers(6, 12))
    h = size // rows
    y, x = np.mgrid[:size, :size]
    row = y // h
    offset = (row % 2) * (size // 4)
    w = size // 2
    mortar = ((y % h) < 2) | (((x + offset) % w) < 2)
    tone = 0.85 + 0.3 * rng.random((size // h + 1, 4))[row, ((x + offset) // w) % 4]
    return _shade(base_color, np.where(mortar, 1.4, tone))


def concrete(rng, base_color, size: int = 64) -> np.ndarray:
    """Concrete: mid-frequency blotches."""
    return _shade(base_color, 0.8 + 0.35 * _periodic_noise(rng, size, 5))


def fabric(rng, base_color, size: int = 64) -> np.ndarray:
    """Woven upholstery: fine cross-hatch weave with soft mottling."""
    period = int(rng.choice([4, 8]))
    y, x = np.mgrid[:size, :size]
    weave = np.where(((x // (period // 2)) + (y // (period // 2))) % 2 == 0, 1.0, 0.88)
    return _shade(base_color, weave * (0.9 + 0.15 * _periodic_noise(rng, size, 3)))


def marble(rng, base_color, size: int = 128) -> np.ndarray:
    """Polished stone: bright base with thin dark veins (ridges of periodic noise)."""
    noise = _periodic_noise(rng, size, 5)
    veins = np.abs(np.sin(np.pi * 6 * noise))
    intensity = 0.97 - 0.3 * np.clip(1.0 - veins / 0.15, 0.0, 1.0) + 0.06 * _periodic_noise(rng, size, 2)
    return _shade(base_color, intensity)


def parquet(rng, base_color, size: int = 128) -> np.ndarray:
    """Parquet: square blocks of short planks, alternating direction, per-plank tone."""
    blocks, planks = 4, int(rng.choice([2, 4]))
    step = size // blocks
    y, x = np.mgrid[:size, :size]
    by, bx, ly, lx = y // step, x // step, y % step, x % step
    vertical = (by + bx) % 2 == 0
    plank = np.where(vertical, lx * planks // step, ly * planks // step)
    seam = np.where(vertical, (lx * planks) % step < planks, (ly * planks) % step < planks) | (lx < 1) | (ly < 1)
    tone = 0.8 + 0.3 * rng.random((blocks, blocks, planks))[by, bx, plank]
    return _shade(base_color, np.where(seam, 0.6, tone * (0.93 + 0.1 * _periodic_noise(rng, size, 3))))


TEXTURES = {
    "plaster": plaster, "paint": paint, "wood": wood, "tiles": tiles, "carpet": carpet,
    "wallpaper": wallpaper, "brick": brick, "concrete": concrete,
    "fabric": fabric, "marble": marble, "parquet": parquet,
}


def make_texture(kind: str, rng: np.random.Generator, base_color, size: int | None = None) -> np.ndarray:
    """Generate a texture of `kind` (a key of :data:`TEXTURES`) around `base_color` (RGB 0-255)."""
    generator = TEXTURES[kind]
    return generator(rng, base_color) if size is None else generator(rng, base_color, size)
