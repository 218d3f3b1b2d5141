"""What the benchmark relights: views of synthetic scenes with every ground truth in memory.

Two sources, one in-memory form (:class:`BenchView`):

* :func:`load_dataset` reads a folder written by :mod:`synth.writer` (``data/heldout``)
  through :class:`synth.dataset.SynthDataset` in ``mode="full"``. The physical inputs of
  the analysis-by-synthesis baseline (scene, camera, lighting records) are rebuilt on
  demand from the folder's manifest with :func:`synth.writer.scene_inputs`, which is
  seeded, so they are exactly the ones the folder was rendered from.
* :func:`render_recipes` renders small scenes whose lighting is *chosen* so that every
  stratum has members (low sun, overcast, twilight, glossy materials, very bright and very
  dark albedo) and the time-lapse view (:func:`synth.timelapse.sun_path`: one camera, the sun moving
  through a day). Rendering follows :func:`synth.writer.write_scene` step for step
  (same renderer, same photo nuisances), at 64 px with a fixed seed.

Conventions: images are numpy ``(H, W, C)`` float32 (``(H, W)`` for one channel); normals
in the camera frame; SH ``(9, 3)`` radiance in world units (multiply by the photo's gain
``2**ev * wb_gains`` for the photo's linear units).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from synth.timelapse import sun_path

from ..common import LUMINANCE

# ----------------------------------------------------------------------------- records


@dataclass(frozen=True)
class LightInfo:
    """What the strata need to know about one lighting.

    Attributes:
        kind: ``sunsky``, ``evening``, ``overcast`` or ``hdri`` (the synth kinds).
        sun_elevation: elevation in degrees of the *visible* sun, None without one.
        dominant_azimuth: azimuth in degrees (synth convention: 0 = -Z, 90 = +X) of the
            luminance-weighted SH band-1 direction (world frame): where the light comes
            from, for suns and sun-free skies alike.
        label: short description for reports (``"sunsky 45 deg"``).
    """

    kind: str
    sun_elevation: float | None
    dominant_azimuth: float
    label: str

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def light_info(kind: str, sun_direction: Any, sh_world: np.ndarray) -> LightInfo:
    """:class:`LightInfo` from a lighting's kind, sun direction (or None) and world SH ``(9, 3)``."""
    c = np.asarray(sh_world, dtype=np.float64) @ LUMINANCE
    x, y, z = c[3], c[1], c[2]  # Y11 ~ x, Y1-1 ~ y, Y10 ~ z
    azimuth = math.degrees(math.atan2(x, -z)) % 360.0
    elevation = None
    if sun_direction is not None:
        s = np.asarray(sun_direction, dtype=np.float64)
        elevation = math.degrees(math.asin(float(np.clip(s[1] / np.linalg.norm(s), -1.0, 1.0))))
    label = kind if elevation is None else f"{kind} {elevation:.0f} deg"
    return LightInfo(kind=kind, sun_elevation=elevation, dominant_azimuth=azimuth, label=label)


@dataclass
class BenchView:
    """One camera of one scene under several lightings, with every ground truth.

    Attributes:
        scene: scene name (unique in a run).
        view: view index within the scene.
        group: where it comes from (``"heldout"``, ``"quick"``, ``"glossy"``, ``"bright_albedo"``,
            ``"dark_albedo"``, ``"twilight"``, ``"timelapse"``).
        albedo: ``(H, W, 3)`` diffuse reflectance (0 on sky).
        normal: ``(H, W, 3)`` camera-frame unit normals (0 on sky).
        sky: ``(H, W)`` bool.
        glossy: ``(H, W)`` share of the footprint on non-Lambertian materials.
        lights: one :class:`LightInfo` per lighting.
        sh: per lighting ``(9, 3)`` camera-frame radiance SH (world radiance units).
        radiance: per lighting ``(H, W, 3)`` path-traced HDR.
        shadow: per lighting ``(H, W)`` synth's ``shadow.exr``: the sun's visibility (the
            direct-light ratio without a sun).
        direct_shadow: per lighting ``(H, W)`` the direct-light ratio ``int V L cos / int L cos``
            over the whole environment (``direct_shadow.exr``): the factor ``s`` that makes the
            image model ``s * albedo * E / pi`` exact for direct light.
        sun_sh: per lighting ``(9, 3)`` camera-frame SH of the sun alone (zeros without a
            sun), so the sky's part is ``sh - sun_sh``.
        photo: per lighting ``(H, W, 3)`` float32 display values in [0, 1] (the LDR photo).
        photo_params: per lighting the :class:`synth.photo.PhotoParams` record (dict).
        K: ``(3, 3)`` the camera's intrinsics (pixel grid of the images), or None.
        depth: ``(H, W)`` true z-depth at the pixel centres (0 on sky), or None; only the
            oracle-depth diagnostics read it.
        physical: ``() -> (SceneSpec, Camera, [Lighting])`` for the analysis-by-synthesis
            baseline (Mitsuba objects, built on demand), or None.
    """

    scene: str
    view: int
    group: str
    albedo: np.ndarray
    normal: np.ndarray
    sky: np.ndarray
    glossy: np.ndarray
    lights: list[LightInfo]
    sh: list[np.ndarray]
    radiance: list[np.ndarray]
    shadow: list[np.ndarray]
    direct_shadow: list[np.ndarray]
    sun_sh: list[np.ndarray]
    photo: list[np.ndarray]
    photo_params: list[dict[str, Any]]
    physical: Callable[[], tuple[Any, Any, list[Any]]] | None = field(default=None, repr=False)
    K: np.ndarray | None = None
    depth: np.ndarray | None = None

    @property
    def name(self) -> str:
        return f"{self.scene}/view_{self.view:02d}"

    @property
    def num_lights(self) -> int:
        return len(self.lights)

    def foreground(self) -> np.ndarray:
        """``(H, W)`` bool: not sky and a valid ground-truth normal (the protocol's foreground)."""
        return ~self.sky & (np.linalg.norm(self.normal, axis=-1) > 0.5)

    def glossy_share(self) -> float:
        """Share of foreground pixels on non-Lambertian materials."""
        fg = self.foreground()
        return float((self.glossy[fg] >= 0.5).mean()) if fg.any() else 0.0

    def albedo_luminance(self) -> float:
        """Mean foreground albedo luminance."""
        fg = self.foreground()
        return float((self.albedo[fg] @ LUMINANCE).mean()) if fg.any() else 0.0


def sun_sh(sun_direction: Any, sun_irradiance: Any, world_to_camera: Any) -> np.ndarray:
    """``(9, 3)`` camera-frame radiance SH of a delta sun (zeros when ``sun_direction`` is None)."""
    from physrelight import sh

    if sun_direction is None:
        return np.zeros((9, 3))
    world = np.asarray(sh.project_sun(np.asarray(sun_direction, dtype=np.float64),
                                      np.asarray(sun_irradiance, dtype=np.float64), 2))
    R = np.asarray(world_to_camera, dtype=np.float64)[:3, :3]
    return np.asarray(sh.rotation(R, 2)) @ world


# ----------------------------------------------------------------------------- a synth folder


def load_dataset(root: str | Path, max_scenes: int | None = None, with_physical: bool = True) -> list[BenchView]:
    """Every view of a :mod:`synth.writer` folder (first ``max_scenes`` scenes if given).

    Raises:
        FileNotFoundError: no ``manifest.json`` under ``root``.
        ValueError: not a synth folder, or no scenes.
    """
    from synth.dataset import SynthDataset

    root = Path(root)
    if not (root / "manifest.json").is_file():
        raise FileNotFoundError(f"no synth dataset at {str(root)!r} (manifest.json missing); make one with "
                                "'physrelight synth DIR' or run the benchmark without --data")
    ds = SynthDataset(root, split="all", mode="full")
    scenes = ds.scenes[:max_scenes] if max_scenes else ds.scenes
    if not scenes:
        raise ValueError(f"{str(root)!r} holds no finished scenes")
    views: list[BenchView] = []
    for scene in scenes:
        rec = ds.record(scene)
        n_light = len(rec["lights"])
        lights = [light_info(l["kind"], l["sun_direction"], np.asarray(l["sh"]["world"]["2"])) for l in rec["lights"]]
        physical = _dataset_physical(ds.config, int(rec["index"])) if with_physical else None
        for v in range(len(rec["views"])):
            geo = ds.load(scene, v, None, keys=("albedo", "normal", "sky_mask", "glossy_mask", "depth", "K"))
            per = [ds.load(scene, v, l, keys=("radiance", "shadow", "direct_shadow", "photo", "photo_params", "sh"))
                   for l in range(n_light)]
            views.append(BenchView(
                scene=scene, view=v, group="heldout", albedo=geo["albedo"], normal=geo["normal"],
                sky=geo["sky_mask"].astype(bool), glossy=geo["glossy_mask"].astype(np.float32), lights=lights,
                sh=[p["sh"]["2"] for p in per], radiance=[p["radiance"] for p in per],
                shadow=[_single(p["shadow"]) for p in per],
                direct_shadow=[_single(p["direct_shadow"]) for p in per],
                sun_sh=[sun_sh(l["sun_direction"], l["sun_irradiance"], rec["views"][v]["world_to_camera"])
                        for l in rec["lights"]],
                photo=[np.clip(p["photo"], 0, 1) for p in per],
                photo_params=[p["photo_params"] for p in per],
                physical=(lambda v=v, physical=physical: _pick_view(physical(), v)) if physical else None,
                K=np.asarray(geo["K"], dtype=np.float64), depth=_single(geo["depth"]).astype(np.float32)))
    return views


def _single(x: np.ndarray) -> np.ndarray:
    return x[..., 0] if x.ndim == 3 else x


def _dataset_physical(config: dict[str, Any], index: int) -> Callable[[], tuple[Any, list[Any], list[Any]]]:
    """Rebuild (spec, cameras, lightings) of scene ``index`` from a folder's manifest config (cached)."""
    cache: dict[str, Any] = {}

    def build() -> tuple[Any, list[Any], list[Any]]:
        if "value" not in cache:
            from synth.writer import SynthConfig, scene_inputs

            cfg = dict(config)
            cfg["kinds"] = tuple(cfg["kinds"])
            _, spec, cams, lights = scene_inputs(SynthConfig(**cfg), index)
            cache["value"] = (spec, cams, lights)
        return cache["value"]

    return build


def _pick_view(built: tuple[Any, list[Any], list[Any]], v: int) -> tuple[Any, Any, list[Any]]:
    spec, cams, lights = built
    return spec, cams[v], lights


# ----------------------------------------------------------------------------- rendered scenes


@dataclass(frozen=True)
class LightSpec:
    """A chosen lighting: ``kind`` with sun elevation/azimuth in degrees (hidden sun for
    ``overcast``), or ``hdri`` with a map name and an azimuth."""

    kind: str
    elevation: float = 45.0
    azimuth: float = 0.0
    hdri: str = ""
    turbidity: float = 3.0

    def build(self, resolution: int) -> Any:
        from synth import lighting

        if self.kind == "hdri":
            path = lighting.HDRI_DIR / f"{self.hdri}.exr"
            columns = 2 * resolution  # a whole number of sky columns: an exact, cached rotation
            az = round(self.azimuth / 360.0 * columns) * 360.0 / columns
            return lighting.hdri(path, azimuth_deg=az, resolution=resolution)
        make = {"sunsky": lighting.sunsky, "evening": lighting.evening, "overcast": lighting.overcast}[self.kind]
        turbidity = 9.0 if self.kind == "overcast" else self.turbidity
        return make(0, elevation_deg=self.elevation, azimuth_deg=self.azimuth, turbidity=turbidity, albedo=0.2,
                    resolution=resolution)


@dataclass(frozen=True)
class Recipe:
    """A rendered scene of the benchmark.

    Attributes:
        name: scene name.
        group: :attr:`BenchView.group` of its views.
        seed: scene generator seed (:func:`synth.scene.generate_scene`).
        views: cameras (tourist-like, :func:`synth.cameras.sample_views`).
        lights: the lightings.
        glossy_fraction: share of non-Lambertian landmark/prop materials.
        albedo_scale: every texture multiplied by this (clipped to [0, 0.95]).
    """

    name: str
    group: str
    seed: int
    views: int
    lights: tuple[LightSpec, ...]
    glossy_fraction: float = 0.0
    albedo_scale: float = 1.0


def timelapse_lights(hours: Sequence[float]) -> tuple[LightSpec, ...]:
    """Clear-sky lightings along :func:`sun_path` (one per hour)."""
    return tuple(LightSpec("sunsky", elevation=el, azimuth=az) for _, el, az in sun_path(hours))


def _seed(*keys: int) -> int:
    """A 32-bit seed derived from integers (stable across runs and platforms)."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])


def _scaled(spec: Any, scale: float) -> Any:
    """The scene with every texture multiplied by ``scale`` (clipped to [0, 0.95])."""
    if scale == 1.0:
        return spec
    parts = []
    for p in spec.parts:
        tex = np.clip(p.material.texture * scale, 0.0, 0.95).astype(np.float32)
        parts.append(dataclasses.replace(p, material=dataclasses.replace(p.material, texture=tex)))
    return dataclasses.replace(spec, parts=parts)


def render_recipe(recipe: Recipe, res: int = 64, spp: int = 32, env_res: int = 32, texture_size: int = 64,
                  gbuffer_spp: int = 16, shadow_spp: int = 32, seed: int = 0) -> list[BenchView]:
    """Render a :class:`Recipe` as :func:`synth.writer.write_scene` would (same renderer,
    same photo nuisances), into memory. Same arguments, same bytes."""
    from synth import cameras, photo, render, scene

    base = _seed(seed, recipe.seed)
    spec = scene.generate_scene(recipe.seed, glossy_fraction=recipe.glossy_fraction, texture_size=texture_size)
    spec = _scaled(spec, recipe.albedo_scale)
    cams = cameras.sample_views(spec, recipe.views, seed=_seed(base, 1) % (2**31), width=res, height=res)
    lights = [ls.build(env_res) for ls in recipe.lights]
    w2c = [np.asarray(c.world_to_camera, dtype=np.float64) for c in cams]
    geo: list[Any] = []
    per: list[list[dict[str, Any]]] = [[] for _ in cams]
    for li, light in enumerate(lights):
        msc = render.build_scene(spec, cams, light, spp, 8, seed=_seed(base, 4, li) % (2**31))
        for vi, cam in enumerate(cams):
            if li == 0:
                geo.append(render.render_geometry(msc, vi, cam, gbuffer_spp, _seed(base, 5, vi) % (2**31)))
            lb = render.render_lit(msc, vi, light, spp, shadow_spp, _seed(base, 7, vi, li) % (2**31))
            rng = np.random.default_rng(_seed(base, 8, vi, li))
            params = photo.sample_photo_params(rng, lb.radiance)
            img = photo.make_photo(lb.radiance, params, rng).astype(np.float32) / 255.0
            per[vi].append({"radiance": lb.radiance, "shadow": lb.shadow, "direct_shadow": lb.direct_shadow,
                            "photo": img, "sun_sh": sun_sh(light.sun_direction, light.sun_irradiance, w2c[vi]),
                            "params": params.to_json(), "sh": light.sh(2, w2c[vi]).astype(np.float64)})
    infos = [light_info(l.kind, l.sun_direction, l.sh(2)) for l in lights]
    out = []
    for vi, cam in enumerate(cams):
        g = geo[vi]
        out.append(BenchView(
            scene=recipe.name, view=vi, group=recipe.group, albedo=g.albedo, normal=g.normal, sky=g.sky_mask,
            glossy=g.glossy, lights=infos, sh=[p["sh"] for p in per[vi]], radiance=[p["radiance"] for p in per[vi]],
            shadow=[p["shadow"] for p in per[vi]], direct_shadow=[p["direct_shadow"] for p in per[vi]],
            sun_sh=[p["sun_sh"] for p in per[vi]], photo=[p["photo"] for p in per[vi]],
            photo_params=[p["params"] for p in per[vi]],
            physical=lambda cam=cam: (spec, cam, lights), K=np.asarray(cam.K, dtype=np.float64),
            depth=np.asarray(g.depth, dtype=np.float32)))
    return out


def render_recipes(recipes: Sequence[Recipe], progress: Callable[[str], None] = lambda m: None,
                   **kwargs: Any) -> list[BenchView]:
    """:func:`render_recipe` for each recipe, in order."""
    views: list[BenchView] = []
    for r in recipes:
        progress(f"rendering {r.name} ({r.views} view(s) x {len(r.lights)} lightings)")
        views += render_recipe(r, **kwargs)
    return views
