"""The sky mask's classical processing: which parts of a mask are a sky, its boundary decided by colour, and
the sky grown by colour into a lattice's gaps.

A segmenter (``learned.sky_segmentation``) gives a sky probability at a working resolution; everything after it is
image processing, in this module: :func:`plausible_sky` keeps the 8-connected components (:func:`label_components`)
that are a sky (at the top, sky-coloured, smoother than the foreground once the photo's noise is taken out:
:func:`sky_roughness`), :func:`refine_sky_boundary` decides the pixels near the boundary of the upsampled mask by
the local colour statistics of both sides, and :func:`grow_sky_by_colour` adds the pixels near the mask that fit the
sky's smooth colour model (:func:`sky_colour_model`). :func:`is_monochrome` says when a photo has no colour to go by.

Shapes: masks ``(1, 1, H, W)`` bool and linear photos ``(1, 3, H, W)`` (one photo at a time), or ``(H, W)`` and
``(3, H, W)`` where stated.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import colour
from physrelight.parallel import thread_map

__all__ = ["COLOUR_MIN_BLUE_OVER_RED", "GROW_CHI2", "GROW_ERODE", "GROW_MAX_SPREAD", "GROW_REACH", "MIN_SKY_FRACTION",
           "MIN_SURE_SHARE", "MONOCHROME_MAX_SHARE", "MONOCHROME_TOLERANCE", "REFINEMENT", "REFINEMENTS",
           "SMOOTHNESS_MAX_RATIO", "SMOOTHNESS_NOISE_AT_OWN_SIZE", "SMOOTHNESS_NOISE_AWARE", "VARIANCE_FLOOR",
           "check_rgb_batch", "display_noise_sigma", "grow_sky_by_colour", "is_monochrome", "label_components", "log_noise_sigma",
           "plausible_sky", "refine_sky_boundary", "resized_noise_roughness", "sky_colour_model", "sky_roughness"]

_LUMA = colour.LUMINANCE


def check_rgb_batch(image: torch.Tensor, name: str = "image") -> None:
    """Refuse anything but a non-empty ``(B, 3, H, W)`` tensor with a ``ValueError`` naming ``name``."""
    if not isinstance(image, torch.Tensor) or image.ndim != 4 or image.shape[1] != 3:
        got = tuple(image.shape) if isinstance(image, torch.Tensor) else type(image).__name__
        raise ValueError(f"{name} must be a tensor of shape (B, 3, H, W), got {got}")
    if image.shape[-1] < 1 or image.shape[-2] < 1:
        raise ValueError(f"{name} must be non-empty, got {tuple(image.shape)}")


COLOUR_MIN_BLUE_OVER_RED = 0.85
"""A sky's median blue/red at least this (blue, grey or white). (Study 22's real-view segmenter needed
0.9 to refuse the mottled studio backdrop of scikit-image's astronaut, blue/red 0.859 under it; that
segmenter was not kept, and under the shipped one the backdrop is refused at 0.85.)"""
SMOOTHNESS_MAX_RATIO = 0.5
SMOOTHNESS_NOISE_AWARE = True
"""Whether :func:`plausible_sky`'s smoothness test takes each pixel's expected noise out of the roughness
(:func:`sky_roughness`; docs/experiments/50-noise-aware-smoothness.md). False: the plain roughness, as before."""
SMOOTHNESS_NOISE_AT_OWN_SIZE = True
"""Whether that noise is read off the photo at its own size and carried through the resizing to the working size
(:func:`resized_noise_roughness`), rather than read off the working image, where an enlarged small photo's noise is
spread over neighbouring pixels and mostly missed (study 50, round 2)."""
MIN_SKY_FRACTION = 0.01

REFINEMENTS = ("local", "gauss")
"""How :func:`refine_sky_boundary` decides a band pixel: ``"local"``, the nearer of the two sides'
local mean colours; ``"gauss"``, the likelier under each side's local diagonal Gaussian (mean and
variance of log RGB)."""
REFINEMENT = "gauss"
VARIANCE_FLOOR = 1e-3
"""Floor of a side's local variance of log RGB in ``"gauss"`` (about 3 % noise)."""
MIN_SURE_SHARE = 0.125
"""The least share of :func:`refine_sky_boundary`'s window that a side's sure pixels must fill for that side's
*local* statistics; below it the side's statistics over the whole photo stand in (0: any sure pixel in the
window will do, as before study 44). An object narrower than the band has no sure pixels of its own, and a
Gaussian of the few unrelated ones near it, at the variance floor, lost rocket.jpg's body to the sky
(docs/experiments/44-band-statistics-from-enough-pixels.md: training crops +0.009, lattices +0.024, sunrise
+0.022 in mean IoU/F)."""


MONOCHROME_TOLERANCE = 3.0 / 255.0
"""A display pixel counts as coloured when its channels spread by more than this (JPEG's chroma noise on a
grey photo stays under it)."""
MONOCHROME_MAX_SHARE = 0.005
"""A photo is monochrome when no more than this share of its pixels is coloured."""


def is_monochrome(image: torch.Tensor) -> bool:
    """Whether a linear photo ``(1, 3, H, W)`` has no colour: a black-and-white photo stored as RGB.

    The sky mask leans on the sky's colour (the segmenter was trained on colour photos; the band and the
    growth compare colours), so on such a photo it takes white walls and pale objects for sky: scikit-image's
    ``camera`` (the cameraman, its three channels equal) loses a white tower and part of the camcorder to it.
    :meth:`learned.relighter.Relighter.relight_layers` says so in a warning. A tinted monochrome (sepia) has
    colour by this test.
    """
    check_rgb_batch(image)
    h, w = image.shape[-2:]
    most = MONOCHROME_MAX_SHARE * h * w
    coloured = 0
    # by strips of rows, stopping as soon as too many pixels are coloured: a colour photo is known from its first
    # strip, so a 12-megapixel one is not converted to display values whole
    for r0 in range(0, h, _MONOCHROME_STRIP):
        d = colour.to_ldr(image[0, :, r0: r0 + _MONOCHROME_STRIP].clamp_min(0.0))
        coloured += int(((d.amax(0) - d.amin(0)) > MONOCHROME_TOLERANCE).sum())
        if coloured > most:
            return False
    return True


_MONOCHROME_STRIP = 256


def label_components(mask: torch.Tensor) -> torch.Tensor:
    """8-connected component labels of ``mask (H, W)`` bool: ``(H, W)`` int64, 0 off the mask, each
    component's label its largest flat index + 1.

    One pass (``scipy.ndimage.label`` with a 3 x 3 structure), then each component renamed by its largest flat
    index: the labels that the max-label propagation this replaced gave (one 3 x 3 max pool per pass, up to
    ``H * W`` passes: minutes on a long thin photo), so the masks built on them are unchanged."""
    from scipy import ndimage

    if not isinstance(mask, torch.Tensor) or mask.ndim != 2 or mask.dtype != torch.bool:
        got = f"{mask.dtype} {tuple(mask.shape)}" if isinstance(mask, torch.Tensor) else type(mask).__name__
        raise ValueError(f"mask must be a bool tensor of shape (H, W), got {got}")
    m = mask.detach().cpu().numpy()
    lab, n = ndimage.label(m, structure=np.ones((3, 3), dtype=bool))
    # the largest flat index + 1 of each component; index 0 (off the mask) stays 0
    largest = np.zeros(n + 1, dtype=np.int64)
    np.maximum.at(largest, lab.ravel(), np.arange(1, m.size + 1, dtype=np.int64))
    largest[0] = 0
    return torch.from_numpy(largest[lab]).to(mask.device)


def _roughness(lum: torch.Tensor) -> torch.Tensor:
    """``(H, W)`` std of log luminance over 3 x 3 pixels (border windows cut at the image)."""
    from physrelight.guided_filter import box_filter

    ly = torch.log(lum.clamp_min(1e-4))[None, None]
    m = box_filter(ly, 1)
    return (box_filter(ly * ly, 1) - m * m).clamp_min(0).sqrt()[0, 0]


def log_noise_sigma(lum: torch.Tensor, sigma_d: float | torch.Tensor | None = None) -> torch.Tensor:
    """The photo's noise at each pixel of linear luminance ``lum (H, W)``, in log luminance: ``(H, W)``.

    Noise in a stored photo (the sensor's after the camera's curve, JPEG's) is about even in *display* values, so
    in log luminance it is larger where the photo is darker: ``sigma_d / (d display / d log lum)``, with
    ``sigma_d`` the noise of the display luminance (given, or the noise floor of ``lum``'s:
    :func:`physrelight.denoise.noise_sigma`) and the slope of :func:`physrelight.colour.to_ldr` taken
    numerically. Where the display clips the slope is 0 and the noise infinite (a clipped patch has no noise left
    to see).
    """
    y = lum.clamp_min(1e-4)
    if sigma_d is None:
        sigma_d = display_noise_sigma(y)
    h = 1e-3  # central difference in log luminance
    slope = (colour.to_ldr(y * math.exp(h)) - colour.to_ldr(y * math.exp(-h))) / (2.0 * h)
    return torch.where(slope > 0, sigma_d / slope.clamp_min(1e-12), torch.full_like(y, math.inf))


def display_noise_sigma(lum: torch.Tensor) -> torch.Tensor:
    """The noise floor (:func:`physrelight.denoise.noise_sigma`) of the display luminance of linear ``lum (H, W)``:
    a 0-d tensor, in display values."""
    from physrelight.denoise import noise_sigma

    return noise_sigma(colour.to_ldr(lum.clamp_min(1e-4))[None, None])[0, 0]


def resized_noise_roughness(size: tuple[int, int], working: tuple[int, int]) -> float:
    """The expected squared 3 x 3 roughness (variance over 9 pixels) of unit white noise at ``size (H, W)`` once
    resized to ``working (h, w)`` as :func:`learned.data.resize_short_side` does: 8/9 without resizing.

    Enlarged bilinearly, each noise sample spreads over its neighbours, so a small photo's noise looks smoother at
    the working size than it is, and the noise floor read there misses most of it (study 50: a third). Measured on
    seeded noise (patches of at most 1024 x 1024 at the same scale, about 65k resized samples: ~1 %), so the same
    sizes give the same number.
    """
    if tuple(size) == tuple(working):
        return 8.0 / 9.0
    from physrelight.guided_filter import box_filter

    ph, pw = min(size[0], 1024), min(size[1], 1024)
    oh, ow = max(3, round(ph * working[0] / size[0])), max(3, round(pw * working[1] / size[1]))
    # enough draws for about 65k resized samples (mean known to ~1 %), at most 8M noise samples (~0.3 s)
    draws = max(1, min(math.ceil(65536 / (oh * ow)), (8 << 20) // (ph * pw)))
    g = torch.Generator().manual_seed(0)
    n = torch.randn(draws, 1, ph, pw, generator=g, dtype=torch.float64)
    if oh * ow < ph * pw:
        y = F.interpolate(n, size=(oh, ow), mode="area")
    else:
        y = F.interpolate(n, size=(oh, ow), mode="bilinear", align_corners=False)
    m = box_filter(y, 1)
    var = (box_filter(y * y, 1) - m * m)[:, 0, 1:-1, 1:-1]
    return float(var.mean())


def sky_roughness(lum: torch.Tensor, noise_aware: bool = True, noise_var: torch.Tensor | None = None) -> torch.Tensor:
    """``(H, W)`` roughness of linear luminance ``lum (H, W)`` for :func:`plausible_sky`'s smoothness test.

    The standard deviation of log luminance over 3 x 3 pixels; with ``noise_aware``, less the photo's noise:
    ``sqrt(max(r^2 - v, 0))``, ``v (H, W)`` the squared roughness the noise alone would give (``noise_var``; by
    default ``8/9 s^2`` with ``s`` from :func:`log_noise_sigma`, 8/9 being the expected 3 x 3 variance, over 9 and
    not 8, of unit white noise). Without it a small noisy photo's sky is as rough as its foreground and refused
    (study 50: rocket.jpg at 160 px with 2 % noise); a photo without noise keeps the plain roughness.
    """
    r = _roughness(lum)
    if not noise_aware:
        return r
    if noise_var is None:
        noise_var = (8.0 / 9.0) * log_noise_sigma(lum) ** 2
    return (r * r - noise_var).clamp_min(0.0).sqrt()


def plausible_sky(mask: torch.Tensor, image: torch.Tensor,
                  noise_var: torch.Tensor | None = None) -> tuple[torch.Tensor, str]:
    """Keep the parts of a sky mask that are a sky, and say why when none is.

    A sky component (8-connected, of ``mask (H, W)`` bool on linear ``image (3, H, W)``) is kept
    when it touches the top border, or when it is as bright as the top-touching sky (median
    luminance at least half of it) and as blue (blue/red at least 0.9 of it): sky between towers
    or branches. The kept sky is then judged a sky when it covers at least 1 % of the photo, is
    sky-coloured (median blue/red >= :data:`COLOUR_MIN_BLUE_OVER_RED`: blue, grey or white, not a warm
    wall, a face or a cup) and smooth (median 3 x 3 roughness of log luminance, less the photo's noise, at most half the
    foreground's: :func:`sky_roughness`; ``noise_var (H, W)``, the squared roughness the photo's noise alone
    gives at each pixel, when the caller knows it better than ``image`` shows, as for a resized photo).

    Returns:
        ``(kept (H, W) bool, reason)``; ``reason`` is ``""`` for a plausible sky, else one line
        saying why there is none (then ``kept`` is all False).
    """
    lum = (image * image.new_tensor(_LUMA)[:, None, None]).sum(0)
    lab = label_components(mask)
    top = set(lab[0][lab[0] > 0].tolist())
    if not top:
        return torch.zeros_like(mask), "no sky region touches the top of the photo"
    top_mask = torch.isin(lab, torch.tensor(sorted(top)))
    ratio = image[2] / image[0].clamp_min(1e-4)
    ref_lum, ref_ratio = float(lum[top_mask].median()), float(ratio[top_mask].median())
    kept = top_mask.clone()
    for c in torch.unique(lab[(lab > 0) & ~top_mask]).tolist():
        sel = lab == c
        if float(lum[sel].median()) >= 0.5 * ref_lum and float(ratio[sel].median()) >= 0.9 * ref_ratio:
            kept |= sel
    frac = float(kept.float().mean())
    if frac < MIN_SKY_FRACTION:
        return torch.zeros_like(mask), f"the sky found covers {100 * frac:.1f} % of the photo"
    colour_ratio = float(ratio[kept].median())
    if colour_ratio < COLOUR_MIN_BLUE_OVER_RED:
        return torch.zeros_like(mask), (f"the region found at the top is not sky-coloured (blue/red {colour_ratio:.3f}, "
                                        f"a sky has >= {COLOUR_MIN_BLUE_OVER_RED})")
    rough = sky_roughness(lum, SMOOTHNESS_NOISE_AWARE, noise_var)
    fg = ~kept
    if bool(fg.any()):
        r_sky, r_fg = float(rough[kept].median()), float(rough[fg].median())
        if r_sky > SMOOTHNESS_MAX_RATIO * r_fg:
            return torch.zeros_like(mask), (f"the region found at the top is as textured as the rest "
                                            f"(roughness {r_sky:.3f} vs {r_fg:.3f}): not a sky")
    return kept, ""


_DILATE_POOL_MAX = 16


def _dilate(mask: torch.Tensor, r: int) -> torch.Tensor:
    """``mask (B, 1, H, W)`` bool dilated by a ``(2r+1)^2`` square. A small ``r`` by two separable max pools;
    a wide one (the colour band of a large photo: hundreds of pixels) by scipy's running maximum
    (``scipy.ndimage.maximum_filter1d``, van Herk / Gil-Werman: its cost does not grow with ``r``, a max pool's
    does) on bytes, the window cut at the border (zeros outside add nothing to a maximum). The same mask as the
    window count of summed-area tables this replaced, in a fifth of the time and an eighth of the memory."""
    r = min(r, max(mask.shape[-2:]))
    if r > _DILATE_POOL_MAX:
        return _running_extreme(mask, r, "max")
    m = F.max_pool2d(mask.float(), (1, 2 * r + 1), stride=1, padding=(0, r))
    return F.max_pool2d(m, (2 * r + 1, 1), stride=1, padding=(r, 0)) > 0.5


def _running_extreme(mask: torch.Tensor, r: int, which: str) -> torch.Tensor:
    """``(B, 1, H, W)`` bool: whether the ``(2r+1)^2`` window (cut at the border) of each pixel of ``mask (B, 1, H,
    W)`` bool holds any True (``which="max"``: the dilation) or only True (``"min"``: the erosion), by two
    separable running extremes on bytes (``scipy.ndimage.maximum_filter1d`` / ``minimum_filter1d``; the
    pixels outside count as 0 for a maximum, 1 for a minimum, so they never decide; single-threaded)."""
    from scipy import ndimage

    fn, cval = (ndimage.maximum_filter1d, 0) if which == "max" else (ndimage.minimum_filter1d, 1)
    m = mask.detach().cpu().numpy().astype(np.uint8)
    m = fn(m, 2 * r + 1, axis=-1, mode="constant", cval=cval)
    m = fn(m, 2 * r + 1, axis=-2, mode="constant", cval=cval)
    return torch.from_numpy(m.astype(bool)).to(mask.device)


def _boundary_band(sky: torch.Tensor, band: int) -> torch.Tensor:
    """``(B, 1, H, W)`` bool: the pixels within a ``(2 band + 1)^2`` square of both sky and non-sky,
    ``_dilate(sky, band) & _dilate(~sky, band)``. A wide band reads the second as ``~erosion(sky)``
    (:func:`_running_extreme`): a window holds non-sky where not all of it is sky."""
    r = min(band, max(sky.shape[-2:]))
    if r > _DILATE_POOL_MAX:
        return _running_extreme(sky, r, "max") & ~_running_extreme(sky, r, "min")
    return _dilate(sky, band) & _dilate(~sky, band)


def refine_sky_boundary(sky: torch.Tensor, image: torch.Tensor, band: int, refine: str = REFINEMENT,
                        min_share: float | None = None) -> torch.Tensor:
    """Decide the pixels near a sky boundary by colour, at full resolution.

    A mask brought up from a working resolution is right away from its boundary and wrong
    within a band as wide as a working pixel or two: a lattice tower or a branch is thinner
    than that. Within ``band`` pixels of the boundary each pixel goes to the side whose local
    mean colour (log RGB, averaged over the sure pixels of that side within ``4 band``, or over
    all of them where none is that near) it is nearer to; elsewhere the mask stays. A step edge
    between two flat colours is kept exactly.

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. band: pixels.
        min_share: a side's local statistics need its sure pixels to fill this share of the window, else its
            statistics over the whole photo are used (:data:`MIN_SURE_SHARE` when None).

    Returns:
        ``(1, 1, H, W)`` bool.
    """
    min_share = MIN_SURE_SHARE if min_share is None else float(min_share)
    if not 0.0 <= min_share < 1.0:
        raise ValueError(f"min_share must lie in [0, 1), got {min_share!r}")
    near = _boundary_band(sky, band)
    if not bool(near.any()):
        return sky
    x = torch.log(image.clamp_min(1e-4))
    sure_sky, sure_fg = (sky & ~near).to(x.dtype), (~sky & ~near).to(x.dtype)
    if float(sure_sky.sum()) == 0 or float(sure_fg.sum()) == 0:
        return sky
    r = 4 * band
    if refine == "local":
        d_sky = ((x - _local_mean(sure_sky, x, r, min_share)) ** 2).sum(1, keepdim=True)
        d_fg = ((x - _local_mean(sure_fg, x, r, min_share)) ** 2).sum(1, keepdim=True)
    else:
        # "gauss": a diagonal Gaussian per side, so a smooth sky does not claim a varied foreground's outliers
        # the two sides are independent: one per thread (physrelight.parallel), the numbers of one after the other
        x2 = x * x
        d_sky, d_fg = thread_map(lambda w: _local_gaussian_nll(x, w, r, min_share, x2), [sure_sky, sure_fg])
    return torch.where(near, d_sky < d_fg, sky)


def _local_moments(w: torch.Tensor, planes: list[torch.Tensor], r: int, min_share: float = 0.0) -> list[torch.Tensor]:
    """The weighted means of each of ``planes`` (``(1, C_k, H, W)`` each) over the pixels of weight ``w (1, 1, H, W)``
    (not all zero) within ``r`` of each pixel, from one box filter of the weight and every plane; where those
    pixels fill no more than ``min_share`` of the window (none, at 0), over all of them."""
    from physrelight.guided_filter import box_filter

    weighted = [p * w for p in planes]
    sums = box_filter(torch.cat([w, *weighted], 1), r)
    n = sums[:, :1]
    local, total = n > min_share, float(w.sum())
    out, k = [], 1
    for p in weighted:
        c = p.shape[1]
        out.append(torch.where(local, sums[:, k: k + c] / n.clamp_min(1e-12), p.sum((2, 3), keepdim=True) / total))
        k += c
    return out


def _local_mean(w: torch.Tensor, v: torch.Tensor, r: int, min_share: float = 0.0) -> torch.Tensor:
    """``(1, C, H, W)`` mean of ``v (1, C, H, W)`` over the pixels of weight ``w (1, 1, H, W)`` (not all
    zero) within ``r`` of each pixel; where they fill no more than ``min_share`` of that window (none, at 0),
    over all of them (:func:`_local_moments`)."""
    return _local_moments(w, [v], r, min_share)[0]


def _local_gaussian_nll(x: torch.Tensor, w: torch.Tensor, r: int, min_share: float = 0.0,
                        x2: torch.Tensor | None = None) -> torch.Tensor:
    """``(1, 1, H, W)`` negative log-likelihood (times 2, up to a constant) of each pixel of ``x (1, C, H, W)``
    under the diagonal Gaussian of the pixels ``w`` near it (:func:`_local_moments` of ``x`` and ``x^2`` in one
    box filter; variance floor :data:`VARIANCE_FLOOR`). ``x2``: ``x * x``, when the caller has it."""
    mu, ex2 = _local_moments(w, [x, x * x if x2 is None else x2], r, min_share)
    var = (ex2 - mu * mu).clamp_min(0) + VARIANCE_FLOOR
    return ((x - mu) ** 2 / var + torch.log(var)).sum(1, keepdim=True)


def _local_gaussian_nll_at(x: torch.Tensor, w: torch.Tensor, r: int, index: torch.Tensor) -> torch.Tensor:
    """:func:`_local_gaussian_nll` at the flat pixel indices ``index (N,)`` only: ``(N,)`` float64.

    The windows' sums are read from summed-area tables (four look-ups per pixel), so the cost does not grow with
    ``r`` and the statistics are computed only where they are asked for (the growth asks at its few candidates,
    while a window of ``4 * reach`` spans most of a large photo). The tables are float64, built one plane at a time
    (each about 0.2 GB for a 24-megapixel photo). ``x (1, C, H, W)``, ``w (1, 1, H, W)``."""
    from physrelight.window_sums import summed_area_table

    c, h, wd = x.shape[1], x.shape[-2], x.shape[-1]
    iy, ix = index // wd, index % wd
    y0, y1 = (iy - r).clamp_min(0), (iy + r + 1).clamp_max(h)
    x0, x1 = (ix - r).clamp_min(0), (ix + r + 1).clamp_max(wd)
    xd, wt = x[0].to(torch.float64), w[0, 0].to(torch.float64)

    def window_sums(plane: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The sums of ``plane (H, W)`` over the windows of ``index``, and over the whole image."""
        sat = summed_area_table(plane)  # F.pad(plane.cumsum(0).cumsum(1), (1, 0, 1, 0)), compiled
        return sat[y1, x1] - sat[y0, x1] - sat[y1, x0] + sat[y0, x0], sat[-1, -1]

    def plane(k: int) -> torch.Tensor:
        """The weight, then per channel ``x w`` and ``x^2 w``."""
        if k == 0:
            return wt
        ch, power = divmod(k - 1, 2)
        return xd[ch] * wt if power == 0 else xd[ch] * xd[ch] * wt

    # each plane's table on its own thread (physrelight.parallel), made and dropped there: the same sums
    sums = thread_map(lambda k: window_sums(plane(k)), range(1 + 2 * c))
    n, n_all = sums[0]
    near = n > 0
    out = torch.zeros(index.numel(), dtype=torch.float64)
    for ch in range(c):
        (s1, t1), (s2, t2) = sums[1 + 2 * ch], sums[2 + 2 * ch]
        mu = torch.where(near, s1 / n.clamp_min(1e-12), t1 / n_all)
        var = (torch.where(near, s2 / n.clamp_min(1e-12), t2 / n_all) - mu * mu).clamp_min(0) + VARIANCE_FLOOR
        out += (xd[ch].flatten()[index] - mu) ** 2 / var + torch.log(var)
    return out


GROW_REACH = 0.1
"""How far from the mask (a fraction of the photo's short side)
:func:`learned.sky_segmentation.sky_mask_full_resolution` lets :func:`grow_sky_by_colour` add sky-coloured pixels;
0: not at all. The segmenter draws a lattice tower, power lines or bare branches solid at its working size; the
growth finds the sky between the bars. Chosen by study 40
(docs/experiments/40-sky-through-lattices.md) on the training panoramas' crops with composited lattices (mean of
IoU and boundary F +0.020 [+0.009, +0.033]); on the crops without lattices it changes the mean by -0.001 (study
28, round 3); on the held-out sunrise crops (real pylons), read once: IoU 0.903 -> 0.916, boundary F 0.702 ->
0.717. ``relight --sky-grow 0`` turns it off."""
GROW_CHI2 = 11.34
"""A grown pixel's colour must lie within this squared Mahalanobis distance of the smooth sky model
(chi-square with 3 degrees of freedom at 0.99)."""
GROW_MAX_SPREAD = 0.1
"""The sky model's largest spread (log RGB, per channel) at which
:func:`learned.sky_segmentation.sky_mask_full_resolution`'s growth adds anything: wider, and the mask it was
fitted to holds façade or foliage (study 28, round 3: neutral on the training crops at reach 0.05; rocket.jpg's
dusk sky fits within it)."""
GROW_ERODE = 2
"""Pixels within this many pixels of the mask's boundary are left out of the sky model's fit."""
_GROW_MAX_FIT = 20000


def _sky_basis(h: int, w: int, dtype: torch.dtype, order: int = 2,
               box: tuple[float, float, float, float] | None = None) -> torch.Tensor:
    """``(K, H, W)`` monomials of pixel centres up to ``order`` (1: 1, u, v; 2: also u^2, uv, v^2),
    u and v centred and scaled by the longer side, and clamped to ``box = (u0, u1, v0, v1)``."""
    s = float(max(h, w))
    v = ((torch.arange(h, dtype=dtype) + 0.5 - h / 2) / s)[:, None].expand(h, w)
    u = ((torch.arange(w, dtype=dtype) + 0.5 - w / 2) / s)[None, :].expand(h, w)
    if box is not None:
        u, v = u.clamp(box[0], box[1]), v.clamp(box[2], box[3])
    terms = [torch.ones_like(u), u, v] + ([u * u, u * v, v * v] if order == 2 else [])
    return torch.stack(terms)


def sky_colour_model(sky: torch.Tensor, image: torch.Tensor, order: int = 2,
                     clamp: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """The smooth model of a sky's colour that :func:`grow_sky_by_colour` fits: per channel, log RGB as a
    polynomial of degree ``order`` in the pixel position, least squares over the mask's pixels at least
    ``GROW_ERODE`` px inside it, refitted once without the 3-sigma outliers.

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. order: 1 or 2.
        clamp: evaluate the model only inside the fitted pixels' bounding box (no extrapolation).

    Returns:
        ``(x, pred, sigma)``: the photo's log RGB ``(3, H, W)`` and the model's prediction ``(3, H, W)`` (float64),
        and its spread per channel ``(3,)`` (the residuals' MAD scaled to a standard deviation, at least
        ``sqrt(VARIANCE_FLOOR)``); None when fewer than 64 pixels lie inside the mask, it covers everything, or
        fewer than 16 survive the outlier test.
    """
    h, w = sky.shape[-2:]
    x = torch.log(image.clamp_min(1e-4)).to(torch.float64)[0]  # (3, H, W)
    sure = ~_dilate(~sky, GROW_ERODE)[0, 0]
    if int(sure.sum()) < 64 or bool(sure.all()):
        return None
    idx = torch.nonzero(sure.flatten()).squeeze(1)
    basis = _sky_basis(h, w, torch.float64, order)
    if clamp:
        uv = basis[1:3].reshape(2, -1)[:, idx]
        box = (float(uv[0].min()), float(uv[0].max()), float(uv[1].min()), float(uv[1].max()))
        basis = _sky_basis(h, w, torch.float64, order, box)
    if idx.numel() > _GROW_MAX_FIT:  # an even, deterministic subsample keeps the fit cheap
        idx = idx[torch.linspace(0, idx.numel() - 1, _GROW_MAX_FIT).round().long()]
    a = basis.reshape(basis.shape[0], -1)[:, idx].T  # (N, K)
    y = x.reshape(3, -1)[:, idx].T  # (N, 3)
    keep = torch.ones(a.shape[0], dtype=torch.bool)
    for _ in range(2):
        coef = torch.linalg.lstsq(a[keep], y[keep]).solution  # (K, 3)
        res = y - a @ coef
        med = res[keep].median(0).values
        sigma = (1.4826 * (res[keep] - med).abs().median(0).values).clamp_min(math.sqrt(VARIANCE_FLOOR))
        keep = ((res - med).abs() <= 3 * sigma).all(1)
        if int(keep.sum()) < 16:
            return None
    return x, torch.einsum("khw,kc->chw", basis, coef) + med[:, None, None], sigma


def grow_sky_by_colour(sky: torch.Tensor, image: torch.Tensor, reach: int, chi2: float = GROW_CHI2,
                       order: int = 2, clamp: bool = True, max_spread: float | None = None) -> torch.Tensor:
    """Add the pixels that have the sky's colour where the sky would be, near the mask.

    A working-resolution segmenter sees a lattice tower or a tree's crown as solid; the sky
    between its bars or leaves is too far inside for :func:`refine_sky_boundary`'s band. A clear
    or overcast sky's log RGB varies smoothly across a photo, so it is modelled per channel as a
    polynomial in the pixel position, fitted by least squares to the mask's pixels away from its
    boundary (twice, the second time without the fit's 3-sigma outliers; the spread per channel is
    the residuals' MAD scaled to a standard deviation, at least ``sqrt(VARIANCE_FLOOR)``). A
    non-sky pixel within ``reach`` pixels of the mask becomes sky when its colour is within
    squared Mahalanobis distance ``chi2`` of the model's prediction at its position, and likelier
    under it than under the local Gaussian of the surrounding non-sky pixels (as in
    :func:`refine_sky_boundary`'s ``"gauss"``). A dark bar or a lit wall is far from the sky's
    colour; a blue wall is nearer its own surroundings. Nothing is removed. With ``clamp``, the model is
    not extrapolated: a pixel outside the fitted pixels' bounding box gets the prediction at the
    box's nearest point (a quadratic fitted to a sky at the top would otherwise dive toward a grey
    road below it).

    Args:
        sky: ``(1, 1, H, W)`` bool. image: ``(1, 3, H, W)`` linear. reach: pixels, >= 0.
        chi2: the squared Mahalanobis gate, > 0. order: the polynomial's degree, 1 or 2.
        clamp: evaluate the model only inside the fitted pixels' bounding box.
        max_spread: when the model's spread in log RGB exceeds this in any channel, the mask it was
            fitted to is not a clean sky (a façade or foliage taken for sky) and nothing is added;
            None: no such check.

    Returns:
        ``(1, 1, H, W)`` bool, a superset of ``sky``.
    """
    if sky.ndim != 4 or sky.shape[:2] != (1, 1):
        raise ValueError(f"sky must have shape (1, 1, H, W), got {tuple(sky.shape)}")
    if image.ndim != 4 or image.shape[:2] != (1, 3) or image.shape[-2:] != sky.shape[-2:]:
        raise ValueError(f"image must have shape (1, 3, {sky.shape[-2]}, {sky.shape[-1]}), got {tuple(image.shape)}")
    if isinstance(reach, bool) or not isinstance(reach, int) or reach < 0:
        raise ValueError(f"reach must be an integer >= 0, got {reach!r}")
    if not chi2 > 0:
        raise ValueError(f"chi2 must be > 0, got {chi2!r}")
    if order not in (1, 2):
        raise ValueError(f"order must be 1 or 2, got {order!r}")
    if reach == 0:
        return sky
    h, w = sky.shape[-2:]
    cand = (_dilate(sky, reach) & ~sky)[0, 0]
    if not bool(cand.any()):
        return sky
    model = sky_colour_model(sky, image, order, clamp)
    if model is None:
        return sky
    x, pred, sigma = model
    if max_spread is not None and float(sigma.max()) > max_spread:
        return sky
    maha = (((x - pred) / sigma[:, None, None]) ** 2).sum(0)
    d_sky = maha + 2 * torch.log(sigma).sum()
    # only the candidates with the sky's colour need the local Gaussian of the non-sky pixels around them (a
    # candidate is itself non-sky, so it is always defined there)
    ask = torch.nonzero((cand & (maha < chi2)).flatten()).squeeze(1)
    grow = torch.zeros(h * w, dtype=torch.bool)
    if ask.numel():
        d_fg = _local_gaussian_nll_at(x[None], (~sky).to(torch.float64), max(4, 4 * reach), ask)
        grow[ask] = d_sky.flatten()[ask] < d_fg
    return sky | grow.reshape(1, 1, h, w)
