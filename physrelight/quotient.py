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

Shapes: ``image (B, 3, H, W)`` linear, ``normals (B, 3, H, W)`` camera frame, lightings
``(B, 9, 3)`` radiance SH in the same frame and units, shadows ``(B, 1, H, W)`` in [0, 1] (None = 1),
``mask (B, 1, H, W)`` bool (True = foreground; the guard's mean is taken there).
"""

from __future__ import annotations

import torch

from physrelight import image_model

__all__ = ["DEFAULT_GUARD", "quotient_ratio", "quotient_relight"]

DEFAULT_GUARD = 0.05


def _shaded(normals: torch.Tensor, lighting: torch.Tensor, shadow: torch.Tensor | None) -> torch.Tensor:
    s = image_model.shading(normals, lighting).clamp_min(0.0)
    return s if shadow is None else s * shadow.clamp(0.0, 1.0)


def quotient_ratio(normals: torch.Tensor, source: torch.Tensor, target: torch.Tensor,
                   mask: torch.Tensor | None = None, source_shadow: torch.Tensor | None = None,
                   target_shadow: torch.Tensor | None = None, guard: float = DEFAULT_GUARD) -> torch.Tensor:
    """``(B, 3, H, W)`` the guarded ratio ``(s_t S_t + g) / (s_s S_s + g)`` per colour channel.

    ``g`` is ``guard`` times the mean of ``s_s S_s`` over ``mask`` (every pixel when None or
    empty), per image and channel. Raises ``ValueError`` for bad shapes or a non-positive guard.
    """
    if normals.ndim != 4 or normals.shape[1] != 3:
        raise ValueError(f"normals must have shape (B, 3, H, W), got {tuple(normals.shape)}")
    b = normals.shape[0]
    for name, L in (("source", source), ("target", target)):
        if L.shape != (b, 9, 3):
            raise ValueError(f"{name} lighting must have shape ({b}, 9, 3), got {tuple(L.shape)}")
    if not guard > 0:
        raise ValueError(f"guard must be positive, got {guard!r}")
    s_src = _shaded(normals, source, source_shadow)
    s_tgt = _shaded(normals, target, target_shadow)
    if mask is None:
        mean = s_src.mean((2, 3), keepdim=True)
    else:
        m = mask.to(s_src.dtype)
        count = m.sum((2, 3), keepdim=True)
        mean = torch.where(count > 0, (s_src * m).sum((2, 3), keepdim=True) / count.clamp_min(1),
                           s_src.mean((2, 3), keepdim=True))
    g = (guard * mean).clamp_min(torch.finfo(s_src.dtype).tiny)
    return (s_tgt + g) / (s_src + g)


def quotient_relight(image: torch.Tensor, normals: torch.Tensor, source: torch.Tensor, target: torch.Tensor,
                     mask: torch.Tensor | None = None, source_shadow: torch.Tensor | None = None,
                     target_shadow: torch.Tensor | None = None, guard: float = DEFAULT_GUARD) -> torch.Tensor:
    """``(B, 3, H, W)`` the photo relit by :func:`quotient_ratio` (``image * ratio``)."""
    if image.shape != normals.shape:
        raise ValueError(f"image {tuple(image.shape)} and normals {tuple(normals.shape)} must have the same shape")
    return image * quotient_ratio(normals, source, target, mask, source_shadow, target_shadow, guard)
