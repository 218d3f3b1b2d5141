"""Sensor noise: its level estimated from the photo itself, and an edge-preserving denoise set by it.

Why. Quotient relighting multiplies the photo (:mod:`physrelight.quotient`), so whatever the photo
carries that is not scene radiance comes along: its sensor noise most of all. On a dark photo brought
up by the exposure the noise is multiplied too. Removing it before relighting is physics, not
cosmetics: the relit photo should be the radiance under the new light, and that has no noise.

Noise level (:func:`noise_sigma`). Donoho's estimate: the median absolute value of the finest diagonal
Haar wavelet coefficients, over 0.6745 (the median absolute value of a unit Gaussian). Each coefficient
``(a - b - c + d) / 2`` of a 2 x 2 block is the noise alone on a flat or linearly varying patch, with the
noise's standard deviation; edges and texture occupy few coefficients, so the median ignores them.

Denoise (:func:`denoise`). Each channel is guided-filtered with itself as the guide
(:func:`physrelight.guided_filter.guided_filter`), ridge ``eps = (strength * sigma)^2``: a window whose
variance is well above the noise's (an edge, texture) is kept, a flatter one is averaged. An image
without noise (sigma 0) comes back unchanged.

Shapes: ``image (B, C, H, W)`` linear; sigmas ``(B, C)``.
"""

from __future__ import annotations

import torch

from physrelight.guided_filter import guided_filter

__all__ = ["MAD_TO_SIGMA", "denoise", "noise_sigma"]

MAD_TO_SIGMA = 1.0 / 0.6745
"""The median absolute value of a zero-mean Gaussian is 0.6745 of its standard deviation."""


def _check(image: torch.Tensor) -> None:
    if not isinstance(image, torch.Tensor) or image.ndim != 4:
        got = tuple(image.shape) if isinstance(image, torch.Tensor) else type(image).__name__
        raise ValueError(f"image must be a tensor of shape (B, C, H, W), got {got}")
    if image.shape[-2] < 2 or image.shape[-1] < 2:
        raise ValueError(f"image must be at least 2 x 2 pixels to estimate its noise, got {tuple(image.shape)}")
    if not bool(torch.isfinite(image).all()):
        raise ValueError("image holds NaN or inf")


def noise_sigma(image: torch.Tensor) -> torch.Tensor:
    """``(B, C)`` the standard deviation of additive white noise in each channel of ``image (B, C, H, W)``.

    Donoho's robust estimate on the finest diagonal Haar coefficients (the module doc). An odd last row
    or column is left out. Raises ``ValueError`` for a bad shape, fewer than 2 x 2 pixels or non-finite
    values.
    """
    _check(image)
    h, w = (image.shape[-2] // 2) * 2, (image.shape[-1] // 2) * 2
    x = image[..., :h, :w]
    hh = (x[..., 0::2, 0::2] - x[..., 0::2, 1::2] - x[..., 1::2, 0::2] + x[..., 1::2, 1::2]) / 2.0
    return hh.abs().flatten(2).median(-1).values * MAD_TO_SIGMA


def denoise(image: torch.Tensor, radius: int = 1, strength: float = 2.0,
            sigma: torch.Tensor | None = None) -> torch.Tensor:
    """``(B, C, H, W)`` ``image`` with its noise averaged out where the image is flat at the noise's scale.

    Args:
        image: ``(B, C, H, W)`` linear values.
        radius: the guided filter's window radius in pixels, >= 1.
        strength: the ridge in units of the noise: ``eps = (strength * sigma)^2`` per channel, > 0.
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
        sigma = noise_sigma(image)
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
