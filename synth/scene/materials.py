"""Material slots: which textures each slot draws from, the palette that draws one diffuse material per slot,
and the swap to a glossy material."""

from __future__ import annotations

import numpy as np

from .. import textures as tx
from .description import Material


# --------------------------------------------------------------------------------------
# Material slots and the palette
# --------------------------------------------------------------------------------------

Rng = np.random.Generator

_SLOT_KINDS: dict[str, tuple[str, ...]] = {
    "walls": ("brick", "plaster", "painted", "stone"),
    "trim": ("stone", "marble", "plaster"),
    "roof": ("roof_tiles", "roof_tiles", "bronze", "stone"),
    "window": ("window",),
    "masonry": ("stone", "stone", "brick", "marble"),
    "marble": ("marble", "stone"),
    "statue": ("bronze", "marble", "stone"),
    "paving": ("paving", "stone", "marble"),
    "ground": ("grass", "grass", "dirt", "paving"),
    "bark": ("bark",),
    "foliage": ("foliage",),
}


class _Palette:
    """Lazily draws one diffuse material per slot name from the texture generator."""

    def __init__(self, rng: Rng, size: int) -> None:
        self.rng, self.size = rng, size
        self.mats: dict[str, Material] = {}

    def get(self, slot: str, kinds: tuple[str, ...] | None = None) -> Material:
        if slot not in self.mats:
            kinds = kinds or _SLOT_KINDS[slot]
            kind = kinds[int(self.rng.integers(len(kinds)))]
            # The ground fills much of every view: twice the texels over twice the tile
            # (same texel density) halves how often its pattern visibly repeats.
            scale = 2 if slot == "ground" else 1
            tex = tx.random_material_texture(self.rng, kind, scale * self.size)
            self.mats[slot] = Material("diffuse", tex, 0.0, kind, scale * tx.TILE_METRES[kind], slot)
        return self.mats[slot]


def _glossy(material: Material, u: float, alpha: float, fraction: float) -> Material:
    """Swap a diffuse material for rough plastic (or rough metal for bronze) when ``u < fraction``."""
    if u >= fraction:
        return material
    kind = "roughconductor" if material.texture_kind == "bronze" else "roughplastic"
    return Material(kind, material.texture, alpha, material.texture_kind, material.tile_m, material.name)
