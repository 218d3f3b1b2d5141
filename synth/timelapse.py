"""A synthetic day in BigTime's layout: one fixed view of a synth scene, the sun moving through a day.

BigTime (Li & Snavely 2018, "Learning Intrinsic Image Decomposition from Watching the World") ships
each time-lapse sequence as a folder of frames of one fixed camera, each frame with an optional mask
beside it (its training loader reads ``ROOT/<sequence>/data/<frame>.jpg`` and
``ROOT/<sequence>/data/<frame>_mask.png``, white = pixels to use)::

    ROOT/day_000/data/0630.jpg          frame (8-bit sRGB JPEG, the hour as HHMM)
    ROOT/day_000/data/0630_mask.png     its foreground mask (255 = not sky, a surface)
    ROOT/day_000/lighting.json          not BigTime's: the ground truth of the synthetic day

``lighting.json`` (format ``physrelight-timelapse-truth``) gives, per frame, the order-2 radiance SH of
the whole lighting (``sh``) and of the sun alone (``sun_sh``), both in the camera frame and in that
frame's linear photo units (``radiance * 2**ev``), plus the sun's elevation and azimuth and the photo
parameters. ``physrelight bench --timelapse`` reads it when present, for its given-lighting rows.

Rendering follows :func:`synth.writer.write_scene` (same scene generator, cameras, renderer, sky model);
the photos are those of a fixed time-lapse camera: metered exposure per frame (auto-exposure, as
webcam sequences are), neutral white balance, sRGB curve, light sensor noise, JPEG. A sequence is
written into ``ROOT/.NAME.partial`` and renamed when complete; the same arguments give the same bytes.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from physrelight import io

__all__ = ["DEFAULT_HOURS", "TRUTH_FORMAT", "frame_name", "sun_path", "write_day", "write_days"]

TRUTH_FORMAT = "physrelight-timelapse-truth"
DEFAULT_HOURS = (6.5, 8.0, 9.5, 11.0, 12.5, 14.0, 15.5, 17.0)
"""One frame per 1.5 h, as the bench's generated time-lapse views (``validation.bench.run.FULL_EXTRA``)."""
NOISE_SIGMA = 0.002
"""Sensor noise of the time-lapse camera, linear exposed units (a clean webcam)."""
JPEG_QUALITY = 95


def _seed(*keys: int) -> int:
    """A 32-bit seed derived from integers (stable across runs and platforms)."""
    return int(np.random.SeedSequence([int(k) for k in keys]).generate_state(1)[0])


def sun_path(hours: Sequence[float], latitude_deg: float = 40.0, declination_deg: float = 10.0,
             min_elevation: float = 3.0) -> list[tuple[float, float, float]]:
    """``(hour, elevation, azimuth)`` in degrees of the sun at local solar ``hours`` (azimuth clockwise from
    north = -Z, synth's convention), keeping the hours with the sun at least ``min_elevation`` up.

    Standard spherical astronomy, no refraction; the bench's time-lapse view takes its sun from here too
    (:func:`validation.bench.data.timelapse_lights`).
    """
    phi, dec = math.radians(latitude_deg), math.radians(declination_deg)
    out = []
    for h in hours:
        H = math.radians(15.0 * (float(h) - 12.0))
        el = math.asin(math.sin(phi) * math.sin(dec) + math.cos(phi) * math.cos(dec) * math.cos(H))
        az = math.atan2(-math.sin(H) * math.cos(dec),
                        math.cos(phi) * math.sin(dec) - math.sin(phi) * math.cos(dec) * math.cos(H))
        if math.degrees(el) >= min_elevation:
            out.append((float(h), math.degrees(el), math.degrees(az) % 360.0))
    return out


def frame_name(hour: float) -> str:
    """``6.5 -> "0630"``: a frame's file stem, its local solar time (sorts in time order)."""
    minutes = int(round(float(hour) * 60.0))
    return f"{minutes // 60:02d}{minutes % 60:02d}"


def write_day(root: str | Path, name: str = "day_000", seed: int = 0, hours: Sequence[float] = DEFAULT_HOURS,
              res: int = 128, spp: int = 32, env_res: int = 32, texture_size: int = 64,
              progress: Callable[[str], None] = lambda m: None) -> Path:
    """Render one fixed view of scene ``seed`` at each of ``hours`` and write it as ``root/name``.

    Args:
        root: the BigTime-layout folder (made if missing).
        name: the sequence's folder name.
        seed: scene, camera and photo-noise seed (same seed, same bytes).
        hours: local solar times; hours with the sun below 3 deg are left out (at least 2 must remain).
        res: the frames' width and height in pixels.
        spp, env_res, texture_size: samples per pixel, sky map height and texture size of the render.

    Returns:
        the sequence folder ``root/name``.
    """
    from . import cameras, lighting, photo, render, scene
    from physrelight import sh

    if not name or "/" in name or name.startswith("."):
        raise ValueError(f"a sequence name must be a plain folder name, got {name!r}")
    if res < 16:
        raise ValueError(f"res must be at least 16 px, got {res}")
    path = sun_path(hours)
    if len(path) < 2:
        raise ValueError(f"a time-lapse needs at least 2 frames with the sun up; hours {list(hours)} give {len(path)}")
    names = [frame_name(h) for h, _, _ in path]
    if len(set(names)) != len(names):
        raise ValueError(f"hours {list(hours)} name two frames alike ({names})")
    root = Path(root)
    final, partial = root / name, root / f".{name}.partial"
    if partial.exists():
        shutil.rmtree(partial)  # left by a killed run
    data = partial / "data"
    data.mkdir(parents=True)

    base = _seed(seed, 4242)
    spec = scene.generate_scene(seed, texture_size=texture_size)
    cam = cameras.sample_views(spec, 1, seed=_seed(base, 1) % (2**31), width=res, height=res)[0]
    w2c = np.asarray(cam.world_to_camera, dtype=np.float64)
    rotation = np.asarray(sh.rotation(w2c[:3, :3], 2))
    frames: dict[str, Any] = {}
    mask = None
    for k, (hour, elevation, azimuth) in enumerate(path):
        progress(f"{name}: rendering {names[k]} (sun {elevation:.0f} deg up, azimuth {azimuth:.0f} deg)")
        light = lighting.sunsky(0, elevation_deg=elevation, azimuth_deg=azimuth, turbidity=3.0, albedo=0.2,
                                resolution=env_res)
        msc = render.build_scene(spec, [cam], light, spp, 8, seed=_seed(base, 4, k) % (2**31))
        if mask is None:  # one camera: one geometry, one mask for every frame
            geo = render.render_geometry(msc, 0, cam, 16, _seed(base, 5) % (2**31))
            mask = ~geo.sky_mask & (np.linalg.norm(geo.normal, axis=-1) > 0.5)
        lb = render.render_lit(msc, 0, light, spp, 32, _seed(base, 7, k) % (2**31))
        rng = np.random.default_rng(_seed(base, 8, k))
        params = photo.PhotoParams(ev=photo.metered_ev(lb.radiance), wb_gains=(1.0, 1.0, 1.0), curve="srgb",
                                   noise_sigma=NOISE_SIGMA, jpeg_quality=None)
        u8 = photo.make_photo(lb.radiance, params, rng)
        _write_jpeg(data / f"{names[k]}.jpg", u8)
        io.write_png(data / f"{names[k]}_mask.png", mask.astype(np.float32))
        gain = photo.photo_gain(params)
        sun = np.asarray(sh.project_sun(np.asarray(light.sun_direction, np.float64),
                                        np.asarray(light.sun_irradiance, np.float64), 2))
        frames[names[k]] = {"hour": hour, "sun_elevation_deg": elevation, "sun_azimuth_deg": azimuth,
                            "sh": light.sh(2, w2c) * gain[None, :], "sun_sh": rotation @ sun * gain[None, :],
                            "photo_params": params.to_json()}
    io.write_json(partial / "lighting.json", {
        "format": TRUTH_FORMAT, "version": 1, "seed": seed, "res": res, "spp": spp, "env_res": env_res,
        "K": np.asarray(cam.K, dtype=np.float64), "world_to_camera": w2c,
        "units": "order-2 radiance SH, camera frame (x right, y up, z to the viewer), the frame's linear photo units",
        "frames": frames})
    if final.exists():
        shutil.rmtree(final)
    partial.rename(final)
    return final


def _write_jpeg(path: Path, u8: np.ndarray) -> None:
    """An 8-bit ``(H, W, 3)`` frame as a baseline JPEG (PIL's encoder is deterministic: same array, same bytes)."""
    from PIL import Image

    with io.atomic_path(path, ".jpg") as tmp:
        Image.fromarray(u8).save(tmp, format="JPEG", quality=JPEG_QUALITY, subsampling=0)


def write_days(root: str | Path, days: int = 1, seed: int = 0, **kwargs: Any) -> list[Path]:
    """:func:`write_day` for ``days`` scenes (``day_000``, ``day_001``, ...; scene seeds ``seed``, ``seed + 1``,
    ...): a BigTime-layout folder of several sequences. ``kwargs`` go to :func:`write_day`."""
    if days < 1:
        raise ValueError(f"days must be at least 1, got {days}")
    return [write_day(root, f"day_{d:03d}", seed + d, **kwargs) for d in range(days)]
