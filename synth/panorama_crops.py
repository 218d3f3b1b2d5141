"""Real photos with exactly known lighting: pinhole crops of real HDR panoramas.

A real HDR panorama is a photograph of an outdoor place in every direction, and its texels
are the exact lighting of everything in it. A pinhole view of it (:mod:`physrelight.panorama`)
made into an 8-bit photo is therefore a real photo whose lighting is known exactly: the
whole map, turned into the camera's frame. The sky seen through that camera under *another*
panorama is the exact answer for the relit sky. ``physrelight bench --real`` is built on
these crops (docs/bench.md, "Real photos").

Per crop (:class:`Crop`): the camera (``K``, ``world_to_camera``, field of view, yaw, pitch,
level roll), the linear view at the panorama's native resolution (:func:`physrelight.panorama.native_width`,
supersampled), the 8-bit photo made by synth's photo model (metering, white balance, sRGB,
mild noise and JPEG: :func:`real_photo_params`), the full-resolution sky mask (the view of
the panorama's reviewed mask, :mod:`synth.panorama_sky`), and the lighting in the camera
frame (:meth:`Crop.lighting_sh`, :meth:`Crop.lighting_map`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from physrelight import colour, envmap, panorama, sh

from .panorama_sky import mask_path, read_sky_mask, sky_mask_procedure
from .photo import PhotoParams, make_photo, metered_ev, photo_gain

__all__ = ["ASPECT", "GROUPS", "HELDOUT_DIR", "TRAINING_DIR", "Crop", "Panorama", "crop_cameras", "folder_panoramas",
           "load_panorama", "make_crop", "make_crops", "real_photo_params", "shipped_panoramas"]

_DATA = Path(__file__).resolve().parents[1] / "physrelight" / "data"
TRAINING_DIR = _DATA / "hdri"
"""The shipped panoramas the lighting prior, the synthetic skies and so every network have seen."""
HELDOUT_DIR = _DATA / "hdri_heldout"
"""The held-out panorama(s): scored only, never trained on, fitted to or chosen by."""
INDOOR = ("studio",)
"""Shipped maps that are not outdoor: a stress case, never an outdoor score."""
GROUPS = ("heldout", "training", "indoor", "user")
ASPECT = 0.75
"""Crops are 4:3 landscape (height / width)."""
NO_SKY_FRACTION = 0.01
GROUND_FRACTION = 0.75


@dataclass
class Panorama:
    """A lat-long HDR panorama and its sky.

    Attributes:
        name: file stem.
        path: the map's file.
        env: ``(H, 2H, 3)`` float32 linear radiance, world frame, row 0 = zenith.
        sky: ``(H, 2H)`` bool, its sky texels.
        group: one of :data:`GROUPS` (``"training"``: seen in training; ``"heldout"``: never).
        mask_source: ``"reviewed"`` (the shipped ``NAME_sky.png``) or ``"procedure"``
            (:func:`synth.panorama_sky.sky_mask_procedure`, not reviewed).
    """

    name: str
    path: Path
    env: np.ndarray
    sky: np.ndarray
    group: str
    mask_source: str
    _sh: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    def sh(self, order: int) -> np.ndarray:
        """``(K, 3)`` world-frame radiance SH (exact projection, cached)."""
        if order not in self._sh:
            self._sh[order] = np.asarray(sh.project_envmap(self.env.astype(np.float64), order=order))
        return self._sh[order]

    @property
    def outdoor(self) -> bool:
        return self.group != "indoor"


def load_panorama(path: str | os.PathLike, group: str = "user") -> Panorama:
    """Read a lat-long ``.exr``/``.hdr`` map and its sky (``NAME_sky.png`` beside it, else the procedure).

    Raises:
        ValueError: unreadable, not 2:1, NaN/inf or negative radiance (one line, naming the file).
    """
    if group not in GROUPS:
        raise ValueError(f"group must be one of {GROUPS}, got {group!r}")
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"panorama {str(p)!r} does not exist")
    try:
        env = np.asarray(envmap.read(p), dtype=np.float32)
        envmap.check_envmap(torch.from_numpy(env), f"panorama {str(p)!r}")
    except (OSError, RuntimeError) as err:
        raise ValueError(f"cannot read panorama {str(p)!r}: {err}") from None
    if mask_path(p).is_file():
        sky, source = read_sky_mask(mask_path(p), env.shape[:2]), "reviewed"
    else:
        sky, source = sky_mask_procedure(env), "procedure"
    return Panorama(p.stem, p, env, sky, group, source)


def shipped_panoramas() -> list[Panorama]:
    """The shipped outdoor panoramas (``training``), studio (``indoor``) and the held-out one(s)."""
    out = [load_panorama(p, "indoor" if p.stem in INDOOR else "training") for p in sorted(TRAINING_DIR.glob("*.exr"))]
    return out + [load_panorama(p, "heldout") for p in sorted(HELDOUT_DIR.glob("*.exr"))]


def folder_panoramas(folder: str | os.PathLike) -> list[Panorama]:
    """Every ``*.exr``/``*.hdr`` lat-long map in ``folder`` (group ``"user"``).

    Raises:
        ValueError: the folder does not exist or holds no such map.
    """
    d = Path(folder)
    if not d.is_dir():
        raise ValueError(f"panorama folder {str(d)!r} does not exist")
    paths = sorted(p for p in d.iterdir() if p.suffix.lower() in (".exr", ".hdr") and p.is_file())
    if not paths:
        raise ValueError(f"panorama folder {str(d)!r} holds no .exr or .hdr panorama")
    return [load_panorama(p, "user") for p in paths]


# ----------------------------------------------------------------------------- crops


def real_photo_params(rng: np.random.Generator, radiance: np.ndarray) -> PhotoParams:
    """A tourist camera's settings for a real view: metered exposure +- 0.3 EV, white balance
    +- 3 %, the sRGB curve, mild noise (sigma 0.001-0.004) and JPEG quality 85-95."""
    ev = metered_ev(radiance) + float(rng.uniform(-0.3, 0.3))
    gains = np.exp(rng.normal(0.0, 0.03, size=3))
    gains /= gains[1]
    return PhotoParams(ev=ev, wb_gains=tuple(float(g) for g in gains), curve="srgb",
                       noise_sigma=float(rng.uniform(0.001, 0.004)), jpeg_quality=int(rng.integers(85, 96)))


@dataclass
class Crop:
    """One pinhole crop of a panorama: a real photo with known camera and lighting.

    Attributes:
        panorama: the :class:`Panorama` it is cut from.
        index: its number among the panorama's crops.
        yaw_deg, pitch_deg, fov_deg: the level camera (:func:`physrelight.panorama.level_camera`)
            and its horizontal field of view.
        K: ``(3, 3)`` intrinsics; world_to_camera: ``(4, 4)``.
        radiance: ``(h, w, 3)`` float32 linear view (the scene radiance, world units).
        photo: ``(h, w, 3)`` uint8, the photo a user would have.
        params: its :class:`synth.photo.PhotoParams`.
        sky: ``(h, w)`` bool true sky (coverage of the panorama's sky > 1/2).
        below_horizon: fraction of pixels whose ray points below the horizon.
    """

    panorama: Panorama
    index: int
    yaw_deg: float
    pitch_deg: float
    fov_deg: float
    K: np.ndarray
    world_to_camera: np.ndarray
    radiance: np.ndarray
    photo: np.ndarray
    params: PhotoParams
    sky: np.ndarray
    below_horizon: float
    rays: torch.Tensor = field(repr=False)

    @property
    def name(self) -> str:
        return f"{self.panorama.name}/{self.index}"

    @property
    def size(self) -> tuple[int, int]:
        return self.photo.shape[0], self.photo.shape[1]

    @property
    def gain(self) -> np.ndarray:
        """``(3,)`` world radiance -> the photo's linear units (``2**ev * wb_gains``)."""
        return photo_gain(self.params)

    @property
    def rotation(self) -> np.ndarray:
        """``(3, 3)`` world-to-camera rotation."""
        return self.world_to_camera[:3, :3]

    @property
    def stratum(self) -> str:
        """``"sky"``, or counted apart: ``"no_sky"`` (< 1 % true sky) or ``"ground"`` (> 3/4 below the horizon)."""
        if self.sky.mean() < NO_SKY_FRACTION:
            return "no_sky"
        return "ground" if self.below_horizon > GROUND_FRACTION else "sky"

    def lighting_sh(self, order: int = 2) -> np.ndarray:
        """``(K, 3)`` camera-frame radiance SH of the panorama, world units: ``D(R) L_world``."""
        return np.asarray(sh.rotate(self.panorama.sh(order), self.rotation))

    def lighting_map(self) -> np.ndarray:
        """``(H, 2H, 3)`` the full panorama in the camera frame (resampled: :func:`physrelight.envmap.rotate`)."""
        return np.asarray(envmap.rotate(self.panorama.env, self.rotation), dtype=np.float32)

    def view_of(self, env: np.ndarray | torch.Tensor) -> np.ndarray:
        """``(h, w, 3)`` float32 another map seen through this crop's camera (same rays, same filter)."""
        e = env if isinstance(env, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(env, dtype=np.float32))
        envmap.check_envmap(e, "env")
        return panorama.look_up(e, self.rays).numpy()

    def display(self) -> np.ndarray:
        """``(h, w, 3)`` float32 display values of the photo in [0, 1]."""
        return self.photo.astype(np.float32) / 255.0

    def linear(self) -> torch.Tensor:
        """``(1, 3, h, w)`` the photo linearised with the sRGB curve (what a method gets)."""
        t = torch.from_numpy(self.display()).permute(2, 0, 1)[None]
        return colour.from_ldr(t)


def crop_cameras(n: int, seed: int, fov_range: tuple[float, float] = (45.0, 75.0),
                 pitch_range: tuple[float, float] = (-5.0, 20.0)) -> list[tuple[float, float, float]]:
    """``n`` (yaw, pitch, fov) in degrees: yaws evenly spread round the circle from a seeded
    start, pitch and field of view uniform in their ranges (seeded)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"the number of crops must be a positive integer, got {n!r}")
    lo, hi = fov_range
    if not (0.0 < lo <= hi <= panorama.MAX_FOV_DEG):
        raise ValueError(f"a crop's field of view must lie in (0, {panorama.MAX_FOV_DEG:g}] degrees, got {fov_range}")
    if not (-90.0 < pitch_range[0] <= pitch_range[1] < 90.0):
        raise ValueError(f"pitch range must lie in (-90, 90) degrees, got {pitch_range}")
    rng = np.random.default_rng(seed)
    start = float(rng.uniform(0.0, 360.0))
    return [((start + 360.0 * k / n) % 360.0, float(rng.uniform(*pitch_range)), float(rng.uniform(lo, hi)))
            for k in range(n)]


def make_crop(pano: Panorama, index: int, yaw_deg: float, pitch_deg: float, fov_deg: float,
              rng: np.random.Generator, samples: int = 4, width: int | None = None) -> Crop:
    """One crop at the panorama's native resolution (or ``width``, never wider than native).

    Args:
        samples: sub-pixel rays per axis (:func:`physrelight.panorama.view`).
        rng: draws the photo's settings and noise.
    """
    native = panorama.native_width(fov_deg, ASPECT, pano.env.shape[1])
    if width is not None and width > native:
        raise ValueError(f"a {fov_deg:.1f} deg crop of {pano.name!r} is at most {native} px wide natively, "
                         f"{width} px would upsample it")
    w = width or native
    h = max(1, round(w * ASPECT))
    K = panorama.view_intrinsics(fov_deg, w, h)
    T = panorama.level_camera(yaw_deg, pitch_deg)
    rays = panorama.camera_rays(K, T, h, w, samples).to(torch.float32)
    env = torch.from_numpy(pano.env)
    radiance = panorama.look_up(env, rays).numpy()
    cover = panorama.look_up(torch.from_numpy(pano.sky.astype(np.float32))[..., None], rays)[..., 0].numpy()
    params = real_photo_params(rng, radiance)
    photo = make_photo(radiance, params, rng)
    below = float((rays[..., 1] < 0).float().mean())
    return Crop(pano, index, float(yaw_deg), float(pitch_deg), float(fov_deg), K, T, radiance, photo, params,
                cover > 0.5, below, rays)


def make_crops(pano: Panorama, n: int, seed: int = 0, fov_range: tuple[float, float] = (45.0, 75.0),
               pitch_range: tuple[float, float] = (-5.0, 20.0), samples: int = 4) -> list[Crop]:
    """``n`` crops of ``pano`` (:func:`crop_cameras`); the same seed and panorama name give the same bytes."""
    key = np.random.SeedSequence([seed, *pano.name.encode()])
    cam_seed, photo_seed = key.spawn(2)
    cams = crop_cameras(n, int(cam_seed.generate_state(1)[0]), fov_range, pitch_range)
    rngs = [np.random.default_rng(s) for s in photo_seed.spawn(n)]
    return [make_crop(pano, i, *cam, rngs[i], samples) for i, cam in enumerate(cams)]
