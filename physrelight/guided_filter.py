"""Edge-aware smoothing and upsampling with the guided filter (He, Sun, Tang, ECCV 2010 / TPAMI 2013).

The output is locally an affine function of a *guide* image, ``q = a I + b``, fitted to the
input ``p`` over each ``(2r+1)^2`` window with ridge ``eps``: where the guide has an edge the
output has it too, and where the guide is flat the output is a box-smoothed ``p``. Used to bring
working-resolution quantities (a relighting ratio, a sky probability) to a photo's full
resolution so that they follow its edges instead of the working grid (no blocky band, no halo).

Shapes: ``guide (B, 1, H, W)`` (a grey guide; luminance or log luminance of a photo),
``src (B, C, H, W)``; every channel of ``src`` is filtered with the one guide.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from physrelight.window_sums import box_mean

__all__ = ["box_filter", "guided_filter", "guided_upsample"]


def _check(guide: torch.Tensor, src: torch.Tensor, radius: int, eps: float) -> None:
    for name, x in (("guide", guide), ("src", src)):
        if not isinstance(x, torch.Tensor) or x.ndim != 4:
            got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
            raise ValueError(f"{name} must be a (B, C, H, W) tensor, got {got}")
    if guide.shape[1] != 1:
        raise ValueError(f"guide must have one channel, got shape {tuple(guide.shape)}")
    if guide.shape[0] != src.shape[0] or guide.shape[-2:] != src.shape[-2:]:
        raise ValueError(f"guide {tuple(guide.shape)} and src {tuple(src.shape)} must share batch and size")
    if isinstance(radius, bool) or not isinstance(radius, int) or radius < 1:
        raise ValueError(f"radius must be a positive integer, got {radius!r}")
    if not (math.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a positive number, got {eps!r}")


def _window_sums(x: torch.Tensor, radius: int, dim: int) -> torch.Tensor:
    """Sums of ``x`` over ``[i - r, i + r]`` along ``dim``, the window cut at the ends (cumulative sums: O(1) per pixel).
    The summed-area path off the CPU (and the arithmetic :mod:`physrelight.window_sums` compiles for it)."""
    n = x.shape[dim]
    c = torch.cumsum(x, dim=dim)  # c[k] = x[0] + ... + x[k], accumulated in float64 for float32 and float64
    r = min(radius, n)
    # sum = c[min(i + r, n - 1)] - c[i - r - 1] (0 for i <= r), written in place into one output by slicing: no
    # padded copy of c and no concatenation (twice as fast on a 12-megapixel image as building both ends by cat)
    out = torch.empty_like(c)
    if n - r > 0:
        out.narrow(dim, 0, n - r).copy_(c.narrow(dim, r, n - r))
    tail = out.narrow(dim, n - r, r)
    tail.copy_(c.narrow(dim, n - 1, 1).expand_as(tail))
    if n - r - 1 > 0:
        out.narrow(dim, r + 1, n - r - 1).sub_(c.narrow(dim, 0, n - r - 1))
    return out


_POOL_MAX_RADIUS = 16
"""Up to this radius :func:`box_filter` averages directly (two separable pools), beyond it by summed-area tables."""


def _window_count(h: int, w: int, radius: int, dtype: torch.dtype, device: torch.device | str = "cpu") -> torch.Tensor:
    """The pixel counts of the ``(2r+1)^2`` windows (cut at the border) of an ``h x w`` image, the very numbers in
    ``dtype`` that the summed-area path of :func:`box_filter` gets by filtering ones: ``(1, 1, h, w)``.

    Along the columns the ones sum to exact integers ``n_i``; along the rows their running sums ``(j + 1) * n_i`` are
    rounded to ``dtype`` (in float32 past ``2**24``: a row of 15000 pixels at radius 600) before the window's two ends
    are subtracted, as the filter does, so the counts are computed here the same way, without two passes of
    summed-area tables over a plane of ones (a third of a guided filter's box sums)."""
    rh, rw = min(radius, h), min(radius, w)
    i = torch.arange(h, dtype=torch.float64, device=device)[:, None]
    j = torch.arange(w, dtype=torch.float64, device=device)[None, :]
    n_i = torch.minimum(i + rh, torch.full_like(i, h - 1)) - torch.maximum(i - rh - 1, torch.full_like(i, -1.0))
    if w * float(n_i.max()) <= 2.0 ** (24 if dtype == torch.float32 else 53):
        # no running sum is rounded: the counts are the exact products of the column and row counts
        m_j = torch.minimum(j + rw, torch.full_like(j, w - 1)) - torch.maximum(j - rw - 1, torch.full_like(j, -1.0))
        return (n_i.to(dtype) * m_j.to(dtype))[None, None]
    hi = torch.minimum(j + rw, torch.full_like(j, w - 1))
    lo = j - rw - 1  # the running sum before the window; none (0) at the left border
    before = torch.where(lo >= 0, (lo + 1) * n_i, torch.zeros(()))
    return (((hi + 1) * n_i).to(dtype) - before.to(dtype))[None, None]


def box_filter(x: torch.Tensor, radius: int) -> torch.Tensor:
    """Mean of ``x (B, C, H, W)`` over the ``(2r+1)^2`` window of each pixel, the window cut at the
    border (the mean of the pixels inside the image, not of zero padding). Small radii average
    directly, a row pass then a column pass (the count of a window cut at the border factorises, so
    the separable mean is exact); wide ones use summed-area tables, whose cost does not grow with
    ``radius`` (at small radii slower: 1.0 s against 0.7 s for three channels of a 12-megapixel image at
    radius 2, one thread, 2-core AMD EPYC)."""
    if radius <= _POOL_MAX_RADIUS:
        k = 2 * radius + 1
        rows = F.avg_pool2d(x, (1, k), stride=1, padding=(0, radius), count_include_pad=False)
        return F.avg_pool2d(rows, (k, 1), stride=1, padding=(radius, 0), count_include_pad=False)
    h, w = x.shape[-2:]
    if x.dtype not in (torch.float32, torch.float64):  # the running sums' own precision: count as they are made
        count = _window_sums(_window_sums(torch.ones(1, 1, h, w, dtype=x.dtype, device=x.device), radius, -2),
                             radius, -1)
        return _window_sums(_window_sums(x, radius, -2), radius, -1) / count
    count = _window_count(h, w, radius, x.dtype, x.device)
    if x.device.type == "cpu":
        # the same running sums, differences and division, compiled (physrelight.window_sums): the same numbers
        # to the bit in a third of the time, by strips on torch's threads (not differentiable, as the numpy
        # running sums it replaces were not)
        return box_mean(x, radius, count)
    return _window_sums(_window_sums(x, radius, -2), radius, -1) / count


def guided_filter(guide: torch.Tensor, src: torch.Tensor, radius: int, eps: float) -> torch.Tensor:
    """The guided filter of ``src (B, C, H, W)`` by ``guide (B, 1, H, W)`` (same size).

    Args:
        radius: window radius in pixels.
        eps: ridge on the local slope ``a``: a guide variance well below ``eps`` (in the guide's
            units squared) counts as flat and is smoothed over, one well above as an edge kept.

    Returns:
        ``(B, C, H, W)``. A constant ``src`` comes back unchanged, and so does one that is an
        affine function of the guide.
    """
    _check(guide, src, radius, eps)
    g = guide.to(src.dtype)
    mean_i = box_filter(g, radius)
    mean_p = box_filter(src, radius)
    cov_ip = box_filter(g * src, radius) - mean_i * mean_p
    var_i = box_filter(g * g, radius) - mean_i * mean_i
    a = cov_ip / (var_i + eps)
    b = mean_p - a * mean_i
    return box_filter(a, radius) * g + box_filter(b, radius)


def guided_upsample(guide: torch.Tensor, low: torch.Tensor, eps: float = 1e-3,
                    radius: int | None = None) -> torch.Tensor:
    """Bring ``low (B, C, h, w)`` to the size of ``guide (B, 1, H, W)`` following the guide's edges.

    ``low`` is upsampled bilinearly, then guided-filtered by the full-resolution guide with a
    window of about two low-resolution pixels (``radius`` default ``max(1, round(H / h))``): a
    boundary that the working grid blurred over a band of ``H / h`` pixels snaps to the guide's
    edge within a pixel or two.
    """
    if not isinstance(low, torch.Tensor) or low.ndim != 4:
        raise ValueError(f"low must be a (B, C, h, w) tensor, got {getattr(low, 'shape', type(low).__name__)}")
    size = guide.shape[-2:]
    up = low if low.shape[-2:] == size else F.interpolate(low, size=size, mode="bilinear", align_corners=False)
    r = radius if radius is not None else max(1, round(size[0] / max(low.shape[-2], 1)))
    return guided_filter(guide, up, r, eps)
