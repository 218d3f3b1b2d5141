"""Procedural albedo textures for the synthetic outdoor scenes.

Every texture function has the signature ``(rng, size) -> float32 (S, S, 3)`` and
returns *linear-RGB diffuse reflectance* (what Mitsuba's ``eval_diffuse_reflectance``
reports), clipped to the physical range ``[ALBEDO_MIN, ALBEDO_MAX] = [0.03, 0.85]``:
fresh snow is about 0.85, the darkest natural materials (wet soil, asphalt, foliage
in shade) about 0.03-0.05.

Textures are *tileable*: every pattern (noise lattices, brick bonds, block joints)
is periodic with the texture, so Mitsuba's ``wrap_mode='repeat'`` shows no seams.
Meshes use UVs in metres divided by :data:`TILE_METRES` of the texture kind, which
keeps the texel density roughly uniform over a scene.

Texture layout follows Mitsuba's ``bitmap`` plugin: ``texture[i, j]`` is the texel
centred at ``uv = ((j + 0.5) / S, (i + 0.5) / S)`` (u -> column, v -> row, row 0 at
v = 0). Meshes put ``v = -height / tile``, so the image's top is up on walls.

All noise is value noise / fBm on periodic lattices, vectorised numpy: a 256 x 256
texture takes a few milliseconds. The same generator state gives the same bytes.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = [
    "ALBEDO_MAX",
    "ALBEDO_MIN",
    "TEXTURES",
    "TILE_METRES",
    "bark",
    "brick",
    "bronze",
    "dirt",
    "fbm",
    "foliage",
    "grass",
    "marble",
    "painted",
    "paving",
    "plaster",
    "random_material_texture",
    "roof_tiles",
    "stone",
    "value_noise",
    "window",
]

ALBEDO_MIN = 0.03
ALBEDO_MAX = 0.85

Rng = np.random.Generator
TextureFn = Callable[[Rng, int], np.ndarray]


# --------------------------------------------------------------------------------------
# Noise
# --------------------------------------------------------------------------------------


def _check_size(size: int) -> None:
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 8:
        raise ValueError(f"texture size must be an integer >= 8, got {size!r}")


def value_noise(rng: Rng, size: int, period: int) -> np.ndarray:
    """Tileable value noise: random lattice values, smoothstep-interpolated.

    Args:
        rng: numpy generator (consumed: ``period**2`` uniforms).
        size: output size S.
        period: lattice cells across the texture (>= 1); the noise repeats every S
            texels, whatever the period, because lattice indices wrap modulo ``period``.

    Returns:
        float64 ``(S, S)`` in [0, 1].
    """
    _check_size(size)
    if period < 1:
        raise ValueError(f"period must be >= 1, got {period}")
    lattice = rng.random((period, period))
    x = (np.arange(size) + 0.5) * (period / size)
    i0 = np.floor(x).astype(np.int64)
    f = x - i0
    f = f * f * (3.0 - 2.0 * f)  # smoothstep: C1 across cells, no grid-aligned creases
    i0 %= period
    i1 = (i0 + 1) % period
    # Separable bilinear: interpolate along columns on the small (period, S) array first.
    cols = lattice[:, i0] + (lattice[:, i1] - lattice[:, i0]) * f[None, :]
    top = cols[i0]
    return top + (cols[i1] - top) * f[:, None]


def fbm(rng: Rng, size: int, period: int = 4, octaves: int = 5, gain: float = 0.5) -> np.ndarray:
    """Tileable fractal noise: sum of value-noise octaves with doubling frequency.

    Args:
        rng: numpy generator.
        size: output size S.
        period: lattice cells of the lowest octave.
        octaves: number of octaves; periods above S are skipped (no sub-texel detail).
        gain: amplitude ratio between successive octaves.

    Returns:
        float64 ``(S, S)``, zero mean over the texture, roughly in [-1, 1].
    """
    out = np.zeros((size, size))
    amp, norm = 1.0, 0.0
    p = period
    for _ in range(octaves):
        if p > size:
            break
        out += amp * (value_noise(rng, size, p) - 0.5)
        norm += amp
        amp *= gain
        p *= 2
    out /= max(norm, 1e-12) * 0.5
    return out - out.mean()


def _finish(img: np.ndarray) -> np.ndarray:
    """Clip to the physical albedo range and return float32 (S, S, 3)."""
    return np.clip(img, ALBEDO_MIN, ALBEDO_MAX).astype(np.float32)


def _tint(base: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """``base (3,)`` times a per-texel factor ``(S, S)`` -> ``(S, S, 3)``."""
    return factor[..., None] * np.asarray(base, dtype=np.float64)[None, None, :]


def _pick(rng: Rng, palette: list[tuple[float, float, float]], jitter: float = 0.08) -> np.ndarray:
    """One palette colour with a small multiplicative per-channel jitter."""
    base = np.asarray(palette[int(rng.integers(len(palette)))], dtype=np.float64)
    return base * (1.0 + jitter * rng.uniform(-1.0, 1.0, 3))


def _soft_step(x: np.ndarray, edge: float, width: float) -> np.ndarray:
    """0 below ``edge - width``, 1 above ``edge + width``, smooth in between."""
    t = np.clip((x - edge + width) / (2.0 * width), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _blocks(rng: Rng, size: int, rows: int, min_cols: int, max_cols: int, joint: int) -> tuple[np.ndarray, np.ndarray]:
    """Tileable running-bond blocks of random widths.

    Returns:
        block id ``(S, S)`` int64 (unique per block) and joint mask ``(S, S)`` in {0, 1}.
    """
    edges = np.linspace(0, size, rows + 1).round().astype(np.int64)
    ids = np.zeros((size, size), dtype=np.int64)
    joint_mask = np.zeros((size, size))
    cols = np.arange(size)
    next_id = 0
    for r in range(rows):
        n = int(rng.integers(min_cols, max_cols + 1))
        cuts = np.sort(rng.choice(size, size=n, replace=False))  # vertical joints, wrap around
        # Column -> index of the block it belongs to (blocks wrap across the seam).
        k = np.searchsorted(cuts, cols, side="right") % n
        ids[edges[r] : edges[r + 1]] = next_id + k[None, :]
        next_id += n
        d = np.min(np.abs(((cols[:, None] - cuts[None, :]) + size // 2) % size - size // 2), axis=1)
        joint_mask[edges[r] : edges[r + 1], d < joint] = 1.0
        joint_mask[edges[r] : edges[r] + joint, :] = 1.0  # bed joint at the top of each course
    return ids, joint_mask


# --------------------------------------------------------------------------------------
# Materials
# --------------------------------------------------------------------------------------

_STONE = [(0.55, 0.50, 0.42), (0.50, 0.37, 0.24), (0.32, 0.31, 0.30), (0.45, 0.40, 0.31), (0.62, 0.58, 0.52)]
_BRICK = [(0.32, 0.09, 0.05), (0.40, 0.16, 0.08), (0.26, 0.10, 0.06), (0.50, 0.36, 0.18)]
_PLASTER = [(0.70, 0.65, 0.55), (0.78, 0.76, 0.72), (0.66, 0.46, 0.22), (0.70, 0.46, 0.40), (0.55, 0.60, 0.55)]
_PAINT = [(0.10, 0.22, 0.50), (0.12, 0.35, 0.18), (0.55, 0.10, 0.07), (0.72, 0.55, 0.12), (0.20, 0.45, 0.45)]
_DIRT = [(0.20, 0.14, 0.09), (0.26, 0.20, 0.13), (0.15, 0.11, 0.08)]
_GRASS = [(0.07, 0.13, 0.035), (0.10, 0.17, 0.05), (0.12, 0.18, 0.06)]
_ROOF = [(0.42, 0.15, 0.07), (0.35, 0.17, 0.09), (0.10, 0.10, 0.11), (0.14, 0.30, 0.24)]


def stone(rng: Rng, size: int) -> np.ndarray:
    """Ashlar masonry: courses of blocks with per-block tint, darker joints, weathering.

    Tile: :data:`TILE_METRES` ``['stone']`` (8 courses of 0.5 m).
    """
    _check_size(size)
    base = _pick(rng, _STONE, jitter=0.04)
    ids, joints = _blocks(rng, size, rows=8, min_cols=3, max_cols=5, joint=max(1, size // 192))
    block_tint = 1.0 + 0.12 * rng.uniform(-1.0, 1.0, ids.max() + 1)
    f = block_tint[ids]
    f *= 1.0 + 0.10 * fbm(rng, size, period=16, octaves=4)  # grain
    f *= 1.0 + 0.15 * fbm(rng, size, period=2, octaves=3)  # weathering stains
    f *= 1.0 - 0.35 * joints
    return _finish(_tint(base, f))


def brick(rng: Rng, size: int) -> np.ndarray:
    """Running-bond brickwork with mortar lines and per-brick colour variation.

    24 courses x 8 bricks per tile (bricks about 0.25 x 0.08 m at the 2 m tile).
    """
    _check_size(size)
    base = _pick(rng, _BRICK)
    mortar = _pick(rng, [(0.45, 0.43, 0.40), (0.35, 0.34, 0.32), (0.55, 0.52, 0.46)])
    rows, cols = 24, 8
    r = np.minimum((np.arange(size) * rows) // size, rows - 1)
    offset = np.where(r % 2 == 1, size // (2 * cols), 0)  # running bond: odd courses shift half a brick
    c = ((np.arange(size)[None, :] + offset[:, None]) % size * cols) // size
    brick_id = r[:, None] * cols + c
    tint = 1.0 + 0.18 * rng.uniform(-1.0, 1.0, rows * cols)
    f = tint[brick_id] * (1.0 + 0.10 * fbm(rng, size, period=32, octaves=3))
    f *= 1.0 + 0.12 * fbm(rng, size, period=2, octaves=3)
    # Mortar: within ``m`` texels of a course top or a brick's left end.
    m = max(1, size // 128)
    row_pos = (np.arange(size) * rows) % size
    col_pos = ((np.arange(size)[None, :] + offset[:, None]) % size * cols) % size
    mortar_mask = (row_pos[:, None] < m * rows) | (col_pos < m * cols)
    img = _tint(base, f)
    img[mortar_mask] = (mortar[None, :] * (1.0 + 0.05 * fbm(rng, size, 32, 2)[mortar_mask][:, None]))
    return _finish(img)


def plaster(rng: Rng, size: int) -> np.ndarray:
    """Rendered wall: a pale colour with soft low-frequency stains and fine grain."""
    _check_size(size)
    base = _pick(rng, _PLASTER, jitter=0.05)
    f = 1.0 + 0.10 * fbm(rng, size, period=2, octaves=4) + 0.03 * fbm(rng, size, period=64, octaves=2)
    stains = _soft_step(fbm(rng, size, period=3, octaves=4), 0.45, 0.15)
    img = _tint(base, f) * (1.0 - 0.25 * stains[..., None])
    return _finish(img)


def painted(rng: Rng, size: int) -> np.ndarray:
    """Painted plaster with patches where the paint has peeled off to the plaster below."""
    _check_size(size)
    paint = _pick(rng, _PAINT)
    under = plaster(rng, size).astype(np.float64)
    cover = _soft_step(fbm(rng, size, period=4, octaves=5), float(rng.uniform(-0.35, 0.0)), 0.04)
    f = 1.0 + 0.08 * fbm(rng, size, period=8, octaves=3)
    img = cover[..., None] * _tint(paint, f) + (1.0 - cover[..., None]) * under
    return _finish(img)


def dirt(rng: Rng, size: int) -> np.ndarray:
    """Bare soil: brown fBm with lighter pebbles and darker damp patches."""
    _check_size(size)
    base = _pick(rng, _DIRT)
    f = 1.0 + 0.25 * fbm(rng, size, period=4, octaves=6)
    pebbles = _soft_step(value_noise(rng, size, 96), 0.93, 0.02)
    damp = _soft_step(fbm(rng, size, period=4, octaves=3), 0.3, 0.2)
    img = _tint(base, f * (1.0 - 0.3 * damp))
    img = img * (1.0 - pebbles[..., None]) + pebbles[..., None] * np.array([0.42, 0.38, 0.33])
    return _finish(img)


def grass(rng: Rng, size: int) -> np.ndarray:
    """Lawn: green blade noise with dry yellowish and bare-soil patches."""
    _check_size(size)
    base = _pick(rng, _GRASS)
    blades = 1.0 + 0.35 * fbm(rng, size, period=64, octaves=2) + 0.15 * fbm(rng, size, period=8, octaves=3)
    img = _tint(base, blades)
    # Patch lattices of 4-6 cells: coarser ones look axis-aligned and, repeated over a
    # large ground, line up into visible stripes.
    dry = 0.7 * _soft_step(fbm(rng, size, period=4, octaves=4), 0.3, 0.2)[..., None]
    img = img * (1.0 - dry) + dry * _tint(np.array([0.22, 0.21, 0.09]), blades)
    bare = _soft_step(fbm(rng, size, period=6, octaves=3), 0.6, 0.08)[..., None]
    img = img * (1.0 - bare) + bare * dirt(rng, size).astype(np.float64)
    return _finish(img)


def paving(rng: Rng, size: int) -> np.ndarray:
    """Square stone slabs (4 x 4 per tile) with joints and per-slab tint."""
    _check_size(size)
    base = _pick(rng, [(0.40, 0.38, 0.35), (0.50, 0.45, 0.38), (0.28, 0.27, 0.26)])
    n = 4
    idx = (np.arange(size) * n) // size
    slab = idx[:, None] * n + idx[None, :]
    tint = 1.0 + 0.12 * rng.uniform(-1.0, 1.0, n * n)
    f = tint[slab] * (1.0 + 0.12 * fbm(rng, size, period=16, octaves=4))
    f *= 1.0 + 0.15 * fbm(rng, size, period=2, octaves=3)
    pos = (np.arange(size) * n) % size
    j = max(1, size // 128) * n
    joints = (pos[:, None] < j) | (pos[None, :] < j)
    f = np.where(joints, 0.55 * f, f)
    return _finish(_tint(base, f))


def marble(rng: Rng, size: int) -> np.ndarray:
    """White/grey marble with dark veins (turbulent sine bands)."""
    _check_size(size)
    base = _pick(rng, [(0.78, 0.76, 0.72), (0.70, 0.70, 0.70), (0.74, 0.66, 0.60)], jitter=0.04)
    x = np.arange(size)[None, :] / size
    y = np.arange(size)[:, None] / size
    k = int(rng.integers(1, 4))
    phase = 2.0 * np.pi * (k * x + int(rng.integers(1, 3)) * y) + 5.0 * fbm(rng, size, period=4, octaves=5)
    veins = np.abs(np.sin(phase)) ** 0.25  # tileable: integer frequencies in x and y
    f = (0.75 + 0.25 * veins) * (1.0 + 0.04 * fbm(rng, size, period=32, octaves=2))
    return _finish(_tint(base, f))


def roof_tiles(rng: Rng, size: int) -> np.ndarray:
    """Roofing (terracotta, slate or weathered copper): rows of tiles with shading stripes."""
    _check_size(size)
    base = _pick(rng, _ROOF)
    rows = 16
    v = (np.arange(size) * rows / size) % 1.0
    stripes = 0.8 + 0.2 * v  # each course darker at its upper (overlapped) edge
    r = (np.arange(size) * rows) // size
    tint = 1.0 + 0.10 * rng.uniform(-1.0, 1.0, rows * 16)
    c = (np.arange(size)[None, :] * 16 + np.where(r % 2 == 1, size // 2, 0)[:, None]) // size % 16
    f = stripes[:, None] * tint[r[:, None] * 16 + c] * (1.0 + 0.12 * fbm(rng, size, period=2, octaves=4))
    return _finish(_tint(base, f))


def bark(rng: Rng, size: int) -> np.ndarray:
    """Tree bark: dark brown-grey with vertical furrows."""
    _check_size(size)
    base = _pick(rng, [(0.10, 0.075, 0.05), (0.14, 0.12, 0.10), (0.08, 0.06, 0.045)])
    x = np.arange(size)[None, :] / size
    furrows = np.abs(np.sin(2.0 * np.pi * (6 * x) + 2.0 * fbm(rng, size, period=4, octaves=4)))
    f = (0.6 + 0.5 * furrows) * (1.0 + 0.15 * fbm(rng, size, period=16, octaves=3))
    return _finish(_tint(base, f))


def foliage(rng: Rng, size: int) -> np.ndarray:
    """Leaf canopy seen from afar: dark green speckle with lighter clusters."""
    _check_size(size)
    base = _pick(rng, [(0.045, 0.09, 0.025), (0.06, 0.11, 0.035), (0.08, 0.10, 0.03)])
    f = 1.0 + 0.45 * fbm(rng, size, period=32, octaves=3) + 0.25 * fbm(rng, size, period=4, octaves=3)
    return _finish(_tint(base, np.maximum(f, 0.2)))


def bronze(rng: Rng, size: int) -> np.ndarray:
    """Cast bronze with green verdigris patches (statues, domes)."""
    _check_size(size)
    metal = _pick(rng, [(0.35, 0.22, 0.10), (0.28, 0.17, 0.08)])
    patina = _pick(rng, [(0.16, 0.32, 0.24), (0.22, 0.36, 0.28)])
    f = 1.0 + 0.12 * fbm(rng, size, period=8, octaves=4)
    cover = _soft_step(fbm(rng, size, period=3, octaves=5), float(rng.uniform(-0.3, 0.3)), 0.1)[..., None]
    img = (1.0 - cover) * _tint(metal, f) + cover * _tint(patina, f)
    return _finish(img)


def window(rng: Rng, size: int) -> np.ndarray:
    """Window glazing seen from outside: very dark, slightly blue, faint smudges."""
    _check_size(size)
    base = _pick(rng, [(0.04, 0.05, 0.07), (0.05, 0.05, 0.05), (0.06, 0.07, 0.08)], jitter=0.05)
    f = 1.0 + 0.2 * fbm(rng, size, period=4, octaves=3)
    return _finish(_tint(base, f))


TEXTURES: dict[str, TextureFn] = {
    "stone": stone,
    "brick": brick,
    "plaster": plaster,
    "painted": painted,
    "dirt": dirt,
    "grass": grass,
    "paving": paving,
    "marble": marble,
    "roof_tiles": roof_tiles,
    "bark": bark,
    "foliage": foliage,
    "bronze": bronze,
    "window": window,
}

# Metres of surface covered by one repeat of each texture kind (UVs = metres / tile).
TILE_METRES: dict[str, float] = {
    "stone": 4.0,
    "brick": 2.0,
    "plaster": 6.0,
    "painted": 6.0,
    "dirt": 6.0,
    "grass": 6.0,
    "paving": 4.0,
    "marble": 3.0,
    "roof_tiles": 3.0,
    "bark": 1.5,
    "foliage": 3.0,
    "bronze": 2.0,
    "window": 2.0,
}


def random_material_texture(rng: Rng, kind: str, size: int = 256) -> np.ndarray:
    """Texture of the named kind (one of :data:`TEXTURES`), drawn from ``rng``.

    Returns:
        float32 ``(size, size, 3)`` linear-RGB albedo in [0.03, 0.85].

    Raises:
        ValueError: unknown kind or bad size.
    """
    try:
        fn = TEXTURES[kind]
    except KeyError:
        raise ValueError(f"unknown texture kind {kind!r}; choose one of {sorted(TEXTURES)}") from None
    return fn(rng, size)
