"""Linear image filters: the separable Gaussian blur.

One Gaussian serves the library: the camera's softening in the segmenter's augmentations
(``learned.sky_segmentation.photometric_augment``), SkyGAN's smoothed sky (``learned.sky_gan.smooth_sky``) and
SSIM's window (:mod:`physrelight.metrics`). The box filter is :func:`physrelight.guided_filter.box_filter`.

Shapes: ``x (B, C, H, W)``; every channel is filtered alone.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

__all__ = ["BORDERS", "gaussian_blur", "gaussian_kernel1d"]

BORDERS = ("replicate", "valid")
"""How :func:`gaussian_blur` treats the border: ``"replicate"`` extends the edge pixels (same size out);
``"valid"`` keeps only the pixels whose whole window lies inside (``2 radius`` fewer rows and columns)."""


def _check_sigma_radius(sigma: float, radius: int | None) -> int:
    """The radius to use (``max(1, int(3 sigma))`` when None), or a ValueError naming the bad argument."""
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or not (math.isfinite(sigma) and sigma > 0):
        raise ValueError(f"sigma must be a positive number of pixels, got {sigma!r}")
    if radius is None:
        return max(1, int(3 * sigma))
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 0:
        raise ValueError(f"radius must be an integer >= 0, got {radius!r}")
    return radius


def gaussian_kernel1d(sigma: float, radius: int | None = None, dtype: torch.dtype = torch.float64,
                      device: torch.device | str | None = None) -> torch.Tensor:
    """The normalised sampled Gaussian ``exp(-t^2 / (2 sigma^2))`` at ``t = -radius ... radius``: ``(2 radius + 1,)``.

    Args:
        sigma: standard deviation in pixels, > 0.
        radius: taps on each side; None: ``max(1, int(3 sigma))``.
        dtype, device: of the result; the taps are computed in ``dtype`` on the CPU, then moved.
    """
    r = _check_sigma_radius(sigma, radius)
    t = torch.arange(-r, r + 1, dtype=dtype)
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    return (k / k.sum()).to(device)


def gaussian_blur(x: torch.Tensor, sigma: float, radius: int | None = None, border: str = "replicate") -> torch.Tensor:
    """Separable Gaussian blur of ``x (B, C, H, W)``: a pass along each row, then one along each column.

    Args:
        x: ``(B, C, H, W)`` float.
        sigma: standard deviation in pixels, > 0.
        radius: the window's half-width; None: ``max(1, int(3 sigma))`` (:func:`gaussian_kernel1d`).
        border: ``"replicate"`` (``(B, C, H, W)`` out) or ``"valid"`` (``(B, C, H - 2 radius, W - 2 radius)``
            out; the image must be at least ``2 radius + 1`` on each side).

    Returns:
        The blurred ``x``, its dtype and device.
    """
    if not isinstance(x, torch.Tensor) or x.ndim != 4 or not x.is_floating_point():
        got = f"{x.dtype} {tuple(x.shape)}" if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"x must be a float tensor of shape (B, C, H, W), got {got}")
    if border not in BORDERS:
        raise ValueError(f"border must be one of {BORDERS}, got {border!r}")
    r = _check_sigma_radius(sigma, radius)
    if border == "valid" and min(x.shape[-2:]) < 2 * r + 1:
        raise ValueError(f"a valid blur of radius {r} needs at least {2 * r + 1} x {2 * r + 1} pixels, "
                         f"got {tuple(x.shape[-2:])}")
    k = gaussian_kernel1d(sigma, r, x.dtype, x.device)
    c, n = x.shape[1], 2 * r + 1
    if border == "replicate":
        x = F.pad(x, (r, r, 0, 0), mode="replicate")
    x = F.conv2d(x, k.view(1, 1, 1, n).expand(c, 1, 1, n), groups=c)
    if border == "replicate":
        x = F.pad(x, (0, 0, r, r), mode="replicate")
    return F.conv2d(x, k.view(1, 1, n, 1).expand(c, 1, n, 1), groups=c)
