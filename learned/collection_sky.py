"""The sky of a photo collection's photos that come without a mask: the shipped sky segmenter's.

Kept apart from :mod:`learned.data` (which :mod:`learned.sky_segmentation` imports): training opens
its data with :func:`segmenter_sky_fn` as the collection's ``sky_fn``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import torch

from physrelight import colour
from physrelight.sky_mask import GROW_REACH

from .lighting import WEIGHTS_DIR
from .sky_segmentation import load_sky_segmenter, sky_mask_full_resolution

__all__ = ["segmenter_sky_fn"]


def segmenter_sky_fn(weights: str | Path | None = None) -> Callable[[np.ndarray], np.ndarray] | None:
    """``photo (H, W, 3) display values -> sky (H, W) bool`` by the shipped sky segmenter, as ``physrelight
    relight`` makes its mask (:meth:`learned.relighter.Relighter.photo_sky`: the plausible sky at full
    resolution, grown by sky colour); None when no segmenter weights are shipped."""
    path = Path(weights) if weights is not None else WEIGHTS_DIR / "sky_segmentation.safetensors"
    if not path.is_file():
        return None
    model = load_sky_segmenter(path)

    def sky_fn(photo: np.ndarray) -> np.ndarray:
        lin = _to_chw(colour.from_ldr(np.clip(photo, 0.0, 1.0)))[None]
        with torch.no_grad():
            sky, _ = sky_mask_full_resolution(model, lin, grow=GROW_REACH)
        return sky[0, 0].numpy()

    return sky_fn


def _to_chw(image: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)).permute(2, 0, 1).contiguous()
