"""Write a multi-view x multi-illumination synthetic dataset (the MegaDepth analogue).

Layout (format ``physrelight-synth``, version 1)::

    OUT/manifest.json                  format, version, the generating configuration
    OUT/scene_0000/scene.json          seed, landmark description, cameras, lightings
                                       (kind, parameters, sun, radiance SH orders 2 and 4
                                       in the world frame and in every camera's frame),
                                       photo parameters per view and lighting
    OUT/scene_0000/timing.json         seconds per phase (the only non-deterministic file)
    OUT/scene_0000/lights/light_YY/    env.exr (sky without the sun, world frame) + lighting.json
    OUT/scene_0000/view_XX/            albedo.exr, normal.exr (camera frame), depth.exr,
                                       sky_mask.png (255 = sky), mvs_depth.exr (0 = missing;
                                       ``mvs_scale`` times the photo's size, see below),
                                       glossy_mask.png (255 = non-Lambertian material)
    OUT/scene_0000/view_XX/light_YY/   radiance.exr (path traced), shadow.exr,
                                       direct_shadow.exr, photo.png (the training input)

``shadow.exr`` is the visibility of the rendered (delta) sun averaged over the pixel when
the lighting has a sun, and the direct-light shadow ratio ``int V L cos / int L cos``
otherwise; ``direct_shadow.exr`` is the latter for every lighting.

``mvs_scale`` (``--mvs-scale``, default 1) > 1 is the paper's setting of MVS run on full-size photos
and the network on downsampled ones, without the downsampled photos' lower noise: every file is
what the same configuration at ``mvs_scale`` 1 writes, byte for byte, except ``mvs_depth.exr``, which
is degraded from a second geometry pass of the same cameras at ``mvs_scale`` times the resolution
(intrinsics ``K[:2] * mvs_scale``). The simulator's holes and noise are per pixel, so such depth
covers more of the scene at the photo's resolution (``learned.data.pooled_mvs_normals``).

A scene is rendered into ``OUT/.scene_0000.partial`` and renamed when complete, so a
killed run loses at most the scene in progress and never leaves a half-written scene
looking finished; a restarted run skips finished scenes. Before anything is made, the run is checked
(:func:`check_run`): every map of the ``hdri`` kind is read and validated, and a scene's estimated memory
(:func:`scene_bytes`) must fit in the available memory. A run that fails (an error, Ctrl-C) leaves nothing of
itself behind: the scene in progress's ``.partial`` folder is removed, and so are the manifest and the folder when
this run made them and no finished scene is there; the progress bar is closed first, so the error is a line of
its own. The same configuration gives the
same bytes in every file but ``timing.json``. Shards (``i/n``) take scenes ``i, i+n, ...``
so several machines can render one dataset into one folder. A scene depends on the
configuration and its index only, not on how many scenes there are (``scene.json`` records
the configuration without ``scenes``), so a dataset can grow: the same arguments with a
larger ``--scenes`` render the new scenes into the same folder.
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Any, Iterable

import numpy as np

from physrelight import io

FORMAT = "physrelight-synth"
VERSION = 1
KINDS = ("sunsky", "evening", "overcast", "hdri")


@dataclass(frozen=True)
class SynthConfig:
    """Everything that determines a dataset's bytes."""

    scenes: int = 4
    views: int = 4
    lights: int = 3
    res: int = 128
    spp: int = 64
    seed: int = 0
    max_depth: int = 8
    gbuffer_spp: int = 16
    shadow_spp: int = 32
    env_resolution: int = 128
    kinds: tuple[str, ...] = KINDS
    hdri_dir: str | None = None
    glossy_fraction: float = 0.0
    trees: bool = True
    mvs_scale: int = 1

    def __post_init__(self) -> None:
        for name in ("scenes", "views", "lights", "res", "spp", "max_depth", "gbuffer_spp", "shadow_spp", "mvs_scale"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if self.res < 16:
            raise ValueError(f"res must be at least 16 pixels, got {self.res}")
        if self.mvs_scale > 4:
            raise ValueError(f"mvs_scale must be at most 4 (the MVS depth is mvs_scale**2 times the pixels), "
                             f"got {self.mvs_scale}")
        if self.seed < 0:
            raise ValueError(f"seed must be non-negative, got {self.seed}")
        if not self.kinds or any(k not in KINDS for k in self.kinds):
            raise ValueError(f"kinds must be a non-empty subset of {KINDS}, got {self.kinds}")
        if not 0.0 <= self.glossy_fraction <= 1.0:
            raise ValueError(f"glossy_fraction must lie in [0, 1], got {self.glossy_fraction}")
        if self.hdri_dir is not None and not Path(self.hdri_dir).is_dir():
            raise ValueError(f"HDRI folder {self.hdri_dir!r} does not exist")

    def to_json(self) -> dict:
        d = dataclasses.asdict(self)
        d["kinds"] = list(self.kinds)
        if self.mvs_scale == 1:  # left out at its default: datasets written before it keep their bytes
            del d["mvs_scale"]
        return d

    def scene_json(self) -> dict:
        """What every scene records of the configuration: all of it but the scene count."""
        d = self.to_json()
        del d["scenes"]
        return d


def scene_name(index: int) -> str:
    """The folder name of scene ``index``: ``scene_0007``."""
    return f"scene_{index:04d}"


def _seed(*keys: int) -> int:
    """A 32-bit seed derived from integers (stable across runs and platforms)."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/n"`` -> ``(i, n)`` with ``0 <= i < n``."""
    try:
        i, n = (int(p) for p in text.split("/"))
    except ValueError:
        raise ValueError(f"shard must look like i/n (e.g. 0/4), got {text!r}") from None
    if not 0 <= i < n:
        raise ValueError(f"shard i/n needs 0 <= i < n, got {text!r}")
    return i, n


def shard_scenes(config: SynthConfig, shard: tuple[int, int] = (0, 1)) -> list[int]:
    """The scene indices shard ``(i, n)`` renders: every ``n``-th from ``i``."""
    i, n = shard
    return list(range(i, config.scenes, n))


def _check_manifest(out: Path, config: SynthConfig) -> None:
    """Create the manifest, grow it to more scenes, or refuse to mix configurations in one folder."""
    path = out / "manifest.json"
    want = {"format": FORMAT, "version": VERSION, "config": config.to_json()}
    if path.exists():
        have = io.read_json(path)
        if have.get("format") != FORMAT or have.get("version") != VERSION:
            raise ValueError(f"{str(out)!r} holds a {have.get('format')!r} v{have.get('version')} folder, "
                             f"not {FORMAT} v{VERSION}")
        old = have.get("config", {})
        if old == want["config"]:
            return
        diff = sorted(k for k in want["config"] if old.get(k) != want["config"][k])
        if diff != ["scenes"]:
            raise ValueError(f"{str(out)!r} was made with different arguments ({', '.join(diff)}); "
                             "use another folder or the same arguments")
        if config.scenes < int(old["scenes"]):
            raise ValueError(f"{str(out)!r} holds a dataset of {old['scenes']} scenes; --scenes {config.scenes} "
                             "would not describe it (a dataset can grow, not shrink)")
    io.write_json(path, want)  # new, or grown: the scenes it already has are those of the larger one


SCENE_BYTES_PER_PIXEL = 600
"""Peak memory of rendering one scene, bytes per pixel (of ``res**2``, the MVS pass's ``(mvs_scale * res)**2``
counted too), the size-dependent part only: Mitsuba's films and wavefronts, the G-buffer and MVS arrays, the photo.
Measured as the process's peak resident memory (``ru_maxrss``) of a 1-view, 1-lighting scene at 512 and 1024 px
minus that at 64 px, per added pixel: 540 and 547 bytes (this CPU, Mitsuba 3.9 llvm_ad_rgb; 64 spp instead of 1
at 256 px did not raise it: the samples run in passes); rounded up."""
SCENE_BASE_BYTES = 600 << 20
"""What a render process holds whatever the size (Python, torch, Mitsuba's JIT): 550-580 MiB measured at 64 px."""


def scene_bytes(config: SynthConfig) -> int:
    """Estimated peak memory of rendering one scene of ``config`` (:data:`SCENE_BASE_BYTES` plus
    :data:`SCENE_BYTES_PER_PIXEL` per pixel of the photo and of the MVS pass)."""
    pixels = config.res**2 + (0 if config.mvs_scale == 1 else (config.mvs_scale * config.res) ** 2)
    return SCENE_BASE_BYTES + SCENE_BYTES_PER_PIXEL * pixels


def check_hdris(config: SynthConfig) -> list[Path]:
    """Read and validate every map the ``hdri`` kind may draw (:func:`synth.lighting.list_hdris`), before any
    work: a truncated file, a non-image or a map that is not a finite, non-negative 2:1 lat-long RGB image is a
    ``ValueError`` naming the file. Returns the maps ([] when ``hdri`` is not among the kinds)."""
    if "hdri" not in config.kinds:
        return []
    import torch

    from physrelight import envmap

    from .lighting import list_hdris

    maps = list_hdris(config.hdri_dir)
    for path in maps:
        try:
            env = envmap.read(path)
            envmap.check_envmap(torch.from_numpy(np.asarray(env, dtype=np.float32)), f"HDRI map {str(path)!r}")
        except ValueError:
            raise
        except Exception as err:  # noqa: BLE001 - OpenEXR reports a broken file as OSError or RuntimeError
            raise ValueError(f"cannot read HDRI map {str(path)!r}: {err}") from None
    return maps


def check_run(config: SynthConfig) -> None:
    """Refuse, before anything is made, a run that cannot finish: a bad input map (:func:`check_hdris`) or a
    scene that needs more memory than there is (:func:`scene_bytes`)."""
    from physrelight.cli_common import check_fits_in_memory

    check_fits_in_memory(scene_bytes(config),
                         f"rendering one {config.res} x {config.res} scene"
                         + (f" (MVS pass {config.mvs_scale * config.res} px)" if config.mvs_scale > 1 else ""))
    check_hdris(config)


def write_dataset(out: str | Path, config: SynthConfig, shard: tuple[int, int] = (0, 1),
                  progress: bool = True) -> dict:
    """Render the dataset's scenes of ``shard`` into ``out`` (resumable; checked first by :func:`check_run`).

    On failure nothing this run made is left: the scene in progress's ``.partial`` folder, and the manifest
    and the folder when this run made them and no finished scene is there (the error is re-raised after the
    progress bar is closed).

    Returns:
        ``{"rendered": [...], "skipped": [...], "seconds": float}``.
    """
    from tqdm import tqdm

    root = Path(out)
    if root.exists() and not root.is_dir():
        raise ValueError(f"output {str(root)!r} exists and is not a folder; give a dataset folder")
    check_run(config)
    made_root = not root.exists()
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as err:  # e.g. a file where a parent folder should be
        raise ValueError(f"cannot make dataset folder {str(root)!r}: {err.strerror}") from None
    made_manifest = not (root / "manifest.json").exists()
    bar = None
    current: list[int] = []
    try:
        _check_manifest(root, config)
        todo = shard_scenes(config, shard)
        done = [i for i in todo if (root / scene_name(i) / "scene.json").is_file()]
        pending = [i for i in todo if i not in done]
        units = len(pending) * config.views * config.lights
        t0 = time.perf_counter()
        bar = tqdm(total=units, unit="view-light", disable=not progress, dynamic_ncols=True,
                   desc=f"synth {len(done)}/{len(todo)} scenes done")
        for index in pending:
            current[:] = [index]
            bar.set_postfix_str(scene_name(index))
            write_scene(root, index, config, on_unit=lambda: bar.update(1))
            bar.set_description(f"synth {todo.index(index) + 1}/{len(todo)} scenes")
        current.clear()
    except BaseException:
        if bar is not None:
            bar.close()  # the error that follows gets a line of its own
        _clean_failed_run(root, current, made_root, made_manifest)
        raise
    bar.close()
    return {"rendered": [scene_name(i) for i in pending], "skipped": [scene_name(i) for i in done],
            "seconds": time.perf_counter() - t0}


def _clean_failed_run(root: Path, current: list[int], made_root: bool, made_manifest: bool) -> None:
    """After a failure: remove the scene in progress's ``.partial`` folder; the manifest when this run wrote it
    and no finished scene needs it; the folder when this run made it and it is empty."""
    for index in current:
        shutil.rmtree(root / f".{scene_name(index)}.partial", ignore_errors=True)
    if made_manifest and not list(finished_scenes(root)):
        (root / "manifest.json").unlink(missing_ok=True)
    if made_root:
        with contextlib.suppress(OSError):  # not empty: something else is there
            root.rmdir()


def scene_inputs(config: SynthConfig, index: int) -> tuple[int, Any, list[Any], list[Any]]:
    """What scene ``index`` is rendered from: ``(seed, SceneSpec, cameras, lightings)``, all seeded."""
    from . import cameras, lighting, scene

    seed = _seed(config.seed, index)
    spec = scene.generate_scene(seed % (2**31), glossy_fraction=config.glossy_fraction, trees=config.trees)
    views = cameras.sample_views(spec, config.views, seed=_seed(seed, 1) % (2**31), width=config.res,
                                 height=config.res)
    kind_rng = np.random.default_rng(_seed(seed, 2))
    lights = [lighting.sample_lighting(str(kind_rng.choice(config.kinds)), _seed(seed, 3, l), config.hdri_dir,
                                       resolution=config.env_resolution) for l in range(config.lights)]
    return seed, spec, views, lights


def write_scene(root: Path, index: int, config: SynthConfig, on_unit: Callable[[], None] = lambda: None) -> Path:
    """Render scene ``index`` into ``root/scene_XXXX`` atomically; return its folder."""
    from . import mvs, photo, render

    final = root / scene_name(index)
    partial = root / f".{scene_name(index)}.partial"
    if partial.exists():
        shutil.rmtree(partial)  # left by a killed run: start the scene again
    partial.mkdir(parents=True)
    timer = render.Timer()
    t = time.perf_counter()
    seed, spec, views, lights = scene_inputs(config, index)
    timer.add("setup", t)
    w2c = [np.asarray(v.world_to_camera, dtype=np.float64) for v in views]

    record: dict = {
        "format": FORMAT, "version": VERSION, "index": index, "seed": seed, "scene": spec.describe(),
        "config": config.scene_json(),
        "views": [{"K": np.asarray(v.K, dtype=np.float64), "world_to_camera": w2c[i], "width": v.width,
                   "height": v.height} for i, v in enumerate(views)],
        "lights": [], "photos": [[None] * config.lights for _ in views],
    }
    for li, light in enumerate(lights):
        t = time.perf_counter()
        light.save(partial / "lights" / f"light_{li:02d}")
        record["lights"].append({**light.to_json(), "sh": light.sh_record(w2c)})
        timer.add("io", t)
        t = time.perf_counter()
        mscene = render.build_scene(spec, views, light, config.spp, config.max_depth, seed=_seed(seed, 4, li) % (2**31))
        timer.add("build", t)
        for vi, cam in enumerate(views):
            vdir = partial / f"view_{vi:02d}"
            if li == 0:
                t = time.perf_counter()
                geo = render.render_geometry(mscene, vi, cam, config.gbuffer_spp, _seed(seed, 5, vi) % (2**31))
                timer.add("gbuffer", t)
                t = time.perf_counter()
                mvs_geo = geo if config.mvs_scale == 1 else render.render_geometry_scaled(
                    mscene, cam, config.mvs_scale, config.gbuffer_spp, _seed(seed, 5, vi) % (2**31))
                mvs_depth = mvs.degrade_depth(mvs_geo.depth, mvs_geo.albedo, np.random.default_rng(_seed(seed, 6, vi)))
                io.write_exr(vdir / "albedo.exr", geo.albedo)
                io.write_exr(vdir / "normal.exr", geo.normal)
                io.write_exr(vdir / "depth.exr", geo.depth)
                io.write_exr(vdir / "mvs_depth.exr", mvs_depth)
                io.write_png(vdir / "sky_mask.png", geo.sky_mask.astype(np.float32))
                io.write_png(vdir / "glossy_mask.png", (geo.glossy >= 0.5).astype(np.float32))
                timer.add("io", t)
            lb = render.render_lit(mscene, vi, light, config.spp, config.shadow_spp,
                                   _seed(seed, 7, vi, li) % (2**31), timer)
            t = time.perf_counter()
            rng = np.random.default_rng(_seed(seed, 8, vi, li))
            params = photo.sample_photo_params(rng, lb.radiance)
            ldir = vdir / f"light_{li:02d}"
            io.write_exr(ldir / "radiance.exr", lb.radiance)
            io.write_exr(ldir / "shadow.exr", lb.shadow)
            io.write_exr(ldir / "direct_shadow.exr", lb.direct_shadow)
            io.write_png(ldir / "photo.png", photo.make_photo(lb.radiance, params, rng).astype(np.float32) / 255.0)
            record["photos"][vi][li] = params.to_json()
            timer.add("io", t)
            on_unit()
    io.write_json(partial / "timing.json", timer.seconds)
    io.write_json(partial / "scene.json", record)  # last: its presence marks the scene complete
    if final.exists():
        shutil.rmtree(final)
    partial.rename(final)
    return final


def finished_scenes(root: str | Path) -> Iterable[Path]:
    """Complete scene folders under ``root``, sorted."""
    return sorted(p.parent for p in Path(root).glob("scene_*/scene.json"))
