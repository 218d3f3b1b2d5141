"""Image metrics: L1, MSE, PSNR, SSIM / DSSIM (Wang et al. 2004) and CIEDE2000.

Conventions (both torch and numpy):
    * images are channel-first, ``(B, C, H, W)`` or ``(C, H, W)``; an unbatched image is a
      batch of one. ``pred`` and ``target`` must have the same shape.
    * ``mask`` selects the pixels a metric averages over: ``(H, W)``, ``(1, H, W)``,
      ``(B, H, W)``, ``(1, 1, H, W)`` or ``(B, 1, H, W)``, boolean or float holding only 0
      and 1, broadcast over channels (and over the batch where its batch size is 1).
      A mask that selects no pixel of some image raises ``ValueError``.
    * ``reduction="mean"`` (default) averages the *per-image* values over the batch (so a
      masked batch weights images equally, not pixels); ``"none"`` returns them, shape
      ``(B,)`` (``(1,)`` for an unbatched image).
    * torch input gives a torch result (0-dim for ``"mean"``) that keeps the autograd
      graph; numpy input gives a Python float (``"mean"``) or a numpy array (``"none"``).

SSIM follows Wang et al. (2004) as scikit-image implements it with
``gaussian_weights=True, sigma=1.5, use_sample_covariance=False``: an 11x11 Gaussian
window (sigma 1.5, truncated at radius 5, weights summing to 1), ``C1 = (0.01 R)^2``,
``C2 = (0.03 R)^2``, population covariances, and the SSIM map averaged over the pixels at
least 5 px from the border (where the window lies inside the image, so no padding rule
enters) and over channels. DSSIM = (1 - SSIM) / 2.

CIEDE2000 follows Sharma, Wu and Dalal (2005) with k_L = k_C = k_H = 1, branch for branch
as ``colour.delta_E(lab1, lab2, method='CIE 2000')`` (hue of a zero-chroma colour = 0;
hue difference 0 when either chroma is 0), written so gradients stay finite at zero chroma
and at zero difference.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import torch
import torch.nn.functional as F

from physrelight._checks import Array, Restore, check_finite, check_image, to_tensor
from physrelight.colour import _check_channels, _rgb_to_lab, _srgb_to_linear
from physrelight.filters import gaussian_blur

__all__ = [
    "l1",
    "mse",
    "psnr",
    "best_gain",
    "ssim",
    "ssim_map",
    "dssim",
    "delta_e2000",
    "delta_e2000_map",
    "ciede2000",
    "mask_iou",
    "mask_boundary",
    "boundary_f",
    "depth_edges",
    "edge_band",
    "edge_band_l1",
]

_REDUCTIONS = ("mean", "none")
_ENCODINGS = ("srgb", "linear")
_SSIM_SIGMA = 1.5
_SSIM_RADIUS = int(3.5 * _SSIM_SIGMA + 0.5)  # = 5, scikit-image's truncate=3.5 rule
_SSIM_K1, _SSIM_K2 = 0.01, 0.03


# ----------------------------------------------------------------------------- input handling


class _Pair(NamedTuple):
    pred: torch.Tensor  # (B, C, H, W)
    target: torch.Tensor  # (B, C, H, W), same dtype and device as pred
    mask: torch.Tensor | None  # (B, 1, H, W) of 0/1 in pred's dtype
    batched: bool
    is_numpy: bool
    restore: Restore


def _prepare(
    pred: Array,
    target: Array,
    mask: Array | None = None,
    reduction: str = "mean",
    channels: int | None = None,
) -> _Pair:
    if reduction not in _REDUCTIONS:
        raise ValueError(f"reduction must be one of {', '.join(_REDUCTIONS)}, got {reduction!r}")
    is_numpy = not isinstance(pred, torch.Tensor)
    p, restore = to_tensor(pred, "pred")
    t, _ = to_tensor(target, "target")
    for x, name in ((p, "pred"), (t, "target")):
        if x.ndim not in (3, 4):
            raise ValueError(f"{name} must be a (B, C, H, W) or (C, H, W) image, got shape {tuple(x.shape)}")
    if p.shape != t.shape:
        raise ValueError(f"pred {tuple(p.shape)} and target {tuple(t.shape)} must have the same shape")
    check_finite(p, "pred")
    check_finite(t, "target")
    batched = p.ndim == 4
    if not batched:
        p, t = p[None], t[None]
    check_image(p, "pred", channels)
    dtype = torch.promote_types(p.dtype, t.dtype)
    p = p.to(dtype)
    t = t.to(dtype=dtype, device=p.device)
    m = None if mask is None else _prepare_mask(mask, p)
    return _Pair(p, t, m, batched, is_numpy, restore)


def _prepare_mask(mask: Array, like: torch.Tensor) -> torch.Tensor:
    """Bring ``mask`` to ``(B, 1, H, W)`` of 0/1 values in the dtype of ``like`` ``(B, C, H, W)``."""
    m, _ = to_tensor(mask, "mask")
    shape = tuple(m.shape)
    B, _, H, W = like.shape
    if m.ndim == 2:
        m = m[None, None]
    elif m.ndim == 3:
        m = m[:, None]
    if m.ndim != 4 or m.shape[1] != 1 or m.shape[0] not in (1, B) or m.shape[-2:] != (H, W):
        raise ValueError(
            f"mask {shape} does not fit images {tuple(like.shape)}: expected (H, W), (1, H, W), "
            f"(B, H, W), (1, 1, H, W) or (B, 1, H, W) with (H, W) = {(H, W)} and B = {B}"
        )
    check_finite(m, "mask")
    md = m.detach()
    if not bool(((md == 0) | (md == 1)).all()):
        raise ValueError(
            f"mask must be boolean or hold only 0 and 1, got values in [{float(md.min()):.4g}, {float(md.max()):.4g}]"
        )
    return md.to(dtype=like.dtype, device=like.device).expand(B, 1, H, W)


def _masked_mean(values: torch.Tensor, mask: torch.Tensor | None, where: str = "") -> torch.Tensor:
    """Per-image mean of ``values`` ``(B, C, h, w)`` over channels and mask pixels -> ``(B,)``."""
    if mask is None:
        return values.mean(dim=(1, 2, 3))
    count = mask.sum(dim=(1, 2, 3))
    empty = torch.nonzero(count == 0).flatten().tolist()
    if empty:
        raise ValueError(f"mask selects no pixels{where} in image(s) {empty} of the batch")
    return (values * mask).sum(dim=(1, 2, 3)) / (count * values.shape[1])


def _finish(per_image: torch.Tensor, pair: _Pair, reduction: str) -> Any:
    """Apply the reduction and convert: 0-dim tensor / float for "mean", ``(B,)`` for "none"."""
    if reduction == "mean":
        out = per_image.mean()
        return float(out) if pair.is_numpy else out
    return pair.restore(per_image)


def _check_data_range(data_range: float) -> None:
    if not (isinstance(data_range, (int, float)) and math.isfinite(data_range) and data_range > 0):
        raise ValueError(f"data_range must be a finite positive number, got {data_range!r}")


# ----------------------------------------------------------------------------- L1, MSE, PSNR


def l1(pred: Array, target: Array, mask: Array | None = None, reduction: str = "mean") -> Any:
    """Mean absolute error per image, averaged over channels and (mask) pixels.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``.
        target: same shape as ``pred``.
        mask: optional, see the module docstring (``(B, 1, H, W)``, ``(H, W)``, ...).
        reduction: ``"mean"`` over images, or ``"none"`` for per-image values ``(B,)``.

    Returns:
        0-dim tensor (differentiable) / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: bad shapes (the message names both), NaN/inf, bad or empty mask.
    """
    pair = _prepare(pred, target, mask, reduction)
    return _finish(_masked_mean((pair.pred - pair.target).abs(), pair.mask), pair, reduction)


def mse(pred: Array, target: Array, mask: Array | None = None, reduction: str = "mean") -> Any:
    """Mean squared error per image, averaged over channels and (mask) pixels.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        0-dim tensor (differentiable) / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: bad shapes, NaN/inf, bad or empty mask.
    """
    pair = _prepare(pred, target, mask, reduction)
    return _finish(_masked_mean((pair.pred - pair.target) ** 2, pair.mask), pair, reduction)


def psnr(
    pred: Array,
    target: Array,
    mask: Array | None = None,
    data_range: float = 1.0,
    reduction: str = "mean",
) -> Any:
    """Peak signal-to-noise ratio per image, ``10 log10(data_range^2 / MSE)`` in dB.

    Computed per image from that image's (masked) MSE; ``"mean"`` averages the dB values
    over the batch (the usual benchmark convention). Identical images give ``inf``.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.
        data_range: peak-to-peak range of the signal (1 for images in [0, 1]).
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        0-dim tensor / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: bad shapes, NaN/inf, bad or empty mask, ``data_range <= 0``.
    """
    _check_data_range(data_range)
    pair = _prepare(pred, target, mask, reduction)
    err = _masked_mean((pair.pred - pair.target) ** 2, pair.mask)
    return _finish(10.0 * torch.log10(data_range**2 / err), pair, reduction)


def best_gain(pred: Array, target: Array, mask: Array | None = None) -> Any:
    """The single gain per image that best brings ``pred`` to ``target`` in least squares.

    ``g = sum(pred * target) / sum(pred ** 2)`` over channels and (mask) pixels, so that
    ``g * pred`` is the prediction with its overall level removed: metrics of ``g * pred``
    report structure apart from level (exposure-invariant metrics). Meant for *linear*
    radiance; ``best_gain(k * pred, target) == best_gain(pred, target) / k`` for ``k > 0``,
    so ``best_gain(pred, target) * pred`` does not change when ``pred`` is scaled.
    An all-zero prediction (over the mask) gets ``g = 1``.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``, linear, non-negative.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.

    Returns:
        ``(B,)`` gains (``(1,)`` unbatched); torch in, torch out (differentiable).

    Raises:
        ValueError: bad shapes, NaN/inf, bad or empty mask.
    """
    pair = _prepare(pred, target, mask, "none")
    m = 1.0 if pair.mask is None else pair.mask
    if pair.mask is not None:
        _masked_mean(pair.pred, pair.mask)  # raises on an empty mask, naming the image
    num = (pair.pred * pair.target * m).sum(dim=(1, 2, 3))
    den = (pair.pred * pair.pred * m).sum(dim=(1, 2, 3))
    g = torch.where(den > 0, num / den.clamp_min(torch.finfo(den.dtype).tiny), torch.ones_like(den))
    return pair.restore(g)


# ----------------------------------------------------------------------------- SSIM


def _pad_symmetric(x: torch.Tensor, r: int) -> torch.Tensor:
    """Half-sample symmetric padding (``d c b a | a b c d``, scipy's ``mode='reflect'``)."""
    for axis in (-2, -1):
        n = x.shape[axis]
        idx = torch.cat(
            [torch.arange(r - 1, -1, -1), torch.arange(n), torch.arange(n - 1, n - 1 - r, -1)]
        ).to(x.device)
        x = x.index_select(axis, idx)
    return x


def _ssim_map(p: torch.Tensor, t: torch.Tensor, data_range: float, padding: str = "valid") -> torch.Tensor:
    """SSIM map of ``(B, C, H, W)`` images: ``(B, C, H-10, W-10)`` ("valid") or ``(B, C, H, W)``."""
    if padding == "symmetric":
        p, t = _pad_symmetric(p, _SSIM_RADIUS), _pad_symmetric(t, _SSIM_RADIUS)
    c = p.shape[1]
    # one blur (grouped convolutions) for the five local moments
    z = torch.cat([p, t, p * p, t * t, p * t], 1)
    mu_p, mu_t, e_pp, e_tt, e_pt = gaussian_blur(z, _SSIM_SIGMA, _SSIM_RADIUS, "valid").split(c, 1)
    var_p = e_pp - mu_p * mu_p  # population (not sample) covariances, as Wang et al.
    var_t = e_tt - mu_t * mu_t
    cov = e_pt - mu_p * mu_t
    c1 = (_SSIM_K1 * data_range) ** 2
    c2 = (_SSIM_K2 * data_range) ** 2
    num = (2.0 * mu_p * mu_t + c1) * (2.0 * cov + c2)
    den = (mu_p * mu_p + mu_t * mu_t + c1) * (var_p + var_t + c2)
    return num / den


def _check_ssim_size(p: torch.Tensor) -> None:
    side = 2 * _SSIM_RADIUS + 1
    if p.shape[-2] < side or p.shape[-1] < side:
        raise ValueError(
            f"ssim needs images of at least {side}x{side} pixels (the Gaussian window), got shape {tuple(p.shape)}"
        )


def _ssim_per_image(pair: _Pair, data_range: float) -> torch.Tensor:
    _check_data_range(data_range)
    _check_ssim_size(pair.pred)
    s = _ssim_map(pair.pred, pair.target, data_range)
    r = _SSIM_RADIUS
    m = None if pair.mask is None else pair.mask[..., r:-r, r:-r]
    return _masked_mean(s, m, where=f" at least {r} px from the border")


def ssim_map(pred: Array, target: Array, data_range: float = 1.0, padding: str = "valid") -> Array:
    """Per-pixel, per-channel SSIM map (Wang et al. 2004; see the module docstring).

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``, H and W at least 11.
        target: same shape as ``pred``.
        data_range: peak-to-peak range of the signal.
        padding: ``"valid"`` returns only the pixels whose window lies inside the image,
            ``(..., H-10, W-10)``: entry ``[i, j]`` belongs to image pixel ``[i+5, j+5]``, and
            its mean is :func:`ssim`. ``"symmetric"`` pads half-sample symmetrically and
            returns ``(..., H, W)``, equal to scikit-image's ``full=True`` map.

    Returns:
        The map, same batching and type as ``pred``: ``(B, C, H', W')`` or ``(C, H', W')``.

    Raises:
        ValueError: bad shapes, NaN/inf, images smaller than 11x11, bad ``padding`` or ``data_range``.
    """
    if padding not in ("valid", "symmetric"):
        raise ValueError(f"padding must be 'valid' or 'symmetric', got {padding!r}")
    _check_data_range(data_range)
    pair = _prepare(pred, target)
    _check_ssim_size(pair.pred)
    s = _ssim_map(pair.pred, pair.target, data_range, padding)
    return pair.restore(s if pair.batched else s[0])


def ssim(
    pred: Array,
    target: Array,
    mask: Array | None = None,
    data_range: float = 1.0,
    reduction: str = "mean",
) -> Any:
    """Structural similarity (Wang et al. 2004), as scikit-image with Gaussian weights.

    Per image: the mean of the SSIM map over channels and over the pixels at least 5 px
    from the border; with a mask, over the mask pixels inside that region.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``, H and W at least 11.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.
        data_range: peak-to-peak range of the signal (1 for images in [0, 1]).
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        0-dim tensor (differentiable) / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: bad shapes, NaN/inf, images smaller than 11x11, a mask with no pixel
            inside the cropped region, ``data_range <= 0``.
    """
    pair = _prepare(pred, target, mask, reduction)
    return _finish(_ssim_per_image(pair, data_range), pair, reduction)


def dssim(
    pred: Array,
    target: Array,
    mask: Array | None = None,
    data_range: float = 1.0,
    reduction: str = "mean",
) -> Any:
    """Structural dissimilarity ``(1 - SSIM) / 2`` per image (see :func:`ssim`).

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``, H and W at least 11.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.
        data_range: peak-to-peak range of the signal.
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        0-dim tensor (differentiable) / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: as :func:`ssim`.
    """
    pair = _prepare(pred, target, mask, reduction)
    return _finish((1.0 - _ssim_per_image(pair, data_range)) / 2.0, pair, reduction)


# ----------------------------------------------------------------------------- CIEDE2000


def _safe_sqrt(x: torch.Tensor) -> torch.Tensor:
    """sqrt with value 0 and gradient 0 (instead of inf/NaN) where ``x <= 0``."""
    pos = x > 0
    return torch.where(pos, torch.sqrt(torch.where(pos, x, torch.ones_like(x))), torch.zeros_like(x))


def _chroma_weight(c: torch.Tensor) -> torch.Tensor:
    """``sqrt(C^7 / (C^7 + 25^7))`` written as ``C^3.5 / sqrt(C^7 + 25^7)``: finite slope at C = 0."""
    return c**3.5 / torch.sqrt(c**7 + 25.0**7)


def _hue_degrees(b: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """Hue angle in [0, 360) degrees; 0 (with zero gradient) where a = b = 0."""
    zero = (a == 0) & (b == 0)
    h = torch.rad2deg(torch.atan2(torch.where(zero, torch.zeros_like(b), b), torch.where(zero, torch.ones_like(a), a)))
    return torch.where(zero, torch.zeros_like(h), torch.remainder(h, 360.0))


def _ciede2000(lab1: torch.Tensor, lab2: torch.Tensor, dim: int) -> torch.Tensor:
    """CIEDE2000 between Lab arrays (3 entries along ``dim``); returns the shape without ``dim``."""
    L1, a1, b1 = lab1.unbind(dim)
    L2, a2, b2 = lab2.unbind(dim)

    c_bar = (_safe_sqrt(a1 * a1 + b1 * b1) + _safe_sqrt(a2 * a2 + b2 * b2)) / 2.0
    g = 0.5 * (1.0 - _chroma_weight(c_bar))
    ap1, ap2 = (1.0 + g) * a1, (1.0 + g) * a2
    cp1, cp2 = _safe_sqrt(ap1 * ap1 + b1 * b1), _safe_sqrt(ap2 * ap2 + b2 * b2)
    hp1, hp2 = _hue_degrees(b1, ap1), _hue_degrees(b2, ap2)

    d_L = L2 - L1
    d_C = cp2 - cp1
    cc = cp1 * cp2
    achromatic = cc == 0  # hue undefined for one of the pair
    dh = hp2 - hp1
    dh = torch.where(dh > 180.0, dh - 360.0, torch.where(dh < -180.0, dh + 360.0, dh))
    dh = torch.where(achromatic, torch.zeros_like(dh), dh)
    d_H = 2.0 * _safe_sqrt(cc) * torch.sin(torch.deg2rad(dh / 2.0))

    L_bar = (L1 + L2) / 2.0
    c_bar_p = (cp1 + cp2) / 2.0
    h_sum = hp1 + hp2
    h_bar = torch.where(
        achromatic,
        h_sum,
        torch.where(
            (hp1 - hp2).abs() <= 180.0,
            h_sum / 2.0,
            torch.where(h_sum < 360.0, (h_sum + 360.0) / 2.0, (h_sum - 360.0) / 2.0),
        ),
    )
    T = (
        1.0
        - 0.17 * torch.cos(torch.deg2rad(h_bar - 30.0))
        + 0.24 * torch.cos(torch.deg2rad(2.0 * h_bar))
        + 0.32 * torch.cos(torch.deg2rad(3.0 * h_bar + 6.0))
        - 0.20 * torch.cos(torch.deg2rad(4.0 * h_bar - 63.0))
    )
    d_theta = 30.0 * torch.exp(-(((h_bar - 275.0) / 25.0) ** 2))
    R_C = 2.0 * _chroma_weight(c_bar_p)
    L50 = (L_bar - 50.0) ** 2
    S_L = 1.0 + 0.015 * L50 / torch.sqrt(20.0 + L50)
    S_C = 1.0 + 0.045 * c_bar_p
    S_H = 1.0 + 0.015 * c_bar_p * T
    R_T = -torch.sin(torch.deg2rad(2.0 * d_theta)) * R_C

    tl, tc, th = d_L / S_L, d_C / S_C, d_H / S_H
    return _safe_sqrt(tl * tl + tc * tc + th * th + R_T * tc * th)


def ciede2000(lab1: Array, lab2: Array, dim: int = -1) -> Array:
    """CIEDE2000 colour difference (k_L = k_C = k_H = 1) between CIELAB colours, per element.

    Agrees with ``colour.delta_E(lab1, lab2, method='CIE 2000')`` (Lab with L* in 0..100).

    Args:
        lab1: Lab with 3 entries along ``dim``: ``(..., 3)`` by default, or e.g.
            ``(B, 3, H, W)`` with ``dim=-3``.
        lab2: Lab, broadcastable against ``lab1``.
        dim: the channel axis.

    Returns:
        Delta E 00, the broadcast shape without ``dim`` (``(...)`` or ``(B, H, W)``), type of ``lab1``.

    Raises:
        ValueError: not 3 entries along ``dim`` (the message names the shape); shapes that
            do not broadcast; NaN or inf.
    """
    a, restore = to_tensor(lab1, "lab1")
    b, _ = to_tensor(lab2, "lab2")
    _check_channels(a, dim, "lab1")
    _check_channels(b, dim, "lab2")
    check_finite(a, "lab1")
    check_finite(b, "lab2")
    try:
        a, b = torch.broadcast_tensors(a, b.to(dtype=a.dtype, device=a.device))
    except RuntimeError:
        raise ValueError(f"lab1 {tuple(a.shape)} and lab2 {tuple(b.shape)} do not broadcast") from None
    return restore(_ciede2000(a, b, dim))


def _delta_e_pixels(pair: _Pair, encoding: str) -> torch.Tensor:
    """Per-pixel CIEDE2000 of RGB images ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    if encoding not in _ENCODINGS:
        raise ValueError(f"encoding must be one of {', '.join(_ENCODINGS)}, got {encoding!r}")
    p, t = pair.pred, pair.target
    if encoding == "srgb":
        p, t = _srgb_to_linear(p), _srgb_to_linear(t)
    return _ciede2000(_rgb_to_lab(p, -3), _rgb_to_lab(t, -3), -3)[:, None]


def delta_e2000_map(pred: Array, target: Array, encoding: str = "srgb") -> Array:
    """Per-pixel CIEDE2000 between two RGB images.

    Args:
        pred: RGB ``(B, 3, H, W)`` or ``(3, H, W)``; sRGB-encoded display values (in [0, 1])
            for ``encoding="srgb"``, linear sRGB for ``encoding="linear"``.
        target: same shape as ``pred``.
        encoding: ``"srgb"`` or ``"linear"``.

    Returns:
        ``(B, 1, H, W)`` or ``(1, H, W)``, type of ``pred``.

    Raises:
        ValueError: not 3 channels, bad shapes, NaN/inf, unknown ``encoding``.
    """
    pair = _prepare(pred, target, channels=3)
    d = _delta_e_pixels(pair, encoding)
    return pair.restore(d if pair.batched else d[0])


def delta_e2000(
    pred: Array,
    target: Array,
    mask: Array | None = None,
    encoding: str = "srgb",
    reduction: str = "mean",
) -> Any:
    """Mean CIEDE2000 colour difference per image (over pixels, or mask pixels).

    RGB is converted to CIELAB with :mod:`physrelight.colour` (sRGB D65 primaries, D65
    white, L* in 0..100); CIEDE2000 as :func:`ciede2000`.

    Args:
        pred: RGB ``(B, 3, H, W)`` or ``(3, H, W)``; sRGB-encoded display values (in [0, 1])
            for ``encoding="srgb"`` (default), linear sRGB for ``encoding="linear"``.
        target: same shape as ``pred``.
        mask: optional, see the module docstring.
        encoding: ``"srgb"`` or ``"linear"``.
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        0-dim tensor (differentiable) / float for ``"mean"``; ``(B,)`` for ``"none"``.

    Raises:
        ValueError: not 3 channels, bad shapes, NaN/inf, bad or empty mask, unknown ``encoding``.
    """
    pair = _prepare(pred, target, mask, reduction, channels=3)
    return _finish(_masked_mean(_delta_e_pixels(pair, encoding), pair.mask), pair, reduction)


# ----------------------------------------------------------------------------- masks (segmentation)


def _binary_mask(x: Array, name: str) -> torch.Tensor:
    t, _ = to_tensor(x, name)
    if t.ndim != 2:
        raise ValueError(f"{name} must be an (H, W) mask, got shape {tuple(t.shape)}")
    check_finite(t, name)
    if not bool(((t == 0) | (t == 1)).all()):
        raise ValueError(f"{name} must be boolean or hold only 0 and 1")
    return t > 0.5


def _check_pair_masks(pred: Array, target: Array) -> tuple[torch.Tensor, torch.Tensor]:
    p, t = _binary_mask(pred, "pred"), _binary_mask(target, "target")
    if p.shape != t.shape:
        raise ValueError(f"pred {tuple(p.shape)} and target {tuple(t.shape)} must have the same shape")
    return p, t


def mask_iou(pred: Array, target: Array) -> float:
    """Intersection over union of two ``(H, W)`` masks; 1 when both are empty (they agree: no region)."""
    p, t = _check_pair_masks(pred, target)
    union = int((p | t).sum())
    return 1.0 if union == 0 else int((p & t).sum()) / union


def mask_boundary(mask: Array) -> Array:
    """``(H, W)`` bool: the pixels of ``mask`` with a 4-neighbour outside it (the image border is not a boundary)."""
    m = _binary_mask(mask, "mask")
    pad = F.pad(m[None, None].float(), (1, 1, 1, 1), mode="replicate")[0, 0] > 0.5
    inner = pad[:-2, 1:-1] & pad[2:, 1:-1] & pad[1:-1, :-2] & pad[1:-1, 2:]
    out = m & ~inner
    return out if isinstance(mask, torch.Tensor) else out.numpy()


def _within(b: torch.Tensor, tolerance: float) -> torch.Tensor:
    """Pixels within Euclidean distance ``tolerance`` of a True pixel of ``b`` ``(H, W)``."""
    r = int(math.floor(tolerance))
    if r <= 0:
        return b
    d = torch.arange(-r, r + 1, dtype=torch.float32)
    disk = ((d[:, None] ** 2 + d[None, :] ** 2) <= tolerance**2 + 1e-9).float()[None, None]
    return F.conv2d(b[None, None].float(), disk, padding=r)[0, 0] > 0.5


def boundary_f(pred: Array, target: Array, tolerance: float = 2.0) -> float:
    """Boundary F-score of two ``(H, W)`` masks (Martin et al.; the DAVIS ``F`` measure).

    Precision: the fraction of ``pred``'s boundary pixels (:func:`mask_boundary`) within
    ``tolerance`` pixels (Euclidean) of ``target``'s boundary; recall the other way round;
    ``F = 2 P R / (P + R)``. Two masks without a boundary (both empty or both full) score 1;
    one without, against one with, 0.
    """
    if not (isinstance(tolerance, (int, float)) and math.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"tolerance must be a finite number >= 0 of pixels, got {tolerance!r}")
    p, t = _check_pair_masks(pred, target)
    bp, bt = torch.as_tensor(mask_boundary(p)), torch.as_tensor(mask_boundary(t))
    n_p, n_t = int(bp.sum()), int(bt.sum())
    if n_p == 0 and n_t == 0:
        return 1.0
    if n_p == 0 or n_t == 0:
        return 0.0
    precision = int((bp & _within(bt, tolerance)).sum()) / n_p
    recall = int((bt & _within(bp, tolerance)).sum()) / n_t
    return 0.0 if precision + recall == 0 else 2.0 * precision * recall / (precision + recall)


# ----------------------------------------------------------------------------- halos at depth edges

DEPTH_EDGE_THRESHOLD = 0.1
"""Relative depth jump between 4-neighbours that counts as a discontinuity: ``|d_p - d_q| / min(d_p, d_q)``.
A smooth surface seen at 60 deg field of view jumps by ``pixel angle / tan(grazing angle)`` per pixel:
at 256 px (0.004 rad a pixel) that passes 0.1 only on ground within ~2 deg of grazing."""


def _prepare_depth(depth: Array, like: torch.Tensor) -> torch.Tensor:
    """Bring ``depth`` to ``(B, 1, H, W)`` in the dtype of ``like`` ``(B, C, H, W)``; check it."""
    d, _ = to_tensor(depth, "depth")
    shape = tuple(d.shape)
    B, _, H, W = like.shape
    if d.ndim == 2:
        d = d[None, None]
    elif d.ndim == 3:
        d = d[:, None]
    if d.ndim != 4 or d.shape[1] != 1 or d.shape[0] not in (1, B) or d.shape[-2:] != (H, W):
        raise ValueError(
            f"depth {shape} does not fit images {tuple(like.shape)}: expected (H, W), (1, H, W), "
            f"(B, H, W), (1, 1, H, W) or (B, 1, H, W) with (H, W) = {(H, W)} and B = {B}"
        )
    check_finite(d, "depth")
    if bool((d.detach() < 0).any()):
        raise ValueError(f"depth must be >= 0 (0 = no surface, e.g. sky), got a minimum of {float(d.min()):.4g}")
    return d.detach().to(dtype=like.dtype, device=like.device).expand(B, 1, H, W)


def _jumps(a: torch.Tensor, b: torch.Tensor, threshold: float) -> torch.Tensor:
    """Whether neighbouring depths ``a``, ``b`` (same shape) are apart: one surface and one none, or a
    relative jump ``|a - b| / min(a, b)`` above ``threshold``."""
    sa, sb = a > 0, b > 0
    lo = torch.minimum(a, b)
    rel = (a - b).abs() > threshold * lo
    return (sa != sb) | (sa & sb & rel)


def depth_edges(depth: Array, threshold: float = DEPTH_EDGE_THRESHOLD) -> Array:
    """Pixels on a depth discontinuity.

    A pair of 4-neighbours ``p, q`` is a discontinuity when one has a surface and the other none
    (depth 0: sky), or both have one and ``|d_p - d_q| / min(d_p, d_q) > threshold``; both pixels
    of the pair are marked. The image border is not an edge.

    Args:
        depth: ``(H, W)``, ``(B, H, W)`` or ``(B, 1, H, W)`` z-depth, >= 0 (0 = no surface).
        threshold: relative jump, > 0 (default :data:`DEPTH_EDGE_THRESHOLD`).

    Returns:
        bool of ``depth``'s shape (numpy in, numpy out).
    """
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a finite number > 0, got {threshold!r}")
    d, restore = to_tensor(depth, "depth")
    if d.ndim not in (2, 3, 4) or (d.ndim == 4 and d.shape[1] != 1):
        raise ValueError(f"depth must be (H, W), (B, H, W) or (B, 1, H, W), got shape {tuple(d.shape)}")
    check_finite(d, "depth")
    if bool((d < 0).any()):
        raise ValueError(f"depth must be >= 0 (0 = no surface, e.g. sky), got a minimum of {float(d.min()):.4g}")
    d = d.detach()
    e = torch.zeros_like(d, dtype=torch.bool)
    h = _jumps(d[..., :, 1:], d[..., :, :-1], threshold)  # between columns j and j - 1
    v = _jumps(d[..., 1:, :], d[..., :-1, :], threshold)  # between rows i and i - 1
    e[..., :, 1:] |= h
    e[..., :, :-1] |= h
    e[..., 1:, :] |= v
    e[..., :-1, :] |= v
    return e if isinstance(depth, torch.Tensor) else e.numpy()


def edge_band(depth: Array, k: int = 2, threshold: float = DEPTH_EDGE_THRESHOLD) -> Array:
    """Pixels within ``k`` pixels (Chebyshev distance) of a :func:`depth_edges` pixel.

    Across a straight edge the band is ``2k + 2`` pixels wide (both pixels of the jump, and ``k`` more
    on each side). Shapes as :func:`depth_edges`; ``k`` an integer >= 0.
    """
    if isinstance(k, bool) or not isinstance(k, int) or k < 0:
        raise ValueError(f"k must be an integer >= 0, got {k!r}")
    e = torch.as_tensor(depth_edges(depth, threshold))
    if k == 0:
        band = e
    else:
        x = e.reshape(-1, 1, *e.shape[-2:]).float()
        band = (F.max_pool2d(x, 2 * k + 1, stride=1, padding=k) > 0.5).reshape(e.shape)
    return band if isinstance(depth, torch.Tensor) else band.numpy()


def edge_band_l1(pred: Array, target: Array, depth: Array, mask: Array | None = None, k: int = 2,
                 threshold: float = DEPTH_EDGE_THRESHOLD, reduction: str = "mean") -> Any:
    """L1 in a band of ``k`` pixels around depth discontinuities: the halo error of an upsampling.

    A relighting brought from a working resolution to full size by a ratio that does not follow the
    photo's edges is wrong in a band along object boundaries (a halo), and the band is a small share
    of the image, so the plain l1 barely sees it. This is :func:`l1` restricted to
    :func:`edge_band` ``(depth, k, threshold)`` and ``mask``.

    Args:
        pred: ``(B, C, H, W)`` or ``(C, H, W)``.
        target: same shape as ``pred``.
        depth: ``(H, W)``, ``(1, H, W)``, ``(B, H, W)``, ``(1, 1, H, W)`` or ``(B, 1, H, W)`` z-depth
            of the pixels, >= 0 with 0 = no surface (sky): a surface next to sky is an edge.
        mask: optional, see the module docstring (e.g. the foreground); the band is intersected with it.
        k: band half-width in pixels, integer >= 0.
        threshold: relative depth jump of a discontinuity (:func:`depth_edges`).
        reduction: ``"mean"`` or ``"none"`` (``(B,)``).

    Returns:
        Per image the mean absolute error over channels and the band's (masked) pixels; **NaN for an
        image with no band pixel** (no depth edge, or none inside the mask): there is no halo to
        measure, which is not the same as none. ``"mean"`` averages the images that have a band
        (NaN when none has). Torch in, torch out (differentiable in ``pred``); numpy in, numpy/float out.

    Raises:
        ValueError: bad shapes (the message names them), NaN/inf, negative depth, bad mask, ``k`` or
            ``threshold``.
    """
    pair = _prepare(pred, target, mask, reduction)
    d = _prepare_depth(depth, pair.pred)
    band = edge_band(d, k, threshold).to(pair.pred.dtype)
    if pair.mask is not None:
        band = band * pair.mask
    count = band.sum(dim=(1, 2, 3))
    err = ((pair.pred - pair.target).abs() * band).sum(dim=(1, 2, 3))
    nan = torch.full_like(count, math.nan)
    per_image = torch.where(count > 0, err / (count.clamp_min(1) * pair.pred.shape[1]), nan)
    if reduction == "mean":
        has = count > 0
        out = per_image[has].mean() if bool(has.any()) else per_image.new_tensor(math.nan)
        return float(out) if pair.is_numpy else out
    return pair.restore(per_image)
