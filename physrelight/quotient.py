"""Quotient relighting: the photo times the ratio of target to source shading.

Under the image model ``i = s * albedo * shading(n; L)`` (:mod:`physrelight.image_model`) the
photo relit to a lighting ``L_t`` with shadow ``s_t`` is

    relit = i * (s_t * shading(n; L_t)) / (s_s * shading(n; L_s)),

from one set of normals ``n``. Dividing by the photo's own shading keeps its albedo, texture
and fine detail exactly: nothing is re-synthesised from a predicted albedo. The ratio is
guarded where the source shading is small (a back-facing normal, an umbra): both shadings get
``guard`` times the foreground mean of the source shading added, so the ratio is

* exactly 1 when the target is the source (the photo comes back bit for bit);
* invariant to the albedo/lighting scale (scaling both lightings by ``k`` scales the guard too);
* bounded where the source shading vanishes.

Sun-only shadows. A sun visibility ``v`` (synth's ``shadow.exr``, or
:func:`physrelight.screen_space_shadow.sun_visibility`) belongs to the sun's light only: the sky
still lights an umbra. With ``source_sun`` / ``target_sun``, the SH of the sun's part of each
lighting, a given shadow multiplies that part only, as ``oracle_sh_shadow`` does:

    shaded = shading(n; L - L_sun) + v * shading(n; L_sun)    (clamped at 0),

so the denominator removes the photo's own sun shadows and the numerator casts the target's. With
``sun_cosine`` the sun's part is shaded exactly, ``E max(0, n . s) / pi``, rather than by its
order-2 SH (which rings: a sun is one direction, so "no more than the scene needs" is the exact
term plus an order-2 sky). Without
a sun part (None) a shadow multiplies the whole shading, as before; without a shadow the sun part is
ignored and the shading is exactly the unsplit one.

Smoothing the ratio. The ratio is a function of the estimated normals, whose errors vary from pixel to
pixel; the true ratio is smooth within a surface and changes at its edges. With ``smooth_radius > 0``,
:func:`quotient_relight` replaces the log ratio by its guided filter (:func:`physrelight.guided_filter.guided_filter`)
with the photo's log luminance as the guide, so it is averaged within surfaces and kept at the photo's edges.
A ratio of 1 stays exactly 1 (the filter of zeros is zeros) and a gain on the photo shifts the guide only,
which the filter ignores. Chosen on ``data/val5`` (radius 3, ``eps`` 1e-3 in log units squared) and
confirmed on ``data/heldout`` (known-track l1 -0.0013 [-0.0018, -0.0009]; docs/experiments/27-known-track-budget.md).

Shapes: ``image (B, 3, H, W)`` linear, ``normals (B, 3, H, W)`` camera frame, lightings
``(B, 9, 3)`` radiance SH in the same frame and units, shadows ``(B, 1, H, W)`` in [0, 1] (None = 1),
``mask (B, 1, H, W)`` bool (True = foreground; the guard's mean is taken there), sun parts
``(B, 9, 3)`` in the lightings' frame and units (None = the shadow applies to all the light).
"""

from __future__ import annotations

import torch

from physrelight import image_model
from physrelight.colour import LUMINANCE
from physrelight.guided_filter import guided_filter

__all__ = ["DEFAULT_GUARD", "SMOOTH_EPS", "SMOOTH_RADIUS", "quotient_ratio", "quotient_relight", "smooth_ratio"]

DEFAULT_GUARD = 0.05
SMOOTH_RADIUS = 3
"""The guided filter's radius (px at the working resolution) that relighting uses for the ratio."""
SMOOTH_EPS = 1e-3
"""The guided filter's ridge, in (log luminance)^2: guide variation well below it is smoothed over."""


def _shaded(normals: torch.Tensor, lighting: torch.Tensor, shadow: torch.Tensor | None,
            sun: torch.Tensor | None = None, sun_cosine: bool = False) -> torch.Tensor:
    if sun is not None and sun_cosine:  # the sun's exact clamped cosine, the rest in SH
        direct = image_model.sun_shading(normals, sun)
        if shadow is not None:
            direct = shadow.clamp(0.0, 1.0) * direct
        return (image_model.shading(normals, lighting - sun) + direct).clamp_min(0.0)
    if shadow is not None and sun is not None:  # the shadow dims the sun's light only
        sky = image_model.shading(normals, lighting - sun)
        return (sky + shadow.clamp(0.0, 1.0) * image_model.shading(normals, sun)).clamp_min(0.0)
    s = image_model.shading(normals, lighting).clamp_min(0.0)
    return s if shadow is None else s * shadow.clamp(0.0, 1.0)


def _check_shadow(name: str, shadow: torch.Tensor | None, b: int, hw: tuple[int, ...]) -> None:
    if shadow is not None and tuple(shadow.shape) != (b, 1, *hw):
        raise ValueError(f"{name} must have shape ({b}, 1, {hw[0]}, {hw[1]}), got {tuple(shadow.shape)}")


def quotient_ratio(normals: torch.Tensor, source: torch.Tensor, target: torch.Tensor,
                   mask: torch.Tensor | None = None, source_shadow: torch.Tensor | None = None,
                   target_shadow: torch.Tensor | None = None, guard: float = DEFAULT_GUARD, *,
                   source_sun: torch.Tensor | None = None, target_sun: torch.Tensor | None = None,
                   sun_cosine: bool = False) -> torch.Tensor:
    """``(B, 3, H, W)`` the guarded ratio ``(s_t S_t + g) / (s_s S_s + g)`` per colour channel.

    ``g`` is ``guard`` times the mean of ``s_s S_s`` over ``mask`` (every pixel when None or
    empty), per image and channel. With ``source_sun`` / ``target_sun`` ``(B, 9, 3)`` (the sun's
    part of each lighting) a given shadow multiplies that part only (the module doc); with
    ``sun_cosine`` that part is shaded by the sun's exact clamped cosine
    (:func:`physrelight.image_model.sun_shading`) instead of its order-2 SH. Raises
    ``ValueError`` for bad shapes or a non-positive guard.
    """
    if normals.ndim != 4 or normals.shape[1] != 3:
        raise ValueError(f"normals must have shape (B, 3, H, W), got {tuple(normals.shape)}")
    b = normals.shape[0]
    for name, L in (("source", source), ("target", target)):
        if L.shape != (b, 9, 3):
            raise ValueError(f"{name} lighting must have shape ({b}, 9, 3), got {tuple(L.shape)}")
    for name, L in (("source_sun", source_sun), ("target_sun", target_sun)):
        if L is not None and L.shape != (b, 9, 3):
            raise ValueError(f"{name} must have shape ({b}, 9, 3), got {tuple(L.shape)}")
    if source_sun is not None or target_sun is not None:  # the old path never checked the shadows' shape
        _check_shadow("source_shadow", source_shadow, b, normals.shape[-2:])
        _check_shadow("target_shadow", target_shadow, b, normals.shape[-2:])
    if not guard > 0:
        raise ValueError(f"guard must be positive, got {guard!r}")
    s_src = _shaded(normals, source, source_shadow, source_sun, sun_cosine)
    s_tgt = _shaded(normals, target, target_shadow, target_sun, sun_cosine)
    if mask is None:
        mean = s_src.mean((2, 3), keepdim=True)
    else:
        m = mask.to(s_src.dtype)
        count = m.sum((2, 3), keepdim=True)
        mean = torch.where(count > 0, (s_src * m).sum((2, 3), keepdim=True) / count.clamp_min(1),
                           s_src.mean((2, 3), keepdim=True))
    g = (guard * mean).clamp_min(torch.finfo(s_src.dtype).tiny)
    return (s_tgt + g) / (s_src + g)


def smooth_ratio(image: torch.Tensor, ratio: torch.Tensor, radius: int = SMOOTH_RADIUS,
                 eps: float = SMOOTH_EPS) -> torch.Tensor:
    """``(B, 3, H, W)`` the ratio with its log guided-filtered by the log luminance of ``image (B, 3, H, W)``.

    ``radius == 0`` returns ``ratio`` itself. A ratio of exactly 1 comes back exactly 1, and scaling
    ``image`` by a gain does not change the result. Raises ``ValueError`` for a negative radius, a
    non-positive ``eps`` or mismatched shapes.
    """
    if radius < 0 or int(radius) != radius:
        raise ValueError(f"radius must be a non-negative integer, got {radius!r}")
    if ratio.shape != image.shape:
        raise ValueError(f"ratio {tuple(ratio.shape)} and image {tuple(image.shape)} must have the same shape")
    if radius == 0:
        return ratio
    if not eps > 0:
        raise ValueError(f"eps must be positive, got {eps!r}")
    w = torch.tensor(LUMINANCE, dtype=image.dtype, device=image.device).view(1, 3, 1, 1)
    y = (image.clamp_min(0.0) * w).sum(1, keepdim=True)
    guide = torch.log(y.clamp_min(torch.finfo(image.dtype).tiny) + 1e-6 * y.mean((2, 3), keepdim=True))
    log_ratio = torch.log(ratio)
    if not bool(log_ratio.any()):  # relit to its own lighting: nothing to smooth, the photo comes back bit for bit
        return ratio
    return torch.exp(guided_filter(guide, log_ratio, int(radius), eps))


def quotient_relight(image: torch.Tensor, normals: torch.Tensor, source: torch.Tensor, target: torch.Tensor,
                     mask: torch.Tensor | None = None, source_shadow: torch.Tensor | None = None,
                     target_shadow: torch.Tensor | None = None, guard: float = DEFAULT_GUARD, *,
                     source_sun: torch.Tensor | None = None, target_sun: torch.Tensor | None = None,
                     sun_cosine: bool = False, smooth_radius: int = 0,
                     smooth_eps: float = SMOOTH_EPS) -> torch.Tensor:
    """``(B, 3, H, W)`` the photo relit by :func:`quotient_ratio` (``image * ratio``), the ratio
    smoothed by :func:`smooth_ratio` when ``smooth_radius > 0`` (0, the default here: the raw ratio)."""
    if image.shape != normals.shape:
        raise ValueError(f"image {tuple(image.shape)} and normals {tuple(normals.shape)} must have the same shape")
    ratio = quotient_ratio(normals, source, target, mask, source_shadow, target_shadow, guard,
                           source_sun=source_sun, target_sun=target_sun, sun_cosine=sun_cosine)
    return image * smooth_ratio(image, ratio, smooth_radius, smooth_eps)
