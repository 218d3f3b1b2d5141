"""The photo's own lighting read from its sky, as the relighter divides by it (issue 44).

:func:`read_sky_lighting` runs :func:`physrelight.sun_from_sky.estimate_sun_from_sky` on a photo's sky through its
camera and decides whether the reading is informative: a sun, and its 90 % credible region at most
:data:`MAX_INFORMATIVE_AREA_SR`. Then (``source == "sky"``) the MAP sky and sun, with a ground that reflects them
(:func:`sky_sun_sh`), are the photo's lighting; otherwise (``"fallback"``: no sky, night, overcast, blown out, a sky
the model cannot draw, a sun not seen where the fit puts it, a sun the sky does not place) the caller keeps its own
estimate, the decomposition's.
``physrelight lighting`` (``lighting.json``), ``relight --layers`` and ``Relighter``
(:attr:`learned.relight_options.RelightOptions.source_estimate`) all read the sky through this one function, so they
agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from physrelight import sh
from physrelight.sun_from_sky import SunPosterior, estimate_sun_from_sky

__all__ = ["GROUND_ALBEDO", "MAX_INFORMATIVE_AREA_SR", "SkyLighting", "read_sky_lighting", "sky_sun_sh"]

MAX_INFORMATIVE_AREA_SR = math.pi
"""A posterior with a sun whose 90 % credible region is wider than this (a quarter of the sphere, half the sky)
says there is a sun but not where: the reading falls back to the library's estimate (the flat prior's region is
5.45 sr; the training panoramas' forest crops, 2-31 % sky among trees, give 2-5.4 sr)."""
GROUND_ALBEDO = 0.2
"""The diffuse reflectance of the ground that :func:`sky_sun_sh` puts below the horizon: the sky says nothing of
the ground, and a black one leaves walls without the light the ground throws back (chosen on the training
panoramas' crops: docs/experiments/61-sun-in-relighter.md)."""


@dataclass(frozen=True)
class SkyLighting:
    """What the sky of one photo says of its lighting (:func:`read_sky_lighting`).

    Attributes:
        posterior: the sun's posterior (:class:`physrelight.sun_from_sky.SunPosterior`).
        source: ``"sky"`` (the posterior is informative: ``sh_world`` is the photo's lighting) or ``"fallback"``.
        reason: why the fallback (``""`` with ``"sky"``).
        sh_world: ``(9, 3)`` order-2 radiance SH (world frame, the photo's linear units) of the MAP sky, its sun
            and a ground (:func:`sky_sun_sh`); None with ``"fallback"``.
        sun_world: ``(9, 3)`` the sun's part of ``sh_world`` (:func:`physrelight.sh.project_sun`); None with
            ``"fallback"``.
    """

    posterior: SunPosterior
    source: str
    reason: str
    sh_world: np.ndarray | None
    sun_world: np.ndarray | None

    def camera(self, world_to_camera: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(sh (9, 3), sun (9, 3))`` turned into the camera frame by ``world_to_camera`` ``(3, 3)`` or ``(4, 4)``
        (``D(R) L``, DESIGN.md). Raises ``ValueError`` with ``"fallback"`` (nothing was read)."""
        if self.source != "sky":
            raise ValueError(f"the sky was not read ({self.reason}): there is no sky lighting to turn")
        D = np.asarray(sh.rotation(_rotation(world_to_camera), order=2))
        return D @ self.sh_world, D @ self.sun_world


def _rotation(world_to_camera: Any) -> np.ndarray:
    R = np.asarray(world_to_camera.detach().cpu() if isinstance(world_to_camera, torch.Tensor) else world_to_camera,
                   dtype=np.float64)
    if R.shape == (4, 4):
        R = R[:3, :3]
    if R.shape != (3, 3):
        raise ValueError(f"world_to_camera must have shape (3, 3) or (4, 4), got {R.shape}")
    return R


def sky_sun_sh(posterior: SunPosterior, ground_albedo: float = GROUND_ALBEDO) -> tuple[np.ndarray, np.ndarray]:
    """``(sh (9, 3), sun (9, 3))`` world-frame order-2 radiance SH of a posterior's MAP: its sky
    (:meth:`SunPosterior.envmap`, 64 x 128), its sun (:meth:`SunPosterior.sun_irradiance` as a delta) and, below the
    horizon, a uniform Lambertian ground of reflectance ``ground_albedo`` lit by both (radiance
    ``ground_albedo * E_up / pi``, ``E_up`` the irradiance on a surface facing up). ``ground_albedo = 0`` gives
    :meth:`SunPosterior.sh` (a black ground).

    Raises:
        ValueError: the posterior has no sun, or ``ground_albedo`` is not in [0, 1].
    """
    from physrelight.envmap import directions, solid_angles

    if not posterior.has_sun:
        raise ValueError(f"no sun was read from this sky ({posterior.reason})")
    if not (isinstance(ground_albedo, (int, float)) and 0.0 <= ground_albedo <= 1.0):
        raise ValueError(f"ground_albedo must lie in [0, 1], got {ground_albedo!r}")
    env = posterior.envmap(64).astype(np.float64)  # black below the horizon
    sun_irr = np.asarray(posterior.sun_irradiance(), dtype=np.float64)
    d = directions(*env.shape[:2]).astype(np.float64)
    dw = np.asarray(solid_angles(*env.shape[:2]), dtype=np.float64)
    e_up = (env * (np.clip(d[..., 1], 0.0, None) * dw)[..., None]).sum((0, 1))
    e_up = e_up + sun_irr * max(0.0, float(posterior.sun_direction[1]))
    env = np.where(d[..., 1:2] < 0, ground_albedo * e_up / math.pi, env)
    sun = np.asarray(sh.project_sun(posterior.sun_direction, sun_irr, order=2), dtype=np.float64)
    return np.asarray(sh.project_envmap(env, order=2), dtype=np.float64) + sun, sun


def read_sky_lighting(lin: torch.Tensor, sky: torch.Tensor, K: Any, world_to_camera: Any, *,
                      radiance: bool = False) -> SkyLighting:
    """The sun and sky read from one photo through its camera.

    Args:
        lin: ``(1, 3, H, W)`` the photo as the relighter has it: display values sRGB-decoded, or with ``radiance``
            a radiance photo at its display-like level (:func:`physrelight.image_input.as_radiance`).
        sky: ``(1, 1, H, W)`` or ``(H, W)`` bool (torch or numpy), True on sky.
        K: ``(3, 3)`` intrinsics; ``world_to_camera``: ``(3, 3)`` or ``(4, 4)`` (the camera ``relight`` uses:
            :func:`physrelight.horizon.photo_camera`).
        radiance: ``lin`` is radiance: read as linear, with no night check and no clipping.

    Returns:
        :class:`SkyLighting`: ``"sky"`` when the posterior has a sun whose 90 % region is at most
        :data:`MAX_INFORMATIVE_AREA_SR`, else ``"fallback"`` with the reason.
    """
    from physrelight import colour

    if lin.ndim != 4 or lin.shape[:2] != (1, 3):
        raise ValueError(f"lin must have shape (1, 3, H, W), got {tuple(lin.shape)}")
    sky = torch.as_tensor(sky)
    mask = sky.reshape(lin.shape[-2:]) if sky.numel() == lin.shape[-2] * lin.shape[-1] else None
    if mask is None or sky.dtype != torch.bool:
        raise ValueError(f"sky must be a boolean mask of the photo's size {tuple(lin.shape[-2:])}, got "
                         f"{tuple(sky.shape)} {sky.dtype}")
    # a display photo is read as display values (its clipping and its night check are in those), the sRGB-decoded
    # linear values encoded again
    photo = lin[0] if radiance else colour.to_ldr(lin[0].clamp_min(0.0))
    post = estimate_sun_from_sky(photo.permute(1, 2, 0).double().numpy(), mask.numpy(), K, world_to_camera,
                                 linear=radiance)
    if post.has_sun and post.credible_area_sr <= MAX_INFORMATIVE_AREA_SR:
        sh_world, sun_world = sky_sun_sh(post)
        return SkyLighting(post, "sky", "", sh_world, sun_world)
    if post.has_sun:
        reason = (f"the sky shows a sun but not where: its 90 % credible region is {post.credible_area_sr:.2f} sr "
                  f"> {MAX_INFORMATIVE_AREA_SR:.2f} sr")
    else:
        reason = post.reason
    return SkyLighting(post, "fallback", reason, None, None)
