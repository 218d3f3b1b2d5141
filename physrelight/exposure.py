"""The exposure of a relit photo: keep the camera's settings, or meter it as a camera would.

A relit photo is linear radiance in the source photo's linear units. How it is shown is a
camera setting, chosen here by one of :data:`MODES`:

``keep``
    the same camera settings as the source photo: the relit radiance as it is (gain 1); a
    brighter target lighting gives a brighter picture and may clip.
``auto``
    meter the relit image as a camera does: one gain that brings the log-average luminance
    of its foreground to the source photo's foreground key, or to middle grey (0.18) when the
    source is dark (key below :data:`DARK_KEY`, a photo a camera would not have metered so);
    then, as a photographer protects highlights, lowered where it would clip the sky: the
    sky's 99th percentile of luminance stays at or below white (the sun's disc, under 1 % of a
    sky, may clip).
``EV`` (a number)
    ``keep`` plus ``EV`` stops.

The sky always takes the foreground's gain: one picture, one exposure.

Shapes: linear images ``(B, 3, H, W)``, masks ``(B, 1, H, W)`` bool (True = counted).
"""

from __future__ import annotations

import math

import torch

from physrelight import colour
from physrelight.stats import quantile

__all__ = ["DARK_KEY", "MIDDLE_GREY", "MODES", "dc_luminance", "exposure_gain", "exposure_scale", "log_average",
           "match_exposure", "parse_exposure"]

MIDDLE_GREY = 0.18
DARK_KEY = 0.045
"""Two stops under middle grey: a source whose foreground key is below this is a dark photo."""
MODES = ("auto", "keep")


def parse_exposure(value: str | float) -> str | float:
    """``"auto"``, ``"keep"`` or a finite number of stops (``"+1.5"``, ``-2``); anything else is a ``ValueError``."""
    if isinstance(value, str) and value.strip().lower() in MODES:
        return value.strip().lower()
    try:
        ev = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"exposure must be auto, keep or a number of stops, got {value!r}") from None
    if not math.isfinite(ev) or abs(ev) > 24:
        raise ValueError(f"exposure must be a finite number of stops within +-24, got {value!r}")
    return ev


def log_average(image: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """``(B,)`` log-average Rec. 709 luminance of linear ``image (B, 3, H, W)`` over ``mask``
    (``(B, 1, H, W)`` bool; None = every pixel), luminance floored at 1e-6; where the mask is
    empty, over every pixel."""
    if image.ndim != 4 or image.shape[1] != 3:
        raise ValueError(f"image must have shape (B, 3, H, W), got {tuple(image.shape)}")
    y = (image.clamp_min(0) * image.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1, keepdim=True)
    logy = torch.log(y.clamp_min(1e-6))
    if mask is None:
        return torch.exp(logy.mean((1, 2, 3)))
    if mask.shape != y.shape:
        raise ValueError(f"mask must have shape {tuple(y.shape)}, got {tuple(mask.shape)}")
    m = mask.to(logy.dtype)
    count = m.sum((1, 2, 3))
    masked = (logy * m).sum((1, 2, 3)) / count.clamp_min(1)
    return torch.exp(torch.where(count > 0, masked, logy.mean((1, 2, 3))))


def exposure_gain(mode: str | float, relit: torch.Tensor, source: torch.Tensor,
                  foreground: torch.Tensor | None = None, highlights: torch.Tensor | None = None) -> torch.Tensor:
    """``(B,)`` the gain the relit image is shown with.

    Args:
        mode: ``"auto"``, ``"keep"`` or stops (:func:`parse_exposure`).
        relit: ``(B, 3, H, W)`` linear relit photo (source photo's units).
        source: ``(B, 3, H, W)`` the linear source photo.
        foreground: ``(B, 1, H, W)`` bool, the pixels metered (None: all).
        highlights: ``(B, 1, H, W)`` bool, pixels ``auto`` must not clip (the sky; None: none).

    Returns:
        ``auto``: ``key / log_average(relit over the foreground)`` with ``key`` the source's
        foreground log average, or :data:`MIDDLE_GREY` when that is below :data:`DARK_KEY`, at
        most ``1 / q99(luminance over highlights)``; ``keep``: 1; stops: ``2**EV``. Limited to
        ``2**+-16`` so a black relighting stays finite.
    """
    mode = parse_exposure(mode)
    ones = relit.new_ones(relit.shape[0])
    if mode == "keep":
        return ones
    if not isinstance(mode, str):
        return ones * 2.0**mode
    key = log_average(source, foreground)
    key = torch.where(key < DARK_KEY, torch.full_like(key, MIDDLE_GREY), key)
    gain = key / log_average(relit, foreground)
    if highlights is not None:
        y = (relit.clamp_min(0) * relit.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1, keepdim=True)
        for b in range(relit.shape[0]):
            if bool(highlights[b].any()):
                gain[b] = torch.minimum(gain[b], 1.0 / quantile(y[b][highlights[b]].float(), 0.99).clamp_min(1e-12))
    return gain.clamp(2.0**-16, 2.0**16)


def dc_luminance(lighting: torch.Tensor) -> torch.Tensor:
    """``(B, 9, 3)`` radiance SH -> ``(B,)`` luminance of the DC term (the lighting's overall level)."""
    lum = torch.tensor(colour.LUMINANCE, dtype=lighting.dtype)
    return (lighting[:, 0] * lum).sum(-1)


def exposure_scale(target: torch.Tensor, estimated_source: torch.Tensor, given_source: torch.Tensor | None = None,
                   fallback: torch.Tensor | None = None) -> torch.Tensor:
    """``(B,)`` the factor that brings ``target (B, 9, 3)`` into a decomposition's units.

    The decomposition's albedo and lighting share an unknown scale. With ``given_source``
    ``(B, 9, 3)`` (the source lighting in the target's units) it is
    ``lum(DC estimated) / lum(DC given)``; without it, ``lum(DC estimated) / lum(DC target)``,
    so the scaled target's DC luminance equals the estimated source lighting's (the photo keeps
    its exposure). Where the estimate has no positive level (below 1e-6 of ``fallback``'s, e.g. a
    photo without usable foreground), ``fallback`` ``(1 or B, 9, 3)`` (the prior's mean) stands in.

    Raises:
        ValueError: the target (or the given source) has no positive DC luminance.
    """
    ref = dc_luminance(given_source.to(target.dtype) if given_source is not None else target)
    if bool((ref <= 0).any()) or bool((dc_luminance(target) <= 0).any()):
        raise ValueError("target (or source) lighting has no positive DC luminance (a dark or invalid lighting)")
    est = dc_luminance(estimated_source.to(target.dtype))
    if fallback is not None:
        fb = dc_luminance(fallback.to(target.dtype)).expand_as(est)
        est = torch.where(est > 1e-6 * fb, est, fb)
    return est.clamp_min(0) / ref


def match_exposure(target: torch.Tensor, estimated_source: torch.Tensor, given_source: torch.Tensor | None = None,
                   fallback: torch.Tensor | None = None) -> torch.Tensor:
    """``target (B, 9, 3)`` times :func:`exposure_scale`: the target in a decomposition's units."""
    return target * exposure_scale(target, estimated_source, given_source, fallback)[:, None, None]
