"""Sensor noise: its level estimated from the photo itself, and an edge-preserving denoise set by it.

Why. Quotient relighting multiplies the photo (:mod:`physrelight.quotient`), so whatever the photo
carries that is not scene radiance comes along: its sensor noise most of all. On a dark photo brought
up by the exposure the noise is multiplied too. Removing it before relighting is physics, not
cosmetics: the relit photo should be the radiance under the new light, and that has no noise. But a
photo's fine texture and its noise are hard to tell apart, so the relighting uses this only when asked
(``Relighter.denoise``, ``relight --denoise``; study 37 measured it smoothing real foliage).

Noise level (:func:`noise_sigma`). Donoho's estimate: the median absolute value of the finest diagonal
Haar wavelet coefficients, over 0.6745 (the median absolute value of a unit Gaussian). Each coefficient
``(a - b - c + d) / 2`` of a 2 x 2 block is the noise alone on a flat or linearly varying patch, with the
noise's standard deviation. Over a whole photo (``block=None``) that assumes edges and texture occupy
few coefficients, which foliage breaks: it fills the finest coefficients, and the estimate reads it as noise
(study 37: up to 10 times the noise on real forest views). The *noise floor* (``block`` pixels) takes
Donoho's estimate in each ``block x block`` tile instead and returns a low quantile of them: a photo has
some flat tiles (sky, road, a wall) where the estimate is the noise alone, and texture only raises the
others. Tiles with clipped pixels (0, or 0.98 and above) are left out, since clipping removes the noise
there; the quantile of tile estimates of pure noise sits below the noise by a known factor (the median of
``n`` absolute Gaussians has a standard deviation of ``1.166 sigma / sqrt(n)`` after the 1 / 0.6745 scaling),
which is divided out.

Denoise (:func:`denoise`). Each channel is guided-filtered with itself as the guide
(:func:`physrelight.guided_filter.guided_filter`), ridge ``eps = (strength * sigma)^2``: a window whose
variance is well above the noise's (an edge, texture) is kept, a flatter one is averaged. An image
without noise (sigma 0) comes back unchanged.

Shapes: ``image (B, C, H, W)`` linear; sigmas ``(B, C)``.
"""

from __future__ import annotations

import torch

from physrelight.guided_filter import guided_filter

__all__ = ["CLIP_HIGH", "FLOOR_BLOCK", "FLOOR_QUANTILE", "MAD_TO_SIGMA", "denoise", "noise_sigma"]

MAD_TO_SIGMA = 1.0 / 0.6745
"""The median absolute value of a zero-mean Gaussian is 0.6745 of its standard deviation."""
FLOOR_BLOCK = 16
"""The tile (pixels) of :func:`noise_sigma`'s noise floor: 64 wavelet coefficients each."""
FLOOR_QUANTILE = 0.1
"""The quantile of the tiles' estimates that :func:`noise_sigma`'s noise floor takes."""
CLIP_HIGH = 0.98
"""A tile with a value at or above this (linear, a photo's white) is clipped: the noise floor leaves it out."""
_MEDIAN_SD = 1.166  # sd of Donoho's estimate from n coefficients of pure noise, times sqrt(n) / sigma


def _check(image: torch.Tensor) -> None:
    if not isinstance(image, torch.Tensor) or image.ndim != 4:
        got = tuple(image.shape) if isinstance(image, torch.Tensor) else type(image).__name__
        raise ValueError(f"image must be a tensor of shape (B, C, H, W), got {got}")
    if image.shape[-2] < 2 or image.shape[-1] < 2:
        raise ValueError(f"image must be at least 2 x 2 pixels to estimate its noise, got {tuple(image.shape)}")
    if not bool(torch.isfinite(image).all()):
        raise ValueError("image holds NaN or inf")


def noise_sigma(image: torch.Tensor, block: int | None = FLOOR_BLOCK, quantile: float = FLOOR_QUANTILE) -> torch.Tensor:
    """``(B, C)`` the standard deviation of additive white noise in each channel of ``image (B, C, H, W)``.

    Donoho's robust estimate on the finest diagonal Haar coefficients (the module doc): over the whole image
    with ``block=None``; else the noise floor, the ``quantile`` of the estimates of the ``block x block``
    tiles without clipped pixels, divided by that quantile's expected shortfall under pure noise (all tiles
    when every one is clipped; the whole image when it is smaller than one tile). An odd last row or column
    is left out. Raises ``ValueError`` for a bad shape, fewer than 2 x 2 pixels, non-finite values, a block
    that is not an even integer >= 4 or a quantile outside (0, 1).
    """
    _check(image)
    if block is not None and (isinstance(block, bool) or not isinstance(block, int) or block < 4 or block % 2):
        raise ValueError(f"block must be an even integer >= 4 or None, got {block!r}")
    if not (isinstance(quantile, (int, float)) and 0.0 < float(quantile) < 1.0):
        raise ValueError(f"quantile must lie in (0, 1), got {quantile!r}")
    h, w = (image.shape[-2] // 2) * 2, (image.shape[-1] // 2) * 2
    x = image[..., :h, :w]
    hh = ((x[..., 0::2, 0::2] - x[..., 0::2, 1::2] - x[..., 1::2, 0::2] + x[..., 1::2, 1::2]) / 2.0).abs()
    if block is None or h < block or w < block:
        return hh.flatten(2).median(-1).values * MAD_TO_SIGMA
    k = block // 2  # coefficients per tile side
    th, tw = hh.shape[-2] // k, hh.shape[-1] // k
    b, c = hh.shape[:2]
    tiles = hh[..., : th * k, : tw * k].reshape(b, c, th, k, tw, k).permute(0, 1, 2, 4, 3, 5).reshape(b, c, th * tw, k * k)
    est = tiles.median(-1).values * MAD_TO_SIGMA  # (B, C, T)
    px = x[..., : th * block, : tw * block]
    clipped = ((px >= CLIP_HIGH) | (px <= 0.0)).any(1, keepdim=True).float()  # any channel
    clipped = torch.nn.functional.max_pool2d(clipped, block).flatten(2).expand(b, c, -1) > 0.5  # (B, C, T)
    z = float(torch.distributions.Normal(0.0, 1.0).icdf(torch.tensor(float(quantile))))
    shortfall = 1.0 + z * _MEDIAN_SD / k  # the quantile of pure-noise tile estimates, over sigma
    out = torch.empty(b, c, dtype=image.dtype)
    for i in range(b):
        for j in range(c):
            keep = est[i, j][~clipped[i, j]]
            vals = keep if keep.numel() else est[i, j]
            out[i, j] = torch.quantile(vals.double(), float(quantile)).to(image.dtype) / shortfall
    return out


def denoise(image: torch.Tensor, radius: int = 1, strength: float = 2.0, block: int | None = FLOOR_BLOCK, *,
            sigma: torch.Tensor | None = None) -> torch.Tensor:
    """``(B, C, H, W)`` ``image`` with its noise averaged out where the image is flat at the noise's scale.

    Args:
        image: ``(B, C, H, W)`` linear values.
        radius: the guided filter's window radius in pixels, >= 1.
        strength: the ridge in units of the noise: ``eps = (strength * sigma)^2`` per channel, > 0.
        block: :func:`noise_sigma`'s tile when it estimates the noise (None: the whole image, round 1 of
            study 37).
        sigma: ``(B, C)`` the noise's standard deviation; None: :func:`noise_sigma` of ``image``.

    Returns:
        ``(B, C, H, W)``; channels whose sigma is 0 come back unchanged.

    Raises:
        ValueError: a bad shape, a non-positive radius or strength, or a sigma of the wrong shape or sign.
    """
    _check(image)
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 1:
        raise ValueError(f"radius must be an integer >= 1, got {radius!r}")
    if not (isinstance(strength, (int, float)) and strength > 0):
        raise ValueError(f"strength must be a number > 0, got {strength!r}")
    b, c = image.shape[:2]
    if sigma is None:
        sigma = noise_sigma(image, block)
    sigma = torch.as_tensor(sigma, dtype=image.dtype)
    if sigma.shape != (b, c) or bool((sigma < 0).any()) or not bool(torch.isfinite(sigma).all()):
        raise ValueError(f"sigma must be ({b}, {c}) finite values >= 0, got {tuple(sigma.shape)}")
    out = image.clone()
    for i in range(b):
        for j in range(c):
            s = float(sigma[i, j])
            if s > 0:
                ch = image[i: i + 1, j: j + 1]
                out[i: i + 1, j: j + 1] = guided_filter(ch, ch, radius, (strength * s) ** 2)
    return out
