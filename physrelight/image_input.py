"""A photo at the door: the array a user passes in -> the ``(B, 3, H, W)`` linear tensor the library computes on,
and back to the layout it came in.

A photo is numpy ``(H, W, 3)`` (uint8, or float display values in [0, 1]) or torch ``(3, H, W)`` /
``(B, 3, H, W)`` float display values, linearised with the sRGB curve (:func:`as_image`); or linear radiance of
any scale (:func:`as_radiance`). Results go back as the type given (:func:`give_back`): numpy ``(H, W, C)`` or
torch ``(B, C, H, W)`` (``(C, H, W)`` for an unbatched torch image). Sky masks (:func:`as_mask`) and a camera's
rotation (:func:`as_rotation`) are checked here too.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from physrelight import colour
from physrelight.stats import quantile

__all__ = ["RADIANCE_WHITE_QUANTILE", "as_batch", "as_image", "as_mask", "as_radiance", "as_rotation", "give_back"]

RADIANCE_WHITE_QUANTILE = 0.999
"""A radiance photo (``radiance=True``) is brought to a display-like range first: its luminance at this quantile
to 1, as a camera exposed not to clip more than a thousandth of the frame (unchanged when that is already at or
below 1). The networks, the sky mask's tests and the display curve all expect a photo's range."""


def as_batch(image: Any) -> tuple[torch.Tensor, str]:
    """A photo's array -> ``(B, 3, H, W)`` as it is (no conversion) and how to give results back ("numpy", "chw",
    "bchw"): the layouts and the least size (8 x 8) both kinds of photo take."""
    if isinstance(image, np.ndarray):
        if image.ndim != 3 or image.shape[-1] != 3:
            raise ValueError(f"a numpy image must have shape (H, W, 3), got {image.shape}")
        t = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None]
        kind = "numpy"
    elif isinstance(image, torch.Tensor):
        if image.ndim == 3:
            t, kind = image[None], "chw"
        elif image.ndim == 4:
            t, kind = image, "bchw"
        else:
            raise ValueError(f"a torch image must have shape (3, H, W) or (B, 3, H, W), got {tuple(image.shape)}")
        if t.shape[1] != 3:
            raise ValueError(f"a torch image must have 3 channels, got shape {tuple(image.shape)}")
    else:
        raise ValueError(f"image must be a numpy array or torch tensor, got {type(image).__name__}")
    if t.shape[-1] < 8 or t.shape[-2] < 8:
        raise ValueError(f"image must be at least 8x8 pixels, got {tuple(t.shape[-2:])}")
    return t, kind


def as_image(image: Any) -> tuple[torch.Tensor, str]:
    """Photo (display values) -> ``(B, 3, H, W)`` linear float32 and how to give results back (:func:`as_batch`)."""
    t, kind = as_batch(image)
    if t.dtype in (torch.uint8,):
        t = t.float() / 255.0
    elif not t.is_floating_point():
        raise ValueError(f"image must be uint8 or float display values in [0, 1], got dtype {t.dtype}")
    lin = colour.from_ldr(t.detach().float().cpu())  # raises on NaN or values outside [0, 1]
    return lin, kind


def as_radiance(image: Any) -> tuple[torch.Tensor, str, float]:
    """A linear radiance photo -> ``(B, 3, H, W)`` float32 in a display-like range, how to give results back, and
    the gain that brought it there (:data:`RADIANCE_WHITE_QUANTILE`; the photo's units are ``result / gain``)."""
    t, kind = as_batch(image)
    if not t.is_floating_point():
        raise ValueError(f"a radiance photo must hold floats, got dtype {t.dtype}")
    t = t.detach().float().cpu()
    if not bool(torch.isfinite(t).all()):
        raise ValueError("a radiance photo must be finite (it holds NaN or inf)")
    if bool((t < 0).any()):
        raise ValueError(f"a radiance photo must be non-negative, min {float(t.min()):.4g}")
    lum = (t * t.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1)
    white = float(quantile(lum, RADIANCE_WHITE_QUANTILE))
    if white <= 0.0:
        raise ValueError("a radiance photo must not be black")
    gain = 1.0 / white if white > 1.0 else 1.0
    return t * gain, kind, gain


def give_back(x: torch.Tensor, kind: str) -> Any:
    """``x (B, C, H, W)`` in the layout ``kind`` of :func:`as_batch`: numpy ``(H, W, C)`` (first image),
    torch ``(C, H, W)`` (first image) or ``(B, C, H, W)`` itself."""
    if kind == "numpy":
        return x[0].permute(1, 2, 0).numpy()
    return x[0] if kind == "chw" else x


def as_mask(mask: Any, like: torch.Tensor) -> torch.Tensor:
    """A sky mask ``(H, W)``, ``(B, H, W)``, ``(1, H, W)`` or ``(B, 1, H, W)`` (bool, or numbers: above 0.5 is
    True) for ``like (B, C, H, W)`` -> ``(B, 1, H, W)`` bool; None -> all False (no sky)."""
    b, _, h, w = like.shape
    if mask is None:
        return torch.zeros(b, 1, h, w, dtype=torch.bool)
    m = torch.as_tensor(np.asarray(mask) if not isinstance(mask, torch.Tensor) else mask)
    if m.ndim == 2:
        m = m[None, None]
    elif m.ndim == 3:
        m = m[:, None] if m.shape[0] == b and m.shape[1:] == (h, w) else m[None]
    if m.shape != (b, 1, h, w):
        raise ValueError(f"sky_mask must have shape (H, W) = ({h}, {w}) or (B, 1, H, W), got {tuple(m.shape)}")
    return m.bool() if m.dtype == torch.bool else m > 0.5


def as_rotation(world_to_camera: Any) -> torch.Tensor:
    """``(3, 3)`` float64 the rotation block of ``world_to_camera`` (``(4, 4)`` or ``(3, 3)``, numpy or torch),
    checked proper (orthonormal within 1e-4, determinant +1); None -> identity (camera frame = world frame)."""
    if world_to_camera is None:
        return torch.eye(3, dtype=torch.float64)
    r = torch.as_tensor(np.asarray(world_to_camera, dtype=np.float64) if not isinstance(world_to_camera, torch.Tensor)
                        else world_to_camera.double())
    if r.shape == (4, 4):
        r = r[:3, :3]
    if r.shape != (3, 3):
        raise ValueError(f"world_to_camera must have shape (4, 4) or (3, 3), got {tuple(r.shape)}")
    if not torch.allclose(r @ r.T, torch.eye(3, dtype=torch.float64), atol=1e-4) or float(torch.det(r)) <= 0:
        raise ValueError("world_to_camera's rotation block must be a proper rotation")
    return r
