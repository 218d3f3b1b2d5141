"""The statistical outdoor lighting subspace the inverse network's lighting is projected onto.

The paper solves lighting by least squares and projects it onto a whitened PCA subspace
learnt from outdoor environment maps (18 of 27 dimensions for order 2). Here the samples
are (all seeded):

* Hosek-Wilkie ``sunsky`` skies (Mitsuba, via :mod:`synth.lighting`) with the sun
  elevation uniform in [2, 75] degrees, azimuth uniform, turbidity uniform in [2, 10]
  (turbidity >= 8 with the sun switched off half of the time: the hazy, sun-free kind);
* the shipped outdoor HDRIs (``physrelight/data/hdri``, the indoor studio map excluded),
  each turned about +Y by a random azimuth;

each rotated into a random tourist-like camera frame (yaw uniform, pitch ~ N(0, 12 deg)
clipped to +-35 deg, roll ~ N(0, 1 deg): level horizons, as in the synthetic cameras), and
scaled to photo units: the lighting's own ``exposure_scale`` (a white horizontal surface
at 0.18, :mod:`synth.lighting`) times a random metering gain ``2 ** U(1.0, 3.5)``. A camera
meters the frame's log-average (albedo x shading, sky included) to 0.18; with typical
outdoor albedos around 0.2 the shading, i.e. a white surface, lands near 0.9, about
``2 ** 2.3`` times the ``exposure_scale`` units, and the metering spread (+-0.7 EV,
varied scenes) widens that. The lighting solved from a linearised photo lives in those
units, up to the photo's unknown exposure, which the gain spreads the prior over.

Fitting needs Mitsuba (``synth``); the fitted prior ships as
``learned/weights/lighting_prior.npz`` and loading it needs numpy only.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from physrelight.lighting_prior import LightingPrior, fit_lighting_prior

__all__ = ["HDRI_SETS", "PRIOR_PATH", "WEIGHTS_DIR", "camera_rotation", "fit_outdoor_prior", "load_prior",
           "outdoor_lightings", "prior_hdris"]

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
PRIOR_PATH = WEIGHTS_DIR / "lighting_prior.npz"


def camera_rotation(rng: np.random.Generator) -> np.ndarray:
    """A random tourist-like world-to-camera rotation ``(3, 3)``: yaw, small pitch, tiny roll.

    Camera frame: x right, y up, z towards the viewer; world Y up.
    """
    yaw = rng.uniform(0.0, 2.0 * math.pi)
    pitch = math.radians(float(np.clip(rng.normal(0.0, 12.0), -35.0, 35.0)))
    roll = math.radians(float(rng.normal(0.0, 1.0)))

    def rot(axis: int, a: float) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        i, j = [(1, 2), (2, 0), (0, 1)][axis]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        return r

    # camera_to_world = yaw about Y, then pitch about x, then roll about z.
    c2w = rot(1, yaw) @ rot(0, pitch) @ rot(2, roll)
    return c2w.T


HDRI_SETS = ("shipped", "more")
"""Which outdoor maps the prior's HDRI samples come from: ``"shipped"``, the three outdoor maps of
``physrelight/data/hdri`` (city, courtyard, forest); ``"more"``, those and the six outdoor maps of
``physrelight/data/hdri_more`` (issue 43; the held-out maps never)."""


def prior_hdris(which: str = "shipped") -> list[Path]:
    """The outdoor maps of the HDRI set ``which`` (:data:`HDRI_SETS`), sorted by folder then name."""
    from physrelight import data

    if which not in HDRI_SETS:
        raise ValueError(f"HDRI set must be one of {', '.join(HDRI_SETS)}, got {which!r}")
    paths = [data.hdri(n) for n in data.hdri_names(kind="outdoor")]
    if which == "more":
        paths += [data.hdri(n, collection="more") for n in data.hdri_names(collection="more", kind="outdoor")]
    return paths


def outdoor_lightings(n_sky: int = 1000, n_hdri_per_map: int = 200, seed: int = 0,
                      resolution: int = 32, hdris: str = "shipped") -> np.ndarray:
    """Outdoor lightings as order-2 radiance SH in random camera frames, photo units.

    Args:
        n_sky: number of sunsky/overcast samples.
        n_hdri_per_map: samples per outdoor HDRI of the set ``hdris``.
        seed: same seed, same array.
        resolution: sky-map height used for the SH projection (the SH is exact for it).
        hdris: the HDRI set (:data:`HDRI_SETS`, :func:`prior_hdris`).

    Returns:
        ``(N, 9, 3)`` float64, ``N = n_sky + n_hdri_per_map * maps``.
    """
    from physrelight import sh
    from synth import lighting as sl

    if n_sky < 0 or n_hdri_per_map < 0 or n_sky + n_hdri_per_map == 0:
        raise ValueError(f"need a positive number of samples, got n_sky={n_sky}, n_hdri_per_map={n_hdri_per_map}")
    maps = prior_hdris(hdris)
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []

    def add(light: "sl.Lighting") -> None:
        r = camera_rotation(rng)
        gain = light.params["exposure_scale"] * 2.0 ** rng.uniform(1.0, 3.5)
        out.append(np.asarray(sh.rotation(r, 2)) @ light.sh(2) * gain)

    for i in range(n_sky):
        elevation = float(rng.uniform(2.0, 75.0))
        turbidity = float(rng.uniform(2.0, 10.0))
        sub = np.random.default_rng([seed, i])
        if turbidity >= 8.0 and rng.random() < 0.5:
            light = sl.overcast(sub, elevation_deg=max(elevation, 15.0), turbidity=turbidity, resolution=resolution)
        else:
            light = sl.sunsky(sub, elevation_deg=elevation, turbidity=turbidity, resolution=resolution)
        add(light)
    for path in maps:
        for _ in range(n_hdri_per_map):
            azimuth = float(rng.integers(2 * resolution)) * 360.0 / (2 * resolution)
            add(sl.hdri(path, azimuth_deg=azimuth, resolution=resolution))
    return np.stack(out)


def fit_outdoor_prior(k: int = 18, n_sky: int = 1000, n_hdri_per_map: int = 200, seed: int = 0,
                      path: str | Path | None = PRIOR_PATH, hdris: str = "shipped") -> LightingPrior:
    """Fit the whitened PCA prior (``k`` of 27 dimensions) on :func:`outdoor_lightings` of the HDRI set
    ``hdris`` and save it to ``path`` (None: do not save)."""
    prior = fit_lighting_prior(outdoor_lightings(n_sky, n_hdri_per_map, seed, hdris=hdris), k)
    if path is not None:
        prior.save(path)
    return prior


def load_prior(path: str | Path | None = None) -> LightingPrior:
    """The shipped prior (``path=None``) or one saved with :meth:`LightingPrior.save`."""
    p = Path(path) if path is not None else PRIOR_PATH
    if not p.is_file():
        raise FileNotFoundError(f"no lighting prior at {str(p)!r}; fit one with learned.lighting.fit_outdoor_prior()")
    return LightingPrior.load(p)
