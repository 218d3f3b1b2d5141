"""Tiny hand-made scenes, the named lightings and the rendered scene bank of the checks.

* Builders of tiny :class:`synth.scene.SceneSpec` s with known geometry and albedo:
  :func:`sphere_spec`, :func:`box_spec`, :func:`convex_spec` (sphere, box, ellipsoid
  floating in the sky: convex, so every surface point sees the whole upper sky and no
  light bounces between surfaces), and :func:`view` (a look-at camera). The tests of
  :mod:`synth.render` use them too.
* :data:`LIGHTINGS` / :func:`get_lighting`: fixed, named lightings of every kind
  (sun and sky at three elevations, overcast, the shared HDRIs).
* :class:`SceneBank`: generated scenes (:func:`synth.scene.generate_scene`) rendered from
  a few views under a few lightings, each with several independent path-traced renders
  (full, up to 8 bounces, and direct light only), shadows, geometry, exact irradiance per
  pixel and a glossy variant. Checks 2-5 share it.

Conventions: world Y up; normals in ``ViewBuffers``/:class:`BankView` are camera frame
(x right, y up, z to the viewer) unless named ``*_world``; images ``(H, W, C)`` numpy.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from physrelight import camera as pcam
from synth import cameras as _cameras
from synth import lighting as _lighting
from synth import render as _render
from synth.backend import load_mitsuba
from synth.scene import Material, Part, SceneSpec, generate_scene

from .common import LUMINANCE, Context, Level

mi = load_mitsuba()

from synth import integrators as _integrators  # noqa: E402  (after the variant is set)

CONVEX_SHAPES = ("sphere", "box", "ellipsoid")
CONVEX_ALBEDO = (0.6, 0.45, 0.3)


# ----------------------------------------------------------------------------- meshes


def flat_mesh(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray) -> trimesh.Trimesh:
    """Unprocessed mesh with the given vertex normals and zero UVs (constant textures)."""
    m = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_normals=normals, process=False)
    m.visual = trimesh.visual.TextureVisuals(uv=np.zeros((len(vertices), 2)))
    return m


def box_mesh(lo: Any, hi: Any, rotation: np.ndarray | None = None, center: Any = None) -> trimesh.Trimesh:
    """Box with flat faces (4 vertices per face, outward normals).

    Args:
        lo, hi: ``(3,)`` corners of the axis-aligned box.
        rotation: optional ``(3, 3)`` rotation applied about ``center`` (default: the box centre).
    """
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces, normals = [], [], []
    for axis in range(3):
        for side, sign in ((lo, -1.0), (hi, 1.0)):
            u, v = [a for a in range(3) if a != axis]
            quad = []
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = np.empty(3)
                p[axis] = side[axis]
                p[u] = (lo, hi)[a][u]
                p[v] = (lo, hi)[b][v]
                quad.append(p)
            n = np.zeros(3)
            n[axis] = sign
            base = len(verts)
            verts += quad
            normals += [n] * 4
            tri = [[0, 1, 2], [0, 2, 3]]
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) < 0:  # counter-clockwise from outside
                tri = [[0, 2, 1], [0, 3, 2]]
            faces += [[base + i for i in t] for t in tri]
    v, n = np.array(verts), np.array(normals)
    if rotation is not None:
        c = 0.5 * (lo + hi) if center is None else np.asarray(center, float)
        R = np.asarray(rotation, float)
        v = (v - c) @ R.T + c
        n = n @ R.T
    return flat_mesh(v, np.array(faces), n)


def ground_mesh(size: float = 200.0) -> trimesh.Trimesh:
    """A square at y = 0 facing +Y, side ``size`` metres."""
    s = size / 2
    v = np.array([[-s, 0, -s], [s, 0, -s], [s, 0, s], [-s, 0, s]], float)
    return flat_mesh(v, np.array([[0, 2, 1], [0, 3, 2]]), np.tile([0.0, 1.0, 0.0], (4, 1)))


def ellipsoid_mesh(radii: Any, center: Any, rotation: np.ndarray | None = None,
                   subdivisions: int = 5) -> trimesh.Trimesh:
    """Ellipsoid ``R diag(radii) u + center`` (u on the unit sphere) with its exact smooth
    normals ``R (u / radii)`` normalised."""
    r = np.asarray(radii, float)
    R = np.eye(3) if rotation is None else np.asarray(rotation, float)
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    unit = np.asarray(s.vertices)
    n = (unit / r) @ R.T
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return flat_mesh((unit * r) @ R.T + np.asarray(center, float), np.asarray(s.faces), n)


def _normals(mesh: trimesh.Trimesh) -> np.ndarray:
    """The vertex normals a mesh was built with (trimesh keeps them while vertices are untouched)."""
    return np.asarray(mesh.vertex_normals, dtype=np.float64)


def const_material(rgb: Any, name: str) -> Material:
    """Lambertian material of constant albedo ``rgb``."""
    return Material(kind="diffuse", texture=np.full((4, 4, 3), rgb, dtype=np.float32), name=name)


# ----------------------------------------------------------------------------- specs


def sphere_spec(radius: float = 1.0, with_ground: bool = False, albedo: Any = CONVEX_ALBEDO) -> SceneSpec:
    """Sphere of ``radius`` centred at ``(0, radius + 0.5, 0)`` (a level-5 icosphere with
    radial normals), optionally on a grey ground (albedo 0.3)."""
    sph = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    sph.apply_translation([0, radius + 0.5, 0])
    mesh = flat_mesh(np.asarray(sph.vertices), np.asarray(sph.faces),
                     (np.asarray(sph.vertices) - [0, radius + 0.5, 0]) / radius)
    parts = [Part("sphere", mesh, const_material(albedo, "sphere"), role="landmark")]
    if with_ground:
        parts.append(Part("ground", ground_mesh(), const_material([0.3, 0.3, 0.3], "ground"), role="ground"))
    return SceneSpec(seed=0, landmark_type="statue", parts=parts,
                     landmark_bounds=np.array([[-radius, 0.5, -radius], [radius, 2 * radius + 0.5, radius]]),
                     ground_size=200.0)


def box_spec() -> SceneSpec:
    """A red 1 x 2 x 1 m box standing on a grey ground (albedo 0.5)."""
    parts = [Part("box", box_mesh([-0.5, 0.0, -0.5], [0.5, 2.0, 0.5]), const_material([0.7, 0.2, 0.2], "box")),
             Part("ground", ground_mesh(), const_material([0.5, 0.5, 0.5], "ground"), role="ground")]
    return SceneSpec(seed=0, landmark_type="tower", parts=parts,
                     landmark_bounds=np.array([[-0.5, 0.0, -0.5], [0.5, 2.0, 0.5]]), ground_size=200.0)


def _rotation(axis: Any, deg: float) -> np.ndarray:
    from physrelight.rotations import axis_angle

    return axis_angle(np.asarray(axis, float), deg)


def convex_spec(shape: str, albedo: Any = CONVEX_ALBEDO) -> SceneSpec:
    """A lone convex object centred at ``(0, 1.5, 0)``, about 2 m across, no ground.

    Shapes: ``"sphere"`` (radius 1), ``"box"`` (1.4 x 1.4 x 1.4 m, turned so that three
    faces face a camera on +z), ``"ellipsoid"`` (radii 1.1, 0.7, 0.9, tilted). Convex: no
    point shadows another and no light bounces between surfaces, so the path-traced
    radiance of a Lambertian surface is exactly ``albedo * E(n) / pi``.
    """
    c = np.array([0.0, 1.5, 0.0])
    if shape == "sphere":
        return sphere_spec(1.0, albedo=albedo)
    if shape == "box":
        R = _rotation([1, 0, 0], 25.0) @ _rotation([0, 1, 0], 35.0)
        mesh = box_mesh(c - 0.7, c + 0.7, rotation=R)
    elif shape == "ellipsoid":
        mesh = ellipsoid_mesh([1.1, 0.7, 0.9], [0.0, 0.0, 0.0], rotation=_rotation([0, 0, 1], 20.0)
                              @ _rotation([0, 1, 0], 30.0))
        mesh = flat_mesh(np.asarray(mesh.vertices) + c, np.asarray(mesh.faces), _normals(mesh))
    else:
        raise ValueError(f"shape must be one of {CONVEX_SHAPES}, got {shape!r}")
    parts = [Part(shape, mesh, const_material(albedo, shape), role="landmark")]
    v = np.asarray(mesh.vertices)
    return SceneSpec(seed=0, landmark_type="statue", parts=parts,
                     landmark_bounds=np.stack([v.min(0), v.max(0)]), ground_size=200.0)


def view(eye: Any, target: Any, size: int = 32, fov: float = 50.0) -> pcam.Camera:
    """Square look-at camera with horizontal field of view ``fov`` degrees."""
    return pcam.Camera.look_at(np.asarray(eye, float), np.asarray(target, float), fov, size, size)


def convex_view(size: int) -> pcam.Camera:
    """The camera of :func:`convex_spec`: 3.4 m away, slightly above, the object fills ~70 %."""
    return view([0.6, 2.0, 3.4], [0.0, 1.5, 0.0], size=size, fov=42.0)


# ----------------------------------------------------------------------------- lightings


LIGHTINGS: dict[str, tuple[str, dict[str, Any]]] = {
    "sunsky": ("sunsky", dict(elevation_deg=40.0, azimuth_deg=120.0, turbidity=3.0)),
    "sunsky_high": ("sunsky", dict(elevation_deg=70.0, azimuth_deg=200.0, turbidity=2.5)),
    "evening": ("evening", dict(elevation_deg=8.0, azimuth_deg=250.0, turbidity=4.0)),
    "overcast": ("overcast", dict(elevation_deg=40.0, azimuth_deg=60.0, turbidity=9.0)),
    "city": ("hdri", dict(azimuth_deg=0.0)),
    "courtyard": ("hdri", dict(azimuth_deg=0.0)),
    "forest": ("hdri", dict(azimuth_deg=0.0)),
    "studio": ("hdri", dict(azimuth_deg=0.0)),
}
"""Named lightings: ``name -> (kind, parameters)``. HDRIs are the shared maps (their
sun split off as a directional light when it carries >= 1 % of the energy); ``studio``
is an indoor control."""


@functools.lru_cache(maxsize=32)
def get_lighting(name: str, env_res: int) -> _lighting.Lighting:
    """The named lighting with a sky map of height ``env_res`` (cached)."""
    if name not in LIGHTINGS:
        raise ValueError(f"unknown lighting {name!r}; expected one of {', '.join(LIGHTINGS)}")
    kind, params = LIGHTINGS[name]
    if kind == "hdri":
        return _lighting.hdri(_lighting.HDRI_DIR / f"{name}.exr", resolution=env_res, **params)
    maker = {"sunsky": _lighting.sunsky, "evening": _lighting.evening, "overcast": _lighting.overcast}[kind]
    return maker(0, resolution=env_res, **params)


def describe_lighting(light: _lighting.Lighting) -> str:
    """Short human description: ``sunsky, sun 40 deg up, 78 % of E_up from the sun``."""
    p = light.params
    if light.kind == "hdri":
        text = f"HDRI {p['hdri']}"
    else:
        text = f"{light.kind} (Hosek-Wilkie, turbidity {p['turbidity']:.1f})"
    if light.has_sun:
        elevation = math.degrees(math.asin(float(np.clip(light.sun_direction[1], -1, 1))))
        text += f", sun {elevation:.0f} deg up, {100 * sun_share(light):.0f} % of E_up from the sun"
    return text


def sun_share(light: _lighting.Lighting) -> float:
    """Share of the irradiance on an upward surface that comes from the sun."""
    if not light.has_sun:
        return 0.0
    up = np.array([[0.0, 1.0, 0.0]])
    total = float(light.irradiance_reference(up)[0] @ LUMINANCE)
    sun = max(0.0, float(light.sun_direction[1])) * float(light.sun_irradiance @ LUMINANCE)
    return sun / total if total > 0 else 0.0


def total_power(light: _lighting.Lighting) -> float:
    """``int Y(L) dw`` over the sphere, sun included (the scale of the SH error bounds)."""
    from physrelight import envmap

    sun = float(light.sun_irradiance @ LUMINANCE) if light.has_sun else 0.0
    return envmap.luminance_integral(light.sky.astype(np.float64)) + sun


# ----------------------------------------------------------------------------- rendering


def render_film(scene: Any, integrator: Any, index: int, spp: int, seed: int) -> np.ndarray:
    """``(H, W, C)`` float64 film of sensor ``index`` (C = 3 colour channels + AOVs)."""
    img = mi.render(scene, integrator=integrator, sensor=index, spp=int(spp), seed=int(seed))
    return np.array(img, dtype=np.float64)


@functools.lru_cache(maxsize=8)
def path_integrator(max_depth: int) -> Any:
    """Mitsuba's ``path`` integrator; ``max_depth = 2`` is direct light only."""
    return mi.load_dict({"type": "path", "max_depth": int(max_depth)})


def radiance_runs(scene: Any, index: int, spp: int, seeds: list[int], max_depth: int = 8) -> np.ndarray:
    """``(K, H, W, 3)`` independent path-traced renders, one per seed."""
    integ = path_integrator(max_depth)
    return np.stack([render_film(scene, integ, index, spp, s)[..., :3] for s in seeds])


def footprint_spread(scene: Any, index: int, spp: int, seed: int) -> np.ndarray:
    """``(H, W)`` ``1 - |mean shading normal over the pixel's surface samples|``.

    0 where the surface is flat inside the pixel; about ``sigma^2 / 2`` for a normal
    spread of ``sigma`` radians; large where the pixel straddles a crease or a
    silhouette. It bounds the footprint bias of evaluating ``E`` at the pixel centre:
    a smooth ``E`` averaged over the footprint differs from ``E(centre)`` by
    ``O(sigma^2) E``.
    """
    g = render_film(scene, _integrators.gbuffer_integrator(), index, spp, seed)
    names = _integrators.GBUFFER_CHANNELS
    cov = g[..., 3 + names.index("hit")]
    n = np.stack([g[..., 3 + names.index(c)] for c in ("nx", "ny", "nz")], axis=-1)
    length = np.linalg.norm(n, axis=-1) / np.maximum(cov, 1e-12)
    return np.where(cov > 0, 1.0 - np.clip(length, 0.0, 1.0), 1.0)


def world_normals(normal_cam: np.ndarray, cam: pcam.Camera) -> np.ndarray:
    """``(H, W, 3)`` camera-frame normals -> world frame (0 stays 0)."""
    R = np.asarray(cam.world_to_camera, dtype=np.float64)[:3, :3]
    return normal_cam.astype(np.float64) @ R


def exact_irradiance(light: _lighting.Lighting, normal_world: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` brute-force ``E(n)`` (sky texel sum + delta sun) at valid pixels, 0 elsewhere."""
    out = np.zeros(normal_world.shape[:-1] + (3,))
    if valid.any():
        out[valid] = light.irradiance_reference(normal_world[valid])
    return out


def occluded_share(scene: Any, cam: pcam.Camera, light: _lighting.Lighting, pixels: np.ndarray,
                   normals_world: np.ndarray, n_dirs: int = 2048) -> tuple[np.ndarray, np.ndarray]:
    """Share of each pixel's unoccluded irradiance (luminance, sky + sun) that geometry blocks,
    by ray casting from the pixel-centre surface point in ``n_dirs`` directions.

    A sampled shadow estimate can miss occlusion: its directions follow the sky's
    brightness, not ``L cos``, so a dim but well-placed part of the sky (the ground half
    of an HDRI seen by a wall) may get no sample at all. Casting fixed directions (a
    spherical Fibonacci set) weighted by ``L(d) max(0, n . d) dOmega`` does not.

    Args:
        scene: the Mitsuba scene (any sensor).
        cam: the view whose pixel centres are traced.
        light: the lighting (sky map + sun).
        pixels: ``(N, 2)`` integer (row, column) pixel indices.
        normals_world: ``(N, 3)`` their world normals.
        n_dirs: number of test directions over the sphere.

    Returns:
        ``(share, resolution)``, each ``(N,)``: the blocked share of ``E`` and the largest
        share one test direction carries (occluders between directions go unseen).
    """
    from physrelight import envmap
    from physrelight.sh import fibonacci_sphere

    o, d = _cameras.camera_rays(cam)
    k = pixels[:, 0] * cam.width + pixels[:, 1]
    o, d = o[k], d[k]
    ray = mi.Ray3f(mi.Point3f(*[o[:, c].astype(np.float32) for c in range(3)]),
                   mi.Vector3f(*[d[:, c].astype(np.float32) for c in range(3)]))
    si = scene.ray_intersect(ray)
    p = np.stack([np.array(si.p[c], dtype=np.float64) for c in range(3)], axis=-1)
    dirs = fibonacci_sphere(n_dirs)
    sky = np.asarray(envmap.sample(light.sky.astype(np.float64), dirs)) @ np.asarray(envmap.LUMINANCE)
    cos = np.clip(normals_world @ dirs.T, 0.0, None)  # (N, D)
    w = cos * sky[None] * (4 * math.pi / n_dirs)
    sun_w = np.zeros(len(k))
    all_dirs = dirs
    if light.has_sun:
        sun_w = np.clip(normals_world @ light.sun_direction, 0.0, None) * float(
            light.sun_irradiance @ np.asarray(envmap.LUMINANCE))
        all_dirs = np.concatenate([dirs, light.sun_direction[None]])
        w = np.concatenate([w, sun_w[:, None]], axis=1)
    total = w.sum(axis=1)
    blocked = np.zeros_like(w)
    n_pix, n_d = w.shape
    pi, di = np.nonzero(w > 0)
    step = 1 << 20
    for a in range(0, pi.size, step):
        pp, dd = pi[a:a + step], di[a:a + step]
        org = p[pp] + 1e-3 * normals_world[pp]
        r = mi.Ray3f(mi.Point3f(*[org[:, c].astype(np.float32) for c in range(3)]),
                     mi.Vector3f(*[all_dirs[dd, c].astype(np.float32) for c in range(3)]))
        blocked[pp, dd] = np.array(scene.ray_test(r), dtype=bool)
    share = (w * blocked).sum(axis=1) / np.maximum(total, 1e-30)
    resolution = w[:, :n_dirs].max(axis=1) / np.maximum(total, 1e-30) if n_d else np.zeros(n_pix)
    return share, resolution


# ----------------------------------------------------------------------------- scene bank


@dataclass
class BankView:
    """One view of a generated scene under one lighting, with everything the checks compare.

    Images are ``(H, W, C)`` float64 in the lighting's own radiance units; multiply by
    ``exposure`` for display-like values (a white horizontal surface at 0.18).

    Attributes:
        scene_seed, view_index, lighting_name: identity.
        camera: the view.
        light: the lighting record.
        albedo, normal, sky, coverage, glossy: geometry (:class:`synth.render.ViewBuffers`);
            albedo is the mean of two independent G-buffer renders.
        albedo_sem: ``(H, W, 3)`` standard error of that albedo (half the renders' difference).
        normal_world: ``(H, W, 3)``.
        spread: ``(H, W)`` footprint normal spread (:func:`footprint_spread`).
        full: ``(K, H, W, 3)`` independent renders, up to 8 bounces (Mitsuba ``path``, max_depth 8).
        direct: ``(K, H, W, 3)`` independent renders of direct light only (max_depth 2).
        sun_visibility: ``(H, W)`` the synth ``shadow.exr`` for a lighting with a sun.
        direct_ratio: ``(H, W)`` ``int V L cos / int L cos`` over sky and sun (``direct_shadow.exr``),
            mean of two independent shadow renders.
        direct_ratio_sem: ``(H, W)`` its standard error (half the two renders' difference).
        irradiance: ``(H, W, 3)`` exact unoccluded ``E(n)`` at the pixel-centre normal.
        glossy_full, glossy_albedo, glossy_mask: the same view with a share of the
            materials non-Lambertian (same geometry and textures), or None.
        exposure: the lighting's suggested exposure scale.
        unoccluded: ``(H, W)`` pixels that both shadow renders and a ray cast in 2048 fixed
            directions (:func:`occluded_share`) find wholly unoccluded.
        occlusion_resolution: ``(H, W)`` the largest share of ``E`` one cast direction carries.
    """

    scene_seed: int
    view_index: int
    lighting_name: str
    camera: pcam.Camera
    light: _lighting.Lighting
    albedo: np.ndarray
    albedo_sem: np.ndarray
    normal: np.ndarray
    sky: np.ndarray
    coverage: np.ndarray
    normal_world: np.ndarray
    spread: np.ndarray
    full: np.ndarray
    direct: np.ndarray
    sun_visibility: np.ndarray
    direct_ratio: np.ndarray
    direct_ratio_sem: np.ndarray
    irradiance: np.ndarray
    exposure: float
    unoccluded: np.ndarray | None = None
    occlusion_resolution: np.ndarray | None = None
    glossy_full: np.ndarray | None = None
    glossy_albedo: np.ndarray | None = None
    glossy_mask: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return f"{scene_label(self.scene_seed)} / view {self.view_index} / {self.lighting_name}"

    @property
    def is_sphere(self) -> bool:
        return self.scene_seed == SPHERE_SEED

    @property
    def shadow(self) -> np.ndarray:
        """The synth ground-truth shadow (``shadow.exr``): sun visibility with a sun, else the direct ratio."""
        return self.sun_visibility if self.light.has_sun else self.direct_ratio

    @property
    def world_to_camera(self) -> np.ndarray:
        return np.asarray(self.camera.world_to_camera, dtype=np.float64)

    def sh(self, order: int = 2) -> np.ndarray:
        """``(K, 3)`` radiance SH of the lighting in this camera's frame, exposure applied."""
        return self.light.sh(order, self.world_to_camera) * self.exposure

    def mask(self, max_spread: float = 2e-3) -> np.ndarray:
        """``(H, W)`` pixels wholly on a surface whose normal is coherent over the footprint.

        ``coverage == 1`` (no sky inside the pixel) and footprint spread below
        ``max_spread`` (no crease or silhouette inside the pixel: the pixel-centre
        normal stands for the footprint to ``O(spread)`` in E).
        """
        return (~self.sky) & (self.coverage >= 1.0 - 1e-6) & (self.spread < max_spread)


SPHERE_SEED = -1
"""``scene_seed`` of the bank's sphere-on-ground scene (two views)."""


def scene_label(seed: int) -> str:
    """How reports and progress lines name a bank scene: ``"sphere"`` or ``"scene 7"``."""
    return "sphere" if seed == SPHERE_SEED else f"scene {seed}"


class SceneBank:
    """Renders of generated scenes, made on first use and shared by the checks.

    First a sphere on the ground seen from two views (``scene_seed`` :data:`SPHERE_SEED`), then for
    each scene seed of the level: ``scene_views`` tourist views
    (:func:`synth.cameras.sample_views`), each under every lighting of
    ``scene_lightings``; with ``glossy=True`` also the glossy variant.
    """

    def __init__(self, level: Level, progress: Any = None) -> None:
        self.level = level
        self._views: list[BankView] | None = None
        self._progress = progress or (lambda msg: None)
        self.seconds: dict[str, float] = {}

    def views(self) -> list[BankView]:
        if self._views is None:
            self._views = self._render_all()
        return self._views

    def _tick(self, key: str, t0: float) -> None:
        import time

        self.seconds[key] = self.seconds.get(key, 0.0) + time.perf_counter() - t0

    def _render_all(self) -> list[BankView]:
        import time

        lv = self.level
        out: list[BankView] = []
        for si, seed in enumerate((SPHERE_SEED,) + tuple(lv.scene_seeds)):
            t0 = time.perf_counter()
            if seed == SPHERE_SEED:
                # A sphere on the ground shows every camera-facing normal: the lighting is
                # observable from one view (generated landmarks show a few normal directions).
                spec = glossy_spec = sphere_spec(1.0, with_ground=True)
                cams = [view([4.0 * math.sin(math.radians(a)), 2.2, 4.0 * math.cos(math.radians(a))], [0.0, 1.3, 0.0],
                             size=lv.scene_res, fov=45.0) for a in (0.0, 50.0)]
            else:
                spec = generate_scene(seed)
                glossy_spec = generate_scene(seed, glossy_fraction=lv.glossy_fraction)
                cams = _cameras.sample_views(spec, lv.scene_views, seed=seed + 1000, width=lv.scene_res,
                                             height=lv.scene_res)
            self._tick("setup", t0)
            geo: dict[int, Any] = {}
            for li, lname in enumerate(lv.scene_lightings):
                self._progress(f"scene bank: {scene_label(seed)} under {lname}")
                light = get_lighting(lname, lv.env_res)
                t0 = time.perf_counter()
                scene = _render.build_scene(spec, cams, light, spp=lv.scene_spp)
                gscene = None if seed == SPHERE_SEED else _render.build_scene(glossy_spec, cams, light,
                                                                               spp=lv.scene_spp)
                self._tick("build", t0)
                for vi, cam in enumerate(cams):
                    base = 1_000_003 * (seed + 1) + 1009 * vi + 17 * li
                    t0 = time.perf_counter()
                    if vi not in geo:
                        # Two independent albedo renders: a textured pixel's albedo is a footprint
                        # average, itself a Monte Carlo estimate; their spread is its error.
                        g = _render.render_geometry(scene, vi, cam, spp=lv.gbuffer_spp, seed=base)
                        g2 = _render.render_geometry(scene, vi, cam, spp=lv.gbuffer_spp, seed=base + 3)
                        spread = footprint_spread(scene, vi, spp=64, seed=base + 1)
                        gg = None if gscene is None else _render.render_geometry(gscene, vi, cam, spp=64, seed=base)
                        albedo = 0.5 * (g.albedo.astype(np.float64) + g2.albedo)
                        albedo_sem = 0.5 * np.abs(g.albedo.astype(np.float64) - g2.albedo)
                        geo[vi] = (g, spread, gg, albedo, albedo_sem)
                    g, spread, gg, albedo, albedo_sem = geo[vi]
                    self._tick("geometry", t0)
                    seeds = [base + 100 + k for k in range(lv.scene_renders)]
                    t0 = time.perf_counter()
                    full = radiance_runs(scene, vi, lv.scene_spp, seeds, max_depth=8)
                    self._tick("path_full", t0)
                    t0 = time.perf_counter()
                    direct = radiance_runs(scene, vi, lv.scene_spp, [s + 50 for s in seeds], max_depth=2)
                    self._tick("path_direct", t0)
                    t0 = time.perf_counter()
                    glossy = None if gscene is None else radiance_runs(gscene, vi, lv.scene_spp,
                                                                       [s + 90 for s in seeds], max_depth=8)
                    self._tick("path_glossy", t0)
                    t0 = time.perf_counter()
                    # Two independent shadow renders: their spread is the shadow's own MC error.
                    lits = [_render.render_lit(scene, vi, light, spp=1, shadow_spp=lv.shadow_spp, seed=base + 7 + k)
                            for k in range(2)]
                    ratio = np.stack([lit.direct_shadow for lit in lits]).astype(np.float64)
                    sun_vis = np.mean([lit.sun_visibility for lit in lits], axis=0).astype(np.float64)
                    self._tick("shadow", t0)
                    t0 = time.perf_counter()
                    nw = world_normals(g.normal, cam)
                    # Pixels both shadow renders call unoccluded: confirm by casting fixed directions.
                    cand = (~g.sky_mask) & np.all(ratio >= 1.0 - 1e-9, axis=0)
                    unoccluded = np.zeros(cand.shape, dtype=bool)
                    resolution = np.zeros(cand.shape)
                    if cand.any():
                        px = np.argwhere(cand)
                        share, res_px = occluded_share(scene, cam, light, px, nw[cand])
                        unoccluded[cand] = share <= 0.0
                        resolution[cand] = res_px
                    self._tick("occlusion", t0)
                    t0 = time.perf_counter()
                    surf = ~g.sky_mask
                    E = exact_irradiance(light, nw, surf)
                    self._tick("exact_irradiance", t0)
                    out.append(BankView(
                        scene_seed=seed, view_index=vi, lighting_name=lname, camera=cam, light=light,
                        albedo=albedo, albedo_sem=albedo_sem, normal=g.normal.astype(np.float64), sky=g.sky_mask,
                        coverage=g.coverage.astype(np.float64), normal_world=nw, spread=spread, full=full,
                        direct=direct, sun_visibility=sun_vis, direct_ratio=ratio.mean(axis=0),
                        direct_ratio_sem=np.abs(ratio[0] - ratio[1]) / 2.0, irradiance=E,
                        exposure=float(light.params["exposure_scale"]), glossy_full=glossy,
                        glossy_albedo=None if gg is None else gg.albedo.astype(np.float64),
                        glossy_mask=None if gg is None else gg.glossy >= 0.5,
                        unoccluded=unoccluded, occlusion_resolution=resolution,
                        extra={"shadow_spp": lv.shadow_spp}))
        return out


def bank(ctx: Context) -> SceneBank:
    """The run's shared :class:`SceneBank` (rendered on first use, kept in ``ctx.shared``)."""
    if "bank" not in ctx.shared:
        ctx.shared["bank"] = SceneBank(ctx.level, progress=ctx.progress)
    return ctx.shared["bank"]
