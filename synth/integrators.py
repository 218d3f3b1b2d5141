"""Custom Mitsuba integrators for the ground-truth buffers.

Mitsuba 3.9.1's ``aov`` integrator renders a nested integrator twice (DESIGN.md), so the
path-traced radiance is rendered by ``path`` alone and the buffers by two small
``mi.SamplingIntegrator`` subclasses written here:

* :class:`GBuffer` -- per sample: diffuse reflectance ``bsdf.eval_diffuse_reflectance``
  (0 for BSDFs without a diffuse lobe), the shading normal flipped to face the ray, the
  hit position, a hit flag and a glossy flag (BSDF with a glossy lobe). The
  film averages samples over the pixel (box filter), so dividing by the hit flag gives
  the surface-only average (albedo is not darkened by sky at silhouettes).
* :class:`Shadow` -- per sample: the visible fraction of the sun disk (one uniformly
  sampled direction inside the cone per sample, ``scene.ray_test``), and the two sums
  of the direct-light shadow ratio ``int V L cos / int L cos`` over all emitters, with
  Mitsuba's emitter importance sampling (a ratio estimator: exactly 1 on unoccluded
  points), plus the hit flag.

Both output only AOV channels; the colour output is zero.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from synth.backend import load_mitsuba

mi = load_mitsuba()
import drjit as dr  # noqa: E402  (after mitsuba's variant is set)

GBUFFER_CHANNELS = ("albedo.R", "albedo.G", "albedo.B", "nx", "ny", "nz", "px", "py", "pz", "hit", "glossy")
SHADOW_CHANNELS = ("sun_visible", "direct_num", "direct_den", "hit")


class GBuffer(mi.SamplingIntegrator):
    """Albedo, normal (world), position (world) and hit flag per sample."""

    def __init__(self, props: Any) -> None:
        super().__init__(props)

    def aov_names(self) -> list[str]:
        return list(GBUFFER_CHANNELS)

    def sample(self, scene, sampler, ray, medium=None, active=True):  # noqa: ANN001 - Mitsuba signature
        si = scene.ray_intersect(ray, active)
        hit = si.is_valid()
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        diffuse = mi.has_flag(flags, mi.BSDFFlags.DiffuseReflection)
        glossy = hit & mi.has_flag(flags, mi.BSDFFlags.GlossyReflection)
        # eval_diffuse_reflectance is the albedo of diffuse and rough-plastic BSDFs; a
        # conductor has no diffuse lobe (Mitsuba returns a meaningless value: 6x the
        # tint for GGX alpha 0.2), so its albedo is 0 and it is flagged glossy.
        albedo = dr.select(hit & diffuse, bsdf.eval_diffuse_reflectance(si, hit & diffuse), 0.0)
        n = si.sh_frame.n
        # One-sided meshes seen from behind: report the normal that faces the camera.
        n = dr.select(dr.dot(n, -ray.d) < 0, -n, n)
        n = dr.select(hit, n, 0.0)
        p = dr.select(hit, si.p, 0.0)
        h = dr.select(hit, 1.0, 0.0)
        g = dr.select(glossy, 1.0, 0.0)
        aovs = [albedo[0], albedo[1], albedo[2], n[0], n[1], n[2], p[0], p[1], p[2], h, g]
        return mi.Spectrum(0.0), True, aovs


class Shadow(mi.SamplingIntegrator):
    """Sun-disk visibility and the direct-light shadow ratio's two sums, per sample.

    Attributes set after construction (see :func:`shadow_integrator`): ``sun_direction``
    (world, towards the sun; ``None`` for no sun) and ``cos_radius`` (cosine of the
    disk's angular radius). Directions of the disk below the surface's horizon count as
    visible: that is attached shadow, which belongs to the shading term, not to s.
    """

    sun_direction: np.ndarray | None = None
    cos_radius: float = 1.0

    def __init__(self, props: Any) -> None:
        super().__init__(props)

    def aov_names(self) -> list[str]:
        return list(SHADOW_CHANNELS)

    def sample(self, scene, sampler, ray, medium=None, active=True):  # noqa: ANN001
        si = scene.ray_intersect(ray, active)
        hit = si.is_valid()
        n = si.sh_frame.n
        n = dr.select(dr.dot(n, -ray.d) < 0, -n, n)

        # Direct-light ratio int V L cos / int L cos with emitter sampling (Mitsuba's
        # importance sampling of the sky map and the sun): each sample adds Y(L cos / pdf)
        # to the denominator and, if unoccluded, to the numerator.
        ds, weight = scene.sample_emitter_direction(si, sampler.next_2d(hit), False, hit)
        cos = dr.maximum(dr.dot(ds.d, n), 0.0)
        lum = (0.2126 * weight[0] + 0.7152 * weight[1] + 0.0722 * weight[2]) * cos
        visible = ~scene.ray_test(si.spawn_ray_to(ds.p), hit & (cos > 0))
        num = dr.select(hit & visible, lum, 0.0)
        den = dr.select(hit, lum, 0.0)

        sun = dr.select(hit, 1.0, 0.0)
        if self.sun_direction is not None:
            s = mi.Vector3f(*[float(v) for v in self.sun_direction])
            wsun = mi.Frame3f(s).to_world(mi.warp.square_to_uniform_cone(sampler.next_2d(hit), self.cos_radius))
            facing = dr.dot(wsun, n) > 0
            blocked = scene.ray_test(si.spawn_ray(wsun), hit & facing)
            sun = dr.select(hit & facing & blocked, 0.0, sun)
        h = dr.select(hit, 1.0, 0.0)
        return mi.Spectrum(0.0), True, [sun, num, den, h]


def _register() -> None:
    mi.register_integrator("physrelight_gbuffer", lambda props: GBuffer(props))
    mi.register_integrator("physrelight_shadow", lambda props: Shadow(props))


_register()


def shadow_integrator(sun_direction: np.ndarray | None, sun_radius_deg: float) -> Shadow:
    """A :class:`Shadow` integrator for one lighting."""
    integ = mi.load_dict({"type": "physrelight_shadow"})
    integ.sun_direction = None if sun_direction is None else np.asarray(sun_direction, dtype=np.float64)
    integ.cos_radius = math.cos(math.radians(max(sun_radius_deg, 1e-4)))
    return integ


def gbuffer_integrator() -> GBuffer:
    """A :class:`GBuffer` integrator."""
    return mi.load_dict({"type": "physrelight_gbuffer"})
