"""Render the ground truth of one scene: per view (geometry buffers) and per view x lighting
(path-traced radiance and shadows).

One Mitsuba scene is built per lighting with every view as a sensor, so its cost is
shared by the views. Three kinds of render:

* radiance: Mitsuba's ``path`` integrator alone (``max_depth`` bounces), HDR;
* geometry at pixel centres: rays built from our camera model (:func:`synth.cameras.camera_rays`)
  and intersected directly, so normals and depth are exactly those of the pixel centre
  and back-project onto the surface with ``K`` (no averaging across silhouettes);
* pixel-footprint averages with the small integrators of :mod:`synth.integrators`:
  albedo and coverage (anti-aliased like the radiance), sun visibility and the
  direct-light shadow ratio.

The sun is rendered as a directional (delta) light (:mod:`synth.lighting`), so the
shadow ground truth is the delta sun's visibility averaged over each pixel: exactly the
shadow present in the rendered radiance.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from physrelight.camera import Camera

from . import cameras as _cameras
from . import scene as _scene
from .backend import load_mitsuba
from .lighting import Lighting

mi = load_mitsuba()
import drjit as dr  # noqa: E402

from . import integrators  # noqa: E402  (registers the integrators)


@dataclass
class ViewBuffers:
    """Geometry of one view (independent of lighting).

    Attributes:
        albedo: ``(H, W, 3)`` diffuse reflectance averaged over the pixel's surface samples
            (anti-aliased like the radiance); 0 on sky pixels.
        normal: ``(H, W, 3)`` unit normal at the pixel centre, camera frame, facing the camera; 0 on sky.
        depth: ``(H, W)`` z-depth at the pixel centre; 0 on sky.
        sky_mask: ``(H, W)`` bool, True where the pixel-centre ray hits nothing.
        coverage: ``(H, W)`` fraction of the pixel footprint covered by surfaces.
        glossy: ``(H, W)`` fraction of the footprint on non-Lambertian materials
            (rough plastic, conductor; conductors have albedo 0).
    """

    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    sky_mask: np.ndarray
    coverage: np.ndarray
    glossy: np.ndarray


@dataclass
class LightBuffers:
    """One view under one lighting.

    Attributes:
        radiance: ``(H, W, 3)`` path-traced linear radiance (sky visible).
        sun_visibility: ``(H, W)`` fraction of the pixel's surface samples that see the
            sun (1 without a sun; 1 on sky).
        direct_shadow: ``(H, W)`` ``int V L cos / int L cos`` over the environment (1 on sky).
        shadow: ``sun_visibility`` when the lighting has a sun, else ``direct_shadow``.
    """

    radiance: np.ndarray
    sun_visibility: np.ndarray
    direct_shadow: np.ndarray
    shadow: np.ndarray


@dataclass
class Timer:
    """Seconds spent per phase (for the cost split in the benchmarks)."""

    seconds: dict[str, float] = field(default_factory=dict)

    def add(self, key: str, t0: float) -> None:
        self.seconds[key] = self.seconds.get(key, 0.0) + time.perf_counter() - t0


def build_scene(spec: _scene.SceneSpec, views: list[Camera], lighting: Lighting, spp: int, max_depth: int = 8,
                seed: int = 0) -> Any:
    """A Mitsuba scene: the shapes, one sensor per view, the lighting's emitters and a
    ``path`` integrator with ``max_depth`` (so ``mi.render(scene, sensor=i)`` is the radiance)."""
    d: dict[str, Any] = {"type": "scene", **_scene.to_mitsuba(spec, mi), **lighting.mitsuba_emitters(mi),
                         "integrator": {"type": "path", "max_depth": int(max_depth)}}
    for i, cam in enumerate(views):
        d[f"view_{i:02d}"] = _cameras.to_mitsuba_sensor(cam, spp, mi, seed=seed + i)
    return mi.load_dict(d)


def _film(scene: Any, integrator: Any, index: int | Any, spp: int, seed: int) -> np.ndarray:
    img = mi.render(scene, integrator=integrator, sensor=index, spp=spp, seed=seed)
    return np.array(img, dtype=np.float64)


def render_geometry(scene: Any, index: int | Any, camera: Camera, spp: int, seed: int) -> ViewBuffers:
    """Geometry buffers of view ``index`` (see :class:`ViewBuffers`); ``index`` may also be a Mitsuba
    sensor that is not the scene's (it must match ``camera``, as :func:`render_geometry_scaled` makes)."""
    h, w = camera.height, camera.width
    o, d = _cameras.camera_rays(camera)
    ray = mi.Ray3f(mi.Point3f(*[o[:, k].astype(np.float32) for k in range(3)]),
                   mi.Vector3f(*[d[:, k].astype(np.float32) for k in range(3)]))
    si = scene.ray_intersect(ray)
    hit = np.array(si.is_valid(), dtype=bool).reshape(h, w)
    n_world = np.stack([np.array(si.sh_frame.n[k], dtype=np.float64) for k in range(3)], axis=-1)
    p_world = np.stack([np.array(si.p[k], dtype=np.float64) for k in range(3)], axis=-1)
    facing = np.sum(n_world * d, axis=-1) > 0  # seen from behind: flip to face the camera
    n_world[facing] *= -1
    T = np.asarray(camera.world_to_camera, dtype=np.float64)
    n_cam = n_world @ T[:3, :3].T
    n_cam /= np.maximum(np.linalg.norm(n_cam, axis=-1, keepdims=True), 1e-12)
    p_cam = p_world @ T[:3, :3].T + T[:3, 3]
    normal = np.where(hit[..., None], n_cam.reshape(h, w, 3), 0.0)
    depth = np.where(hit, -p_cam[:, 2].reshape(h, w), 0.0)

    g = _film(scene, integrators.gbuffer_integrator(), index, spp, seed)
    cov = g[..., 3 + integrators.GBUFFER_CHANNELS.index("hit")]
    albedo = g[..., 3:6] / np.maximum(cov, 1e-12)[..., None]
    albedo = np.where(((cov > 0) & hit)[..., None], albedo, 0.0)  # sky pixels carry no albedo
    glossy = g[..., 3 + integrators.GBUFFER_CHANNELS.index("glossy")]
    return ViewBuffers(albedo=albedo.astype(np.float32), normal=normal.astype(np.float32),
                       depth=depth.astype(np.float32), sky_mask=~hit, coverage=cov.astype(np.float32),
                       glossy=glossy.astype(np.float32))


def render_geometry_scaled(scene: Any, camera: Camera, scale: int, spp: int, seed: int) -> ViewBuffers:
    """Geometry buffers of ``camera`` at ``scale`` times its resolution (:func:`synth.cameras.scaled_camera`),
    from a sensor of its own: what MVS depth at a multiple of the photo's resolution is degraded from."""
    fine = _cameras.scaled_camera(camera, scale)
    sensor = mi.load_dict(_cameras.to_mitsuba_sensor(fine, spp, mi, seed=seed))
    return render_geometry(scene, sensor, fine, spp, seed)


def render_radiance(scene: Any, index: int, spp: int, seed: int) -> np.ndarray:
    """``(H, W, 3)`` float32 radiance of view ``index`` by the scene's ``path`` integrator (no shadow
    buffers: what :func:`render_lit` renders first, with the same seed the same pixels)."""
    return _film(scene, scene.integrator(), index, spp, seed).astype(np.float32)


def render_lit(scene: Any, index: int, lighting: Lighting, spp: int, shadow_spp: int, seed: int,
               timer: Timer | None = None) -> LightBuffers:
    """Radiance (the scene's ``path`` integrator) and shadows of view ``index`` (see :class:`LightBuffers`)."""
    timer = timer or Timer()
    t0 = time.perf_counter()
    radiance = render_radiance(scene, index, spp, seed)
    timer.add("path", t0)

    t0 = time.perf_counter()
    # Rendered sun is a delta: its visibility is the shadow of the rendered image. Without
    # a sun the shadow is the direct-light ratio over the whole sky, whose visibility
    # varies over the hemisphere: 4x the samples keep its noise near the sun case's.
    shadow_integ = integrators.shadow_integrator(lighting.sun_direction, 0.0)
    spp_s = shadow_spp if lighting.has_sun else 4 * shadow_spp
    s = _film(scene, shadow_integ, index, spp_s, seed + 7919)
    names = integrators.SHADOW_CHANNELS
    cov = s[..., 3 + names.index("hit")]
    sun = np.where(cov > 0, s[..., 3 + names.index("sun_visible")] / np.maximum(cov, 1e-12), 1.0)
    num, den = s[..., 3 + names.index("direct_num")], s[..., 3 + names.index("direct_den")]
    direct = np.where(den > 0, num / np.maximum(den, 1e-30), 1.0)
    timer.add("shadow", t0)
    sun, direct = np.clip(sun, 0, 1), np.clip(direct, 0, 1)
    return LightBuffers(radiance=radiance.astype(np.float32), sun_visibility=sun.astype(np.float32),
                        direct_shadow=direct.astype(np.float32),
                        shadow=(sun if lighting.has_sun else direct).astype(np.float32))
