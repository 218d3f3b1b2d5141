"""The target's sky as the photo's camera sees it: what replaces a relit photo's sky.

An env-map or sun target says what its sky looks like (:func:`target_sky`); any target's order-2 SH implies a sky
through the fitted outdoor sky model (:func:`fitted_sky`). Both come in the target's units, ``(H, W, 3)``, one ray
per pixel of a pinhole camera (``K (3, 3)``, ``world_to_camera`` ``(4, 4)`` or ``(3, 3)``).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

from physrelight.sky_model import FIT_GLOW_EXPONENT, horizon_clamped, sun_disc
from physrelight.target_lighting import (clear_sky_sun, overcast_level, read_target, rotate_azimuth, sky_map_kind,
                                         sun_rgb, target_lighting, turned_camera)

__all__ = ["SKY_RENDERINGS", "fitted_sky", "rendered_sky", "target_sky"]


def target_sky(target: Any, K: Any, world_to_camera: Any, height: int, width: int, sky: str = "clear",
               azimuth_deg: float = 0.0) -> torch.Tensor:
    """``(height, width, 3)`` the target's own sky as the photo's camera sees it (target units).

    An env map is looked up through the pinhole camera (``K``, ``world_to_camera``) by
    :func:`physrelight.panorama.view`, one ray per pixel, bilinearly where a pixel covers a texel or more
    and by the smooth cubic B-spline where the view magnifies the map
    (:func:`physrelight.panorama.texel_magnification` above 1: a 640-px photo at 60 degrees sees a 1024-wide
    map's texel over 3.4 pixels), so a bright texel is not drawn as a clipped square. A sun target's sky is
    evaluated along each ray (:func:`physrelight.sky_model.sunsky_radiance`, or the CIE overcast sky at
    :func:`physrelight.target_lighting.sun_sky_map`'s level), smooth at any resolution, plus the sun's disc for a
    clear sky (radius :data:`physrelight.sky_model.SUN_RADIUS_DEG`, luminance 1, the sun's colour).
    ``azimuth_deg`` turns the target clockwise seen from above as :func:`physrelight.target_lighting.rotate_azimuth`
    does (the camera is turned the other way, :func:`physrelight.target_lighting.turned_camera`).

    Raises:
        ValueError: an SH target (it has no sky to render).
    """
    from physrelight import envmap, panorama

    kind = sky_map_kind(target)
    if kind == "sh":
        raise ValueError("an SH target has no sky to render: use sky source 'fit', 'gan' or 'keep'")
    target = read_target(target)  # a Sun as its direction; a map's path read
    R = turned_camera(world_to_camera, azimuth_deg)
    if kind == "env":
        env = envmap.read(target) if isinstance(target, (str, os.PathLike)) else np.asarray(target)
        smooth = panorama.texel_magnification(K, env.shape[1]) > 1.0
        return torch.as_tensor(panorama.view(torch.as_tensor(env, dtype=torch.float32), K, R, height, width, 1,
                                             interpolation="bspline" if smooth else "bilinear"))
    if sky == "overcast":
        from physrelight.sky_model import overcast_sky

        def strip(rows: slice) -> torch.Tensor:
            d = horizon_clamped(panorama.pixel_rays(K, R, height, width, rows)).numpy()
            return torch.from_numpy(overcast_sky(d) * overcast_level()).float()[..., None].expand(-1, -1, 3)

        return _by_strips(strip, height)
    # the clear sky along each ray itself (not through a lat-long map): smooth at any resolution
    from physrelight.sky_model import sunsky_radiance

    d = clear_sky_sun(target)
    rgb = torch.from_numpy(sun_rgb(d))

    def clear(rows: slice) -> torch.Tensor:
        rays = horizon_clamped(panorama.pixel_rays(K, R, height, width, rows))
        out = torch.from_numpy(sunsky_radiance(rays.numpy(), d)).float()  # rays: float64
        return out + (sun_disc(rays, d)[..., None] * rgb).to(out.dtype)

    return _by_strips(clear, height)


STRIP_ROWS = 64
"""Rows of a model sky evaluated together (:func:`_by_strips`); fixed, so the numbers do not depend on the threads."""


def _by_strips(fn: Any, height: int) -> torch.Tensor:
    """``fn(rows)`` (an ``(h, W, 3)`` image of those rows) for strips of :data:`STRIP_ROWS` rows on torch's threads
    (:func:`physrelight.parallel.thread_map`; numpy and torch release the GIL), stacked: ``(height, W, 3)``. Every pixel
    is evaluated alone, so the image is the one ``fn(slice(None))`` gives, at any thread count (12 MP: the clear sky
    took 3.4 s on one thread in one piece)."""
    from physrelight.parallel import fixed_strips, thread_map

    parts = thread_map(fn, [slice(a, b) for a, b in fixed_strips(height, STRIP_ROWS)])
    return torch.cat(parts, dim=0).contiguous()


def fitted_sky(coeffs: Any, K: Any, world_to_camera: Any, height: int, width: int,
               glow_exponent: float = FIT_GLOW_EXPONENT) -> torch.Tensor:
    """``(height, width, 3)`` the sky implied by world-frame order-2 SH ``coeffs (9, 3)`` as the photo's
    camera (``K``, ``world_to_camera``) sees it, in the coefficients' units: the outdoor sky model
    fitted to them (:func:`physrelight.sky_model.fit_sky`), one ray per pixel
    (:func:`physrelight.sky_model.sky_view`). Smooth by construction."""
    from physrelight import panorama
    from physrelight.sky_model import fit_sky, sky_view

    fit = fit_sky(coeffs, glow_exponent)

    def strip(rows: slice) -> torch.Tensor:
        return sky_view(fit, panorama.pixel_rays(K, world_to_camera, height, width, rows)[..., None, :]).float()

    return _by_strips(strip, height)


SKY_RENDERINGS = ("target", "fit")


def rendered_sky(source: str, target: Any, K: Any, world_to_camera: Any, height: int, width: int,
                 sky: str = "clear", azimuth_deg: float = 0.0) -> torch.Tensor:
    """``(height, width, 3)`` a relit photo's new sky rendered from its target (target units): ``source``
    ``"target"``, the target's own sky (:func:`target_sky`; an env map or a sun direction), or ``"fit"``, the sky
    model fitted to the target's world-frame SH (:func:`fitted_sky`; any target), the target turned by
    ``azimuth_deg`` (clockwise seen from above, :func:`physrelight.target_lighting.rotate_azimuth`) either way."""
    if source not in SKY_RENDERINGS:
        raise ValueError(f"a rendered sky's source must be one of {SKY_RENDERINGS}, got {source!r}")
    if source == "target":
        return target_sky(target, K, world_to_camera, height, width, sky, azimuth_deg)
    turned = rotate_azimuth(target, azimuth_deg) if azimuth_deg else target
    return fitted_sky(target_lighting(turned, None, sky), K, world_to_camera, height, width)
