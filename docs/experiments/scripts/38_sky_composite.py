"""Study 38's candidate, not adopted (docs/experiments/38-sky-composite-unmixed.md): it was
``physrelight/sky_composite.py`` when the rule was written (commit 08f3d1a) and moved here after the result.

Putting a new sky behind a relit foreground: the boundary's mixed pixels un-mixed.

Why. A camera pixel on the sky line sees part sky and part land: ``I = alpha B + (1 - alpha) F``, with
``B`` the old sky's colour there and ``F`` the land's. A hard mask gives such a pixel wholly to one side.
Given to the land, it keeps its share of the old sky, and under a new sky it shows as a thin pale
(or dark) seam along every roof line, tree and horizon; given to the sky, the land loses its edge.

What. Within ``band`` pixels of the mask's boundary, ``alpha`` is estimated by projecting the pixel's
colour on the line from the local land colour ``F`` to the local sky colour ``B`` (each the mean of its
side's pixels away from the boundary, within ``radius``; :func:`masked_local_mean`), and the pixel is
re-composited with its old sky's share taken out and the new sky's put in:

    out = alpha N + max(I - alpha B, 0) R,

``N`` the new sky there and ``R`` the foreground's relighting ratio (``relit / I``, the land side's
carried into the band). Where ``B`` and ``F`` are nearly the same colour (a misty horizon) the
projection is undefined and the hard mask stands. Away from the band the hard composite is kept:
the new sky on the mask, the relit foreground elsewhere.

Shapes: ``image``, ``relit``, ``new_sky`` ``(B, 3, H, W)`` linear; ``sky (B, 1, H, W)`` bool (True = sky);
``alpha (B, 1, H, W)`` in [0, 1].
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from physrelight.guided_filter import box_filter

__all__ = ["MIN_CONTRAST", "boundary_alpha", "composite_sky", "masked_local_mean"]

MIN_CONTRAST = 0.1
"""The least difference of log colour (Euclidean, over RGB) between the local sky and land at which
:func:`boundary_alpha` un-mixes a pixel; below it the two are too alike to tell apart."""
_TINY = 1e-6


def _dilate(mask: torch.Tensor, r: int) -> torch.Tensor:
    """``(B, 1, H, W)`` bool dilated by a ``(2r+1)^2`` square."""
    return F.max_pool2d(mask.float(), 2 * r + 1, stride=1, padding=r) > 0.5


def masked_local_mean(weight: torch.Tensor, values: torch.Tensor, radius: int) -> torch.Tensor:
    """``(B, C, H, W)`` the mean of ``values (B, C, H, W)`` over the pixels of ``weight (B, 1, H, W)``
    (0/1 or soft, not all zero per image) within ``radius`` of each pixel; where none is that near, over
    all of them."""
    n = box_filter(weight, radius)
    total = weight.sum((2, 3), keepdim=True)
    overall = (values * weight).sum((2, 3), keepdim=True) / total.clamp_min(_TINY)
    return torch.where(n > 0, box_filter(values * weight, radius) / n.clamp_min(1e-12), overall)


def _check(name: str, x: torch.Tensor, shape: tuple[int, ...]) -> None:
    if not isinstance(x, torch.Tensor) or tuple(x.shape) != shape:
        got = tuple(x.shape) if isinstance(x, torch.Tensor) else type(x).__name__
        raise ValueError(f"{name} must have shape {shape}, got {got}")


def boundary_alpha(image: torch.Tensor, sky: torch.Tensor, band: int,
                   radius: int | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The sky's share of each pixel near the mask's boundary, and the old sky's colour there.

    Args:
        image: ``(B, 3, H, W)`` linear photo. sky: ``(B, 1, H, W)`` bool.
        band: pixels either side of the boundary that are un-mixed (0: none, the hard mask).
        radius: how far the local sky and land colours are averaged; None: ``3 band + 3``.

    Returns:
        ``alpha (B, 1, H, W)`` (the mask, 0 or 1, outside the band and where the two colours are too alike,
        :data:`MIN_CONTRAST`), ``background (B, 3, H, W)`` the local old sky colour, and ``unmixed
        (B, 1, H, W)`` bool, the pixels whose ``alpha`` is the projection's.
    """
    if not isinstance(image, torch.Tensor) or image.ndim != 4 or image.shape[1] != 3:
        raise ValueError(f"image must have shape (B, 3, H, W), got {getattr(image, 'shape', type(image).__name__)}")
    b, _, h, w = image.shape
    _check("sky", sky, (b, 1, h, w))
    if isinstance(band, bool) or not isinstance(band, int) or band < 0:
        raise ValueError(f"band must be an integer >= 0, got {band!r}")
    r = 3 * band + 3 if radius is None else radius
    if isinstance(r, bool) or not isinstance(r, int) or r < 1:
        raise ValueError(f"radius must be a positive integer, got {radius!r}")
    sky = sky.bool()
    x = image.clamp_min(0.0)
    alpha = sky.to(x.dtype)
    near = _dilate(sky, band) & _dilate(~sky, band) if band > 0 else torch.zeros_like(sky)
    sure_sky, sure_land = (sky & ~near).to(x.dtype), (~sky & ~near).to(x.dtype)
    has_both = (sure_sky.sum((1, 2, 3)) > 0) & (sure_land.sum((1, 2, 3)) > 0)
    if not bool(has_both.any()):
        return alpha, x, torch.zeros_like(sky)
    bg = masked_local_mean(sure_sky, x, r)
    fg = masked_local_mean(sure_land, x, r)
    d = bg - fg
    t = ((x - fg) * d).sum(1, keepdim=True) / (d * d).sum(1, keepdim=True).clamp_min(_TINY)
    contrast = (torch.log(bg.clamp_min(_TINY)) - torch.log(fg.clamp_min(_TINY))).norm(dim=1, keepdim=True)
    use = near & (contrast >= MIN_CONTRAST) & has_both[:, None, None, None]
    return torch.where(use, t.clamp(0.0, 1.0), alpha), torch.where(has_both[:, None, None, None], bg, x), use


def composite_sky(image: torch.Tensor, relit: torch.Tensor, sky: torch.Tensor, new_sky: torch.Tensor,
                  band: int, radius: int | None = None) -> torch.Tensor:
    """``(B, 3, H, W)`` the relit foreground with ``new_sky`` behind it, the boundary un-mixed.

    Where :func:`boundary_alpha` un-mixes a pixel and finds ``0 < alpha < 1``,
    ``out = alpha new_sky + max(image - alpha background, 0) R``, ``R`` the relighting ratio
    ``relit / image`` of the nearby foreground pixels (:func:`masked_local_mean`: a mixed pixel's own ratio
    mixes the land's with the sky's, which is not relit); ``alpha`` 1 gives ``new_sky`` and 0 ``relit``.
    Everywhere else, the hard composite: ``new_sky`` on the sky, ``relit`` off it. ``band = 0`` is the hard
    composite.
    """
    b, _, h, w = image.shape
    for name, x in (("relit", relit), ("new_sky", new_sky)):
        _check(name, x, (b, 3, h, w))
    hard = torch.where(sky.bool(), new_sky, relit)
    if band == 0:
        _check("sky", sky, (b, 1, h, w))
        return hard
    alpha, bg, unmixed = boundary_alpha(image, sky, band, radius)
    land = (~sky.bool()).to(image.dtype)
    lit = image.clamp_min(0.0)
    ratio = torch.where(lit > _TINY, relit / lit.clamp_min(_TINY), torch.ones_like(relit))
    r_band = masked_local_mean(land * (lit.amin(1, keepdim=True) > _TINY).to(image.dtype), ratio,
                               3 * band + 3 if radius is None else radius)
    mixed = alpha * new_sky + (lit - alpha * bg).clamp_min(0.0) * r_band
    mixed = torch.where(alpha >= 1, new_sky, torch.where(alpha <= 0, relit, mixed))
    return torch.where(unmixed, mixed, hard)
