"""Illumination for the synthetic dataset: sun and sky, overcast, evening, real HDRIs.

Every lighting is a :class:`Lighting` record: a world-frame lat-long map of all the
light except the sun (``sky``), plus, where there is one, a sun given by its direction,
its irradiance and its angular radius. The record is what the renderer gets
(:meth:`Lighting.mitsuba_emitters`) and what the SH is computed from
(:meth:`Lighting.sh`), so the two cannot drift apart.

Conventions (DESIGN.md, world frame Y up)
-----------------------------------------

Maps
    ``(H, W, 3)`` float32 radiance, ``W == 2 H``, Mitsuba's lat-long layout
    (:mod:`physrelight.envmap`). ``resolution`` below is ``H``.

Elevation and azimuth of a direction ``d``
    ``elevation = asin(d.y)``; ``azimuth = atan2(d.x, -d.z)`` in degrees, in [0, 360).
    Azimuth 0 is -Z ("north"), 90 is +X ("east"): a compass bearing, clockwise seen
    from above. It is ``360 u`` of the lat-long map, so a sun at azimuth ``a`` sits in
    column ``a / 360 * W``. ``d = (cos e sin a, sin e, -cos e cos a)``.

Units
    Mitsuba's ``sunsky`` units are kept (its RGB radiance, which includes Mitsuba's
    CIE-Y normalisation; only ratios matter for the photos). HDRIs keep their file
    values. Every record carries a suggested exposure in ``params``:
    ``exposure_scale = 0.18 pi / Y(E_up)`` (``Y`` = luminance, ``E_up`` = irradiance on
    an upward-facing surface), so a white horizontal surface renders at 0.18 after
    multiplying radiance by it; ``exposure_stops = log2(exposure_scale)``.

Kinds
-----

``sunsky``
    Mitsuba 3's ``sunsky`` (Hosek-Wilkie sky and sun). The sky is evaluated with
    ``sun_scale = 0`` at the texel directions (one batched ``eval``). The sun is a disk
    of radius :data:`SUN_RADIUS_DEG` whose irradiance is integrated with the emitter's
    own sampling routine (``sky_scale = 0``), i.e. exactly the sun a Mitsuba render
    of ``sunsky`` puts on a diffuse surface. Sunsky returns 0 below its horizon (sky
    and sun), so the lower half of the map is black: scenes have a ground.
``overcast``
    The same sky with the sun switched off and a high turbidity (8-10). This is *not*
    a CIE overcast sky: Hosek-Wilkie is a clear-sky model, so the result is a bright
    hazy sky with a circumsolar glow around a hidden sun and no direct sunlight. It
    gives soft, sun-free lighting without hard shadows; it does not give the
    zenith-bright, azimuth-independent luminance of a real overcast day.
``evening``
    ``sunsky`` with a low sun, elevation in :data:`EVENING_ELEVATION_RANGE`.
``hdri``
    A real map read from an EXR, turned about +Y by an azimuth. By default the sun is
    split off (:func:`physrelight.envmap.split_sun`, exactly energy conserving) and
    becomes a directional light; the record's ``sky`` is the rotated map minus the
    sun. The render uses that same sky + sun, so record and render agree exactly.

The sun in the renderer
-----------------------

Mitsuba 3 allows one environment emitter per scene ("Only one environment emitter can
be specified per scene"), so ``sunsky`` with ``sky_scale = 0`` cannot sit beside the
sky's ``envmap``. The sun is therefore a ``directional`` emitter carrying the
disk-integrated irradiance: a delta direction. Its SH is ``project_sun`` exactly. The
disk's finite size only matters for the penumbra (0.27 deg: usually below a pixel
in our renders) and changes band ``l`` of the SH by a factor ``1 - O(l^2 alpha^2)``
(1e-4 at l = 4); ``sun_radius_deg`` is recorded for soft-shadow ground truth. (In
``llvm_ad_rgb`` the sunsky disk has uniform radiance: no limb darkening, measured.)

Measured (tests/synth/test_lighting.py, H = 256, 4 x 2048 spp): path-traced irradiance
on white plates under this sky envmap + directional sun equals that under Mitsuba's
full ``sunsky`` within 1 +- 0.0014 (standard error <= 0.0013) for sunsky, evening and
overcast, and equals the record's brute-force irradiance within 0.1 %.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Iterable, Sequence

import numpy as np

from physrelight import envmap as _envmap
from physrelight import sh as _sh
from physrelight.io import atomic_path, read_json

__all__ = [
    "EVENING_ELEVATION_RANGE",
    "FORMAT",
    "HDRI_DIR",
    "INDOOR_HDRIS",
    "KINDS",
    "KINDS_FILE",
    "Lighting",
    "SUNSKY_ELEVATION_RANGE",
    "SUN_RADIUS_DEG",
    "SUN_APERTURE_DEG",
    "angles_from_direction",
    "direction_from_angles",
    "eval_emitter",
    "evening",
    "hdri",
    "is_indoor_hdri",
    "list_hdris",
    "overcast",
    "sample_lighting",
    "sunsky",
]

FORMAT = "physrelight.lighting"
VERSION = 1

KINDS = ("sunsky", "overcast", "evening", "hdri")

SUN_APERTURE_DEG = 0.5358
"""Full angular diameter of the sun, Mitsuba's ``sunsky`` default."""
SUN_RADIUS_DEG = SUN_APERTURE_DEG / 2

SUNSKY_ELEVATION_RANGE = (15.0, 75.0)
EVENING_ELEVATION_RANGE = (2.0, 12.0)
OVERCAST_ELEVATION_RANGE = (15.0, 75.0)  # the hidden sun still shapes the sky's glow
TURBIDITY_RANGE = (2.0, 6.0)
OVERCAST_TURBIDITY_RANGE = (8.0, 10.0)
GROUND_ALBEDO_RANGE = (0.1, 0.4)
MITSUBA_TURBIDITY_RANGE = (1.0, 10.0)
EVENING_MAX_ELEVATION = 20.0
"""Largest elevation :func:`evening` accepts when it is given explicitly."""

HDRI_DIR = Path(__file__).resolve().parents[1] / "physrelight" / "data" / "hdri"
"""The maps that ship with the package (CC0): city, courtyard, forest, studio."""
INDOOR_HDRIS = frozenset({"studio"})
"""Map names (file stems) left out of outdoor sampling unless asked for."""
KINDS_FILE = "kinds.json"
"""A folder's map kinds (``{"NAME": "outdoor" | "indoor" | "walkway"}``, as ``physrelight/data/hdri_more`` has):
a map named there as anything but ``outdoor`` is left out of outdoor sampling like :data:`INDOOR_HDRIS`."""


def is_indoor_hdri(path: str | os.PathLike) -> bool:
    """Whether the map at ``path`` is not an outdoor one: its stem in :data:`INDOOR_HDRIS`, or a kind other than
    ``outdoor`` in the :data:`KINDS_FILE` beside it."""
    p = Path(path)
    if p.stem in INDOOR_HDRIS:
        return True
    kinds_file = p.parent / KINDS_FILE
    if not kinds_file.is_file():
        return False
    try:
        kinds = json.loads(kinds_file.read_text())
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read the map kinds {str(kinds_file)!r}: {err}") from None
    return isinstance(kinds, dict) and kinds.get(p.stem, "outdoor") != "outdoor"

EXPOSURE_TARGET = 0.18 * math.pi
"""``exposure_scale * Y(E_up)``: a white horizontal surface renders at 0.18."""

# Mitsuba's sunsky is Z-up; this turns its frame into our Y-up world (DESIGN.md).
_SUNSKY_TO_WORLD_AXIS, _SUNSKY_TO_WORLD_DEG = (1.0, 0.0, 0.0), -90.0
# Stratified samples per axis for the sun-disk integral through sunsky's own sampler.
_SUN_QUADRATURE = 64
_LUM = np.asarray(_envmap.LUMINANCE)


# ------------------------------------------------------------------ angles


def direction_from_angles(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """``(3,)`` unit world direction for an elevation and azimuth in degrees (see module doc)."""
    _check_finite_number(elevation_deg, "elevation_deg")
    _check_finite_number(azimuth_deg, "azimuth_deg")
    return _envmap.direction_from_angles(float(elevation_deg), float(azimuth_deg))


def angles_from_direction(direction: Sequence[float] | np.ndarray) -> tuple[float, float]:
    """``(elevation_deg, azimuth_deg in [0, 360))`` of a world direction (normalised here)."""
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or np.linalg.norm(d) < 1e-12:
        raise ValueError(f"direction must be a finite non-zero (3,) vector, got {direction!r}")
    d = d / np.linalg.norm(d)
    elevation = math.degrees(math.asin(float(np.clip(d[1], -1.0, 1.0))))
    azimuth = math.degrees(math.atan2(d[0], -d[2])) % 360.0
    return elevation, azimuth


# ------------------------------------------------------------------ checks


def _check_finite_number(x: Any, name: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)) or not math.isfinite(x):
        raise ValueError(f"{name} must be a finite number, got {x!r}")
    return float(x)


def _check_range(x: float, lo: float, hi: float, name: str, lo_open: bool = False) -> float:
    x = _check_finite_number(x, name)
    if (x <= lo if lo_open else x < lo) or x > hi:
        bracket = "(" if lo_open else "["
        raise ValueError(f"{name} must be in {bracket}{lo}, {hi}], got {x}")
    return x


def _check_resolution(resolution: Any) -> int:
    if isinstance(resolution, bool) or not isinstance(resolution, (int, np.integer)) or resolution < 8:
        raise ValueError(f"resolution (map height H; width is 2 H) must be an integer >= 8, got {resolution!r}")
    return int(resolution)


def _rng(seed: int | np.random.Generator) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or a numpy Generator, got {seed!r}")
    return np.random.default_rng(int(seed))


def _check_kind(kind: Any) -> str:
    if kind not in KINDS:
        raise ValueError(f"unknown lighting kind {kind!r}; expected one of {', '.join(KINDS)}")
    return kind


# ------------------------------------------------------------------ the record


@dataclass(eq=False)
class Lighting:
    """One illumination: a sky map plus an optional sun, all in the world frame (Y up).

    Attributes:
        kind: one of :data:`KINDS`.
        params: JSON-serialisable parameters (angles in degrees, turbidity, ground
            albedo, HDRI name and azimuth, scale, suggested exposure, ...).
        sky: ``(H, W, 3)`` float32 lat-long radiance of all light except the sun (for
            an HDRI without a split sun, the whole rotated map).
        sun_direction: ``(3,)`` unit direction *towards* the sun, or ``None``.
        sun_irradiance: ``(3,)`` sun irradiance on a surface facing it; zeros if none.
        sun_radius_deg: angular radius of the sun disk (for soft-shadow ground truth).
    """

    kind: str
    params: dict[str, Any]
    sky: np.ndarray
    sun_direction: np.ndarray | None = None
    sun_irradiance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sun_radius_deg: float = SUN_RADIUS_DEG
    _sh_cache: dict[int, np.ndarray] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        _check_kind(self.kind)
        if not isinstance(self.params, dict):
            raise ValueError(f"params must be a dict, got {type(self.params).__name__}")
        try:
            json.dumps(self.params)
        except (TypeError, ValueError) as err:
            raise ValueError(f"params must be JSON-serialisable: {err}") from None
        sky = np.asarray(self.sky)
        if sky.ndim != 3 or sky.shape[-1] != 3 or sky.shape[0] < 2 or sky.shape[1] != 2 * sky.shape[0]:
            raise ValueError(f"sky must be an (H, W, 3) lat-long map with W == 2 H, got shape {sky.shape}")
        if not np.all(np.isfinite(sky)) or (sky.size and sky.min() < 0):
            raise ValueError("sky must hold finite, non-negative radiance")
        self.sky = np.ascontiguousarray(sky, dtype=np.float32)
        e = np.asarray(self.sun_irradiance, dtype=np.float64)
        if e.shape != (3,) or not np.all(np.isfinite(e)) or e.min() < 0:
            raise ValueError(f"sun_irradiance must be a finite non-negative (3,) vector, got {self.sun_irradiance!r}")
        self.sun_irradiance = e
        if self.sun_direction is None:
            if e.any():
                raise ValueError("sun_irradiance must be zero when there is no sun (sun_direction is None)")
        else:
            s = np.asarray(self.sun_direction, dtype=np.float64)
            if s.shape != (3,) or not np.all(np.isfinite(s)) or abs(np.linalg.norm(s) - 1.0) > 1e-6:
                raise ValueError(f"sun_direction must be a unit (3,) vector or None, got {self.sun_direction!r}")
            self.sun_direction = s / np.linalg.norm(s)
        self.sun_radius_deg = _check_range(self.sun_radius_deg, 0.0, 45.0, "sun_radius_deg", lo_open=True)

    # -------------------------------------------------------------- queries

    @property
    def has_sun(self) -> bool:
        return self.sun_direction is not None

    @property
    def resolution(self) -> int:
        """Height ``H`` of the sky map."""
        return int(self.sky.shape[0])

    def sh(self, order: int = 2, world_to_camera: Any = None) -> np.ndarray:
        """Radiance SH of the whole lighting (sky + sun), ``(K, 3)`` float64, ``K = (order+1)^2``.

        ``project_envmap(sky)`` (exact for the map as Mitsuba interpolates it) plus
        ``project_sun(sun)`` (exact for the delta the renderer uses).

        Args:
            order: SH order (0..8).
            world_to_camera: ``None`` for the world frame, or a ``(4, 4)`` world-to-camera
                transform (or its ``(3, 3)`` rotation ``R_wc``): the result is then
                ``D(R_wc) @ sh_world``, the lighting in that camera's frame.
        """
        _sh.num_coeffs(order)  # validates the order (ValueError outside 0..MAX_ORDER)
        order = int(order)
        if order not in self._sh_cache:
            c = np.asarray(_sh.project_envmap(self.sky.astype(np.float64), order), dtype=np.float64)
            if self.has_sun:
                c = c + np.asarray(_sh.project_sun(self.sun_direction, self.sun_irradiance, order))
            c.setflags(write=False)
            self._sh_cache[order] = c
        world = self._sh_cache[order]
        if world_to_camera is None:
            return world.copy()
        R = _rotation_of(world_to_camera)
        return np.asarray(_sh.rotation(R, order)) @ world

    def sh_record(self, world_to_cameras: Iterable[Any] = (), orders: Sequence[int] = (2, 4)) -> dict[str, Any]:
        """JSON-ready SH: ``{"world": {"2": [[...]], "4": ...}, "cameras": [{"2": ..., "4": ...}, ...]}``.

        ``cameras[i]`` is the lighting in the frame of ``world_to_cameras[i]`` (``(4, 4)``).
        """
        return {
            "world": {str(o): self.sh(o).tolist() for o in orders},
            "cameras": [{str(o): self.sh(o, T).tolist() for o in orders} for T in world_to_cameras],
        }

    def irradiance_reference(self, normals: Any) -> np.ndarray:
        """Brute-force irradiance ``(N, 3)`` on world normals ``(N, 3)``: texel sum over the
        sky plus ``sun_irradiance * max(0, n . s)``. The yardstick renders are checked against."""
        n = np.asarray(normals, dtype=np.float64)
        if n.ndim != 2 or n.shape[1] != 3:
            raise ValueError(f"normals must have shape (N, 3), got {n.shape}")
        e = np.asarray(_envmap.irradiance_reference(self.sky.astype(np.float64), n))
        if self.has_sun:
            nn = n / np.linalg.norm(n, axis=1, keepdims=True)
            e = e + np.clip(nn @ self.sun_direction, 0.0, None)[:, None] * self.sun_irradiance[None]
        return e

    def total_envmap(self) -> np.ndarray:
        """``(H, W, 3)`` float32: the sky with the sun splatted into it.

        The sun's irradiance is spread over the four texels of the bilinear cell around
        its direction with bilinear weights, each divided by the texel's solid angle, so
        ``int L dw`` of the result is exactly that of the sky plus the sun's irradiance
        and its centroid stays at the sun. For display and brute-force checks; a
        texel-wide sun, not the 0.5 degree disk.
        """
        total = self.sky.astype(np.float64).copy()
        if self.has_sun:
            h, w = total.shape[:2]
            dw = _envmap.solid_angles(h, w)
            s = self.sun_direction
            u = (math.atan2(s[0], -s[2]) / (2 * math.pi)) % 1.0
            v = math.acos(float(np.clip(s[1], -1.0, 1.0))) / math.pi
            x, y = u * w - 0.5, v * (h - 1)
            x0, y0 = math.floor(x), min(max(math.floor(y), 0), h - 2)
            fx, fy = x - x0, y - y0
            for (yy, xx, wt) in ((y0, x0, (1 - fx) * (1 - fy)), (y0, x0 + 1, fx * (1 - fy)),
                                 (y0 + 1, x0, (1 - fx) * fy), (y0 + 1, x0 + 1, fx * fy)):
                xx %= w
                total[yy, xx] += self.sun_irradiance * wt / dw[yy, xx]
        return total.astype(np.float32)

    # -------------------------------------------------------------- Mitsuba

    def mitsuba_emitters(self, mi: ModuleType) -> dict[str, dict[str, Any]]:
        """Mitsuba emitter dicts for a scene dict: ``{"sky": envmap, "sun": directional}``.

        ``"sky"`` is an ``envmap`` built from a ``mi.Bitmap`` of :attr:`sky` (default
        ``to_world``: Mitsuba's lat-long frame is our Y-up world). ``"sun"`` (only if
        there is a sun) is a ``directional`` emitter travelling along ``-sun_direction``
        with ``irradiance = sun_irradiance``. Mitsuba refuses a second environment
        emitter, so the sun cannot be a ``sunsky`` with ``sky_scale = 0`` beside the
        envmap (see the module doc). An all-black sky is left out.

        Args:
            mi: the mitsuba module, from :func:`synth.backend.load_mitsuba`.
        """
        out: dict[str, dict[str, Any]] = {}
        if self.sky.any():
            out["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(np.ascontiguousarray(self.sky))}
        if self.has_sun:
            out["sun"] = {
                "type": "directional",
                "direction": [float(x) for x in -self.sun_direction],
                "irradiance": {"type": "rgb", "value": [float(x) for x in self.sun_irradiance]},
            }
        return out

    def reference_emitters(self, mi: ModuleType) -> dict[str, dict[str, Any]]:
        """The original analytic light for sunsky kinds: ``{"sunsky": <Mitsuba sunsky dict>}``.

        Sun and sky together, as Mitsuba models them (for validating the record). Raises
        ``ValueError`` for ``hdri``, whose original is just a map.
        """
        if self.kind == "hdri":
            raise ValueError("reference_emitters exists for sunsky kinds only; an HDRI's reference is its map")
        p = self.params
        return {"sunsky": _sunsky_dict(
            mi, direction_from_angles(p["sun_elevation_deg"], p["sun_azimuth_deg"]), p["turbidity"],
            p["ground_albedo"], sky_scale=p["scale"], sun_scale=p["scale"] * float(self.has_sun))}

    # -------------------------------------------------------------- IO

    def to_json(self) -> dict[str, Any]:
        """Everything but the map, JSON-ready (the map goes to an EXR beside it).

        Holds the world-frame SH of orders 2 and 4 for readers that want them without
        the map, and the map's shape and SHA-256 so a reader can tell it has the right one.
        """
        return {
            "format": FORMAT,
            "version": VERSION,
            "kind": self.kind,
            "params": self.params,
            "sun_direction": None if self.sun_direction is None else [float(x) for x in self.sun_direction],
            "sun_irradiance": [float(x) for x in self.sun_irradiance],
            "sun_radius_deg": float(self.sun_radius_deg),
            "sky_shape": [int(x) for x in self.sky.shape],
            "sky_sha256": _sha256(self.sky),
            "sh_world": {str(o): self.sh(o).tolist() for o in (2, 4)},
        }

    @classmethod
    def from_json(cls, data: dict[str, Any] | str, sky: np.ndarray, verify: bool = False) -> "Lighting":
        """Rebuild from :meth:`to_json` output (dict or JSON text) and the sky map.

        Args:
            data: the record.
            sky: ``(H, W, 3)`` map; its shape must match the record's.
            verify: also require the map's bytes to match the recorded SHA-256 (true
                when the map is the float32 EXR written by :meth:`save`).
        """
        if isinstance(data, str):
            try:
                data = json.loads(data)
            except json.JSONDecodeError as err:
                raise ValueError(f"lighting record is not valid JSON: {err}") from None
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError(f"not a lighting record (format must be {FORMAT!r})")
        if data.get("version") != VERSION:
            raise ValueError(f"unsupported lighting record version {data.get('version')!r}; this reads {VERSION}")
        missing = {"kind", "params", "sun_direction", "sun_irradiance", "sun_radius_deg"} - set(data)
        if missing:
            raise ValueError(f"lighting record lacks {sorted(missing)}")
        sky = np.asarray(sky, dtype=np.float32)
        if "sky_shape" in data and list(sky.shape) != list(data["sky_shape"]):
            raise ValueError(f"sky map has shape {sky.shape}, the record says {tuple(data['sky_shape'])}")
        if verify and data.get("sky_sha256") != _sha256(sky):
            raise ValueError("sky map does not match the record (SHA-256 differs): wrong or modified env map")
        s = data["sun_direction"]
        return cls(kind=data["kind"], params=data["params"], sky=sky,
                   sun_direction=None if s is None else np.asarray(s, dtype=np.float64),
                   sun_irradiance=np.asarray(data["sun_irradiance"], dtype=np.float64),
                   sun_radius_deg=float(data["sun_radius_deg"]))

    def save(self, directory: str | os.PathLike) -> None:
        """Write ``env.exr`` (the sky, float32 lossless) and ``lighting.json`` into ``directory``.

        Each file is written atomically, the JSON last: a folder with ``lighting.json``
        holds a complete record.
        """
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        _envmap.write(d / "env.exr", self.sky)
        text = json.dumps(self.to_json(), indent=2, sort_keys=True) + "\n"
        with atomic_path(d / "lighting.json", ".json") as tmp:
            tmp.write_text(text)

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "Lighting":
        """Read what :meth:`save` wrote (the map's bytes are checked against the record)."""
        d = Path(directory)
        if not (d / "lighting.json").is_file():
            raise ValueError(f"{str(d)!r} holds no lighting.json")
        return cls.from_json(read_json(d / "lighting.json"), _envmap.read(d / "env.exr"), verify=True)


def _sha256(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float32).tobytes()).hexdigest()


def _rotation_of(world_to_camera: Any) -> np.ndarray:
    try:
        import torch

        if isinstance(world_to_camera, torch.Tensor):
            world_to_camera = world_to_camera.detach().cpu().numpy()
    except ImportError:  # pragma: no cover - torch is a hard dependency of physrelight
        pass
    T = np.asarray(world_to_camera, dtype=np.float64)
    if T.shape not in ((4, 4), (3, 3)):
        raise ValueError(f"world_to_camera must be a (4, 4) transform or a (3, 3) rotation, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError("world_to_camera holds non-finite values")
    return T[:3, :3]


# ------------------------------------------------------------------ Mitsuba helpers


def _mitsuba() -> ModuleType:
    from synth.backend import load_mitsuba  # selects the variant before mitsuba is imported

    return load_mitsuba()


def _sunsky_dict(mi: ModuleType, direction: np.ndarray, turbidity: float, albedo: float,
                 sky_scale: float = 1.0, sun_scale: float = 1.0) -> dict[str, Any]:
    return {
        "type": "sunsky",
        "sun_direction": [float(x) for x in direction],  # world space (DESIGN.md)
        "to_world": mi.ScalarTransform4f().rotate(list(_SUNSKY_TO_WORLD_AXIS), _SUNSKY_TO_WORLD_DEG),
        "turbidity": float(turbidity),
        "albedo": float(albedo),
        "sun_aperture": SUN_APERTURE_DEG,
        "sky_scale": float(sky_scale),
        "sun_scale": float(sun_scale),
    }


def _is_scalar(mi: ModuleType) -> bool:
    return mi.variant().startswith("scalar")


def eval_emitter(mi: ModuleType, emitter: Any, directions: np.ndarray) -> np.ndarray:
    """Radiance ``(N, 3)`` float64 an environment emitter sends *from* world directions ``(N, 3)``.

    One batched ``emitter.eval`` call (``si.wi = -direction``: ``wi`` points towards
    the scene); a per-direction loop in Mitsuba's scalar variant.
    """
    import drjit as dr

    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    if _is_scalar(mi):
        out = np.empty((d.shape[0], 3))
        si = dr.zeros(mi.SurfaceInteraction3f)
        for i, di in enumerate(d):
            si.wi = mi.Vector3f(*(-di))
            out[i] = np.asarray(emitter.eval(si), dtype=np.float64).reshape(3)
        return out
    si = dr.zeros(mi.SurfaceInteraction3f, d.shape[0])
    si.wi = mi.Vector3f(*(-d.T))
    return np.asarray(emitter.eval(si), dtype=np.float64).T.copy()


def _sun_disk_irradiance(mi: ModuleType, sun_only: Any, direction: np.ndarray) -> np.ndarray:
    """Irradiance of a ``sunsky`` sun (``sky_scale = 0``) on a surface facing it, ``(3,)``.

    A stratified quadrature through the emitter's own ``sample_direction`` (weights =
    eval / pdf): the expectation of what Mitsuba's next-event estimation delivers,
    float32 cone and all. (Mitsuba's ``eval`` accepts a cone about 0.4 % larger in
    solid angle than the one it samples; diffuse renders follow the sampled one.)
    """
    import drjit as dr

    n = _SUN_QUADRATURE
    g = (np.arange(n) + 0.5) / n
    u, v = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    if _is_scalar(mi):
        it = dr.zeros(mi.Interaction3f)
        acc = np.zeros(3)
        for a, b in zip(u, v):
            ds, w = sun_only.sample_direction(it, mi.Point2f(float(a), float(b)))
            acc += np.asarray(w, dtype=np.float64).reshape(3) * float(np.dot(np.asarray(ds.d).reshape(3), direction))
        return acc / u.size
    it = dr.zeros(mi.Interaction3f, u.size)
    ds, w = sun_only.sample_direction(it, mi.Point2f(u, v))
    weight = np.asarray(w, dtype=np.float64).T
    cos = np.asarray(ds.d, dtype=np.float64).T @ direction
    return (weight * cos[:, None]).mean(axis=0)


# ------------------------------------------------------------------ generators


def _exposure(sky: np.ndarray, sun_direction: np.ndarray | None, sun_irradiance: np.ndarray) -> dict[str, Any]:
    """Suggested exposure from the irradiance on an upward-facing surface."""
    up = np.array([[0.0, 1.0, 0.0]])
    e_up = np.asarray(_envmap.irradiance_reference(sky.astype(np.float64), up))[0]
    if sun_direction is not None:
        e_up = e_up + max(0.0, float(sun_direction[1])) * sun_irradiance
    y = float(e_up @ _LUM)
    scale = EXPOSURE_TARGET / y if y > 0 else 1.0
    return {
        "horizontal_irradiance": [float(x) for x in e_up],
        "exposure_scale": scale,
        "exposure_stops": math.log2(scale),
    }


def _sky_lighting(kind: str, rng: np.random.Generator, elevation_range: tuple[float, float],
                  turbidity_range: tuple[float, float], with_sun: bool,
                  elevation_deg: float | None, azimuth_deg: float | None, turbidity: float | None,
                  albedo: float | None, resolution: int, scale: float,
                  max_elevation: float = 90.0) -> Lighting:
    resolution = _check_resolution(resolution)
    scale = _check_finite_number(scale, "scale")
    if scale <= 0:
        raise ValueError(f"scale must be positive, got {scale}")
    # Draw every value even when it is given, so one given value does not shift the others.
    draws = rng.uniform(size=4)
    if elevation_deg is None:
        elevation_deg = elevation_range[0] + draws[0] * (elevation_range[1] - elevation_range[0])
    elevation_deg = _check_range(elevation_deg, 0.0, max_elevation, "elevation_deg", lo_open=True)
    if azimuth_deg is None:
        azimuth_deg = 360.0 * draws[1]
    azimuth_deg = _check_finite_number(azimuth_deg, "azimuth_deg") % 360.0
    if turbidity is None:
        turbidity = turbidity_range[0] + draws[2] * (turbidity_range[1] - turbidity_range[0])
    turbidity = _check_range(turbidity, *MITSUBA_TURBIDITY_RANGE, "turbidity")
    if albedo is None:
        albedo = GROUND_ALBEDO_RANGE[0] + draws[3] * (GROUND_ALBEDO_RANGE[1] - GROUND_ALBEDO_RANGE[0])
    albedo = _check_range(albedo, 0.0, 1.0, "albedo")

    mi = _mitsuba()
    s = direction_from_angles(elevation_deg, azimuth_deg)
    sky_em = mi.load_dict(_sunsky_dict(mi, s, turbidity, albedo, sky_scale=scale, sun_scale=0.0))
    dirs = _envmap.directions(resolution, 2 * resolution).reshape(-1, 3)
    sky = eval_emitter(mi, sky_em, dirs).reshape(resolution, 2 * resolution, 3)
    # Mitsuba's sky is >= 0, but keep float32 rounding from ever making it negative.
    sky = np.clip(sky, 0.0, None).astype(np.float32)
    if with_sun:
        sun_em = mi.load_dict(_sunsky_dict(mi, s, turbidity, albedo, sky_scale=0.0, sun_scale=scale))
        # Near the horizon (elevation ~2 deg, turbidity >= 6) Mitsuba's spectral -> RGB sun
        # comes out slightly negative in blue (-1.4 % of red): clip like the sky above, so
        # the record is valid; the renderer uses this same clipped irradiance.
        e_sun = np.clip(_sun_disk_irradiance(mi, sun_em, s), 0.0, None)
        sun_direction: np.ndarray | None = s
    else:
        e_sun, sun_direction = np.zeros(3), None
    params: dict[str, Any] = {
        "model": "mitsuba sunsky (Hosek-Wilkie)",
        "sun_elevation_deg": float(elevation_deg),
        "sun_azimuth_deg": float(azimuth_deg),
        "sun_visible": bool(with_sun),
        "turbidity": float(turbidity),
        "ground_albedo": float(albedo),
        "scale": float(scale),
        "resolution": resolution,
        "sun_emitter": "directional" if with_sun else "none",
    }
    params.update(_exposure(sky, sun_direction, e_sun))
    return Lighting(kind=kind, params=params, sky=sky, sun_direction=sun_direction,
                    sun_irradiance=e_sun, sun_radius_deg=SUN_RADIUS_DEG)


def sunsky(seed: int | np.random.Generator, elevation_deg: float | None = None,
           azimuth_deg: float | None = None, turbidity: float | None = None,
           albedo: float | None = None, resolution: int = 256, scale: float = 1.0) -> Lighting:
    """Clear sky with sun from Mitsuba's ``sunsky``.

    Unless given: elevation uniform in :data:`SUNSKY_ELEVATION_RANGE` degrees, azimuth
    uniform in [0, 360), turbidity uniform in :data:`TURBIDITY_RANGE`, ground albedo
    uniform in :data:`GROUND_ALBEDO_RANGE`.

    Args:
        seed: integer seed or a numpy ``Generator`` (same seed, same bytes).
        elevation_deg: sun elevation in (0, 90].
        azimuth_deg: sun azimuth (module doc), any finite value (taken mod 360).
        turbidity: in [1, 10] (Mitsuba's range).
        albedo: ground albedo of the sky model, in [0, 1].
        resolution: sky map height ``H`` (width ``2 H``).
        scale: radiance multiplier on sky and sun (1 = Mitsuba's units).
    """
    return _sky_lighting("sunsky", _rng(seed), SUNSKY_ELEVATION_RANGE, TURBIDITY_RANGE, True,
                         elevation_deg, azimuth_deg, turbidity, albedo, resolution, scale)


def overcast(seed: int | np.random.Generator, elevation_deg: float | None = None,
             azimuth_deg: float | None = None, turbidity: float | None = None,
             albedo: float | None = None, resolution: int = 256, scale: float = 1.0) -> Lighting:
    """Sun-free hazy sky: ``sunsky`` with ``sun_scale = 0`` and turbidity in
    :data:`OVERCAST_TURBIDITY_RANGE` (not a CIE overcast sky; see the module doc).

    The hidden sun's elevation/azimuth (sampled as for :func:`sunsky`) are recorded in
    ``params``; :attr:`Lighting.sun_direction` is ``None``. Arguments as for :func:`sunsky`.
    """
    return _sky_lighting("overcast", _rng(seed), OVERCAST_ELEVATION_RANGE, OVERCAST_TURBIDITY_RANGE, False,
                         elevation_deg, azimuth_deg, turbidity, albedo, resolution, scale)


def evening(seed: int | np.random.Generator, elevation_deg: float | None = None,
            azimuth_deg: float | None = None, turbidity: float | None = None,
            albedo: float | None = None, resolution: int = 256, scale: float = 1.0) -> Lighting:
    """Low sun: ``sunsky`` with elevation in :data:`EVENING_ELEVATION_RANGE` unless given
    (a given elevation must be in (0, :data:`EVENING_MAX_ELEVATION`]). Otherwise as :func:`sunsky`."""
    return _sky_lighting("evening", _rng(seed), EVENING_ELEVATION_RANGE, TURBIDITY_RANGE, True,
                         elevation_deg, azimuth_deg, turbidity, albedo, resolution, scale,
                         max_elevation=EVENING_MAX_ELEVATION)


def hdri(path: str | os.PathLike, azimuth_deg: float = 0.0, split_sun: bool = True,
         scale: float = 1.0, resolution: int | None = None) -> Lighting:
    """A real environment map, turned about +Y so every feature's azimuth grows by ``azimuth_deg``.

    With ``split_sun`` (default) the sun is split off the rotated map
    (:func:`physrelight.envmap.split_sun`: energy conserving, a sun only if it carries
    >= 1 % of the map's luminance) and becomes the record's directional sun, with the
    physical disk radius; the render uses exactly this sky + sun. Without it the whole
    rotated map is the sky and there is no sun.

    Args:
        path: EXR file (lat-long, Mitsuba layout, row 0 = zenith).
        azimuth_deg: rotation about +Y in degrees. A multiple of ``360 / W`` of the
            result's sky is an exact column shift, and then the read, the sun split and
            the downsampling are cached per file (what :func:`sample_lighting` draws).
        split_sun: split the sun into a directional light.
        scale: radiance multiplier.
        resolution: if given and below the map's height, the sky (after the sun split)
            is downsampled to this height with :func:`physrelight.envmap.downsample`
            (integral kept); the record and the render both use the downsampled sky.
    """
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"HDRI {str(p)!r} does not exist")
    azimuth_deg = _check_finite_number(azimuth_deg, "azimuth_deg") % 360.0
    scale = _check_finite_number(scale, "scale")
    if scale <= 0:
        raise ValueError(f"scale must be positive, got {scale}")
    if resolution is not None:
        resolution = _check_resolution(resolution)
    native, sky0, sun0, e_sun0, fraction = _hdri_parts(str(p.resolve()), bool(split_sun), resolution)
    w = sky0.shape[1]
    shift = azimuth_deg / 360.0 * w
    if abs(shift - round(shift)) < 1e-6:
        # Exact: rolling columns commutes with the split and the downsampling.
        sky = np.roll(sky0.astype(np.float64), int(round(shift)) % w, axis=1)
        sun_direction = None if sun0 is None else _rotate_azimuth_direction(sun0, azimuth_deg)
        e_sun = e_sun0
    else:
        env = _rotate_azimuth(_envmap.read(p).astype(np.float64), azimuth_deg)
        sun_direction, e_sun, sky, fraction = None, np.zeros(3), env, 0.0
        if split_sun:
            part = _envmap.split_sun(env)
            sky = part.sky
            if part.has_sun:
                sun_direction, e_sun, fraction = part.direction, np.asarray(part.irradiance, np.float64), part.fraction
        sky = np.clip(np.asarray(sky, dtype=np.float64), 0.0, None)
        if resolution is not None and resolution < sky.shape[0]:
            sky = np.clip(_envmap.downsample(sky, resolution), 0.0, None)
    sky = sky * scale
    e_sun = np.asarray(e_sun, dtype=np.float64) * scale
    params: dict[str, Any] = {
        "hdri": p.stem,
        "hdri_file": p.name,
        "azimuth_deg": float(azimuth_deg),
        "scale": float(scale),
        "resolution": int(sky.shape[0]),
        "native_resolution": int(native),
        "indoor": is_indoor_hdri(p),
        "split_sun": bool(split_sun),
    }
    if sun_direction is not None:
        elevation, azimuth = angles_from_direction(sun_direction)
        params.update(sun_elevation_deg=elevation, sun_azimuth_deg=azimuth, sun_fraction=float(fraction))
    params["sun_emitter"] = "directional" if sun_direction is not None else "none"
    sky = sky.astype(np.float32)
    params.update(_exposure(sky, sun_direction, e_sun))
    return Lighting(kind="hdri", params=params, sky=sky, sun_direction=sun_direction,
                    sun_irradiance=e_sun, sun_radius_deg=SUN_RADIUS_DEG)


@functools.lru_cache(maxsize=16)
def _hdri_parts(path: str, split_sun: bool, resolution: int | None
                ) -> tuple[int, np.ndarray, np.ndarray | None, np.ndarray, float]:
    """Read, split and downsample a map once: (native height, sky, sun direction, sun irradiance, fraction)."""
    env = _envmap.read(path).astype(np.float64)
    if env.shape[1] != 2 * env.shape[0]:
        raise ValueError(f"HDRI {path!r} must be a 2:1 lat-long map, got {env.shape[1]}x{env.shape[0]}")
    sky, sun, e_sun, fraction = env, None, np.zeros(3), 0.0
    if split_sun:
        part = _envmap.split_sun(env)
        sky = part.sky.astype(np.float64)
        if part.has_sun:
            sun, e_sun, fraction = part.direction, np.asarray(part.irradiance, dtype=np.float64), part.fraction
    sky = np.clip(sky, 0.0, None)
    if resolution is not None and resolution < sky.shape[0]:
        sky = np.clip(_envmap.downsample(sky, resolution), 0.0, None)
    sky = sky.astype(np.float32)
    sky.setflags(write=False)
    return env.shape[0], sky, sun, e_sun, fraction


def _rotate_azimuth_direction(direction: np.ndarray, azimuth_deg: float) -> np.ndarray:
    """The direction whose azimuth is ``azimuth_deg`` larger (same elevation)."""
    elevation, azimuth = angles_from_direction(direction)
    return direction_from_angles(elevation, azimuth + azimuth_deg)


def _rotate_azimuth(env: np.ndarray, azimuth_deg: float) -> np.ndarray:
    """Turn a map about +Y so azimuths grow by ``azimuth_deg``: exact column roll on the grid."""
    w = env.shape[1]
    shift = azimuth_deg / 360.0 * w
    if abs(shift - round(shift)) < 1e-9:
        return np.roll(env, int(round(shift)) % w, axis=1)
    # about_y(angle) moves azimuth by -angle (right-hand rule about +Y; azimuth is clockwise from above).
    from physrelight.rotations import about_y

    return np.asarray(_envmap.rotate(env, about_y(-azimuth_deg)))


def list_hdris(hdri_dir: str | os.PathLike | None = None, include_indoor: bool = False) -> list[Path]:
    """Sorted ``*.exr`` maps in ``hdri_dir`` (default: the shipped :data:`HDRI_DIR`),
    leaving out the indoor ones (:func:`is_indoor_hdri`: :data:`INDOOR_HDRIS`, or not ``outdoor`` in the folder's
    :data:`KINDS_FILE`, e.g. ``synth --hdri-dir physrelight/data/hdri_more`` draws its six outdoor maps) unless
    ``include_indoor``."""
    d = Path(hdri_dir) if hdri_dir is not None else HDRI_DIR
    if not d.is_dir():
        raise ValueError(f"HDRI folder {str(d)!r} does not exist")
    maps = sorted(p for p in d.iterdir() if p.suffix.lower() == ".exr" and p.is_file())
    if not include_indoor:
        maps = [p for p in maps if not is_indoor_hdri(p)]
    if not maps:
        raise ValueError(f"HDRI folder {str(d)!r} holds no {'' if include_indoor else 'outdoor '}.exr maps")
    return maps


def sample_lighting(kind: str, seed: int | np.random.Generator, hdri_dir: str | os.PathLike | None = None,
                    resolution: int = 256, include_indoor: bool = False) -> Lighting:
    """One seeded lighting of ``kind``.

    For ``hdri``, a map is drawn uniformly from :func:`list_hdris` (``hdri_dir`` or the
    shipped maps; indoor ones only with ``include_indoor``) and turned by an azimuth
    uniform over the ``2 resolution`` column positions of its sky (an exact rotation),
    and its sky downsampled to ``resolution`` (integral kept).
    """
    _check_kind(kind)
    rng = _rng(seed)
    if kind == "sunsky":
        return sunsky(rng, resolution=resolution)
    if kind == "overcast":
        return overcast(rng, resolution=resolution)
    if kind == "evening":
        return evening(rng, resolution=resolution)
    maps = list_hdris(hdri_dir, include_indoor)
    pick = int(rng.integers(len(maps)))
    # A whole number of sky columns: an exact, cached rotation (1.4 deg steps at H = 128).
    columns = 2 * resolution
    azimuth = float(rng.integers(columns)) * 360.0 / columns
    return hdri(maps[pick], azimuth_deg=azimuth, resolution=resolution)
