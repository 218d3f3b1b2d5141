"""A prior over the sun's position and the sky's kind, from the real panoramas of the training side.

The posterior of :func:`physrelight.sun_from_sky.estimate_sun_from_sky` assumes a sun uniform over the sky's solid
angle. Real outdoor photos are not uniform: the sun is seldom at the zenith, and many skies have no sun at all.
:class:`SunPrior` holds, on the posterior's grid (:data:`~physrelight.sun_from_sky.ELEVATIONS_DEG` x
:data:`~physrelight.sun_from_sky.AZIMUTH_STEP_DEG`):

* the sun's **elevation**: a Gaussian kernel density (:data:`KERNEL_DEG`) of the sun elevations found in the
  panoramas (:func:`physrelight.envmap.split_sun`), mixed with the uniform-over-solid-angle prior
  (:data:`UNIFORM_SHARE`): a handful of maps cannot rule an elevation out;
* the sun's **azimuth**: uniform. A panorama's north says nothing of where a photographer points the camera;
* the sky's **kind** (:data:`PRIOR_KINDS`): the share of each, add-one smoothed.

The shipped prior (:data:`SUN_PRIOR`, a few hundred bytes of safetensors) is written by ``scripts/fit_sun_prior.py``
from the training side only: the outdoor maps of ``data/hdri`` (city, courtyard, forest) and of ``data/hdri_more``
(pm_city, pm_dawn, pm_forest, pm_night, pm_sky, pm_venice). Never the held-out ``hdri_heldout`` (sunrise): it
scores ``bench --real``.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physrelight.sun_from_sky import AZIMUTH_STEP_DEG, ELEVATIONS_DEG, _cell_solid_angles

__all__ = ["KERNEL_DEG", "PRIOR_KINDS", "SUN_KINDS", "SUN_PRIOR", "SunPrior", "UNIFORM_SHARE", "fit_sun_prior",
           "load_sun_prior", "uniform_sun_prior"]

SUN_PRIOR = Path(__file__).resolve().parent / "data" / "sun_prior.safetensors"
"""The shipped prior (``scripts/fit_sun_prior.py``; provenance in ``physrelight/data/README.md``)."""
PRIOR_KINDS = ("clear", "hazy", "overcast", "night")
"""The sky kinds the prior counts (:data:`physrelight.sun_from_sky.SKY_KINDS` less the four that describe a reading
of a photo, not a sky: ``blown out``, ``unseen``, ``unfit`` and ``none``). A twilight sky (the sun below the horizon)
counts as ``night``: no sun."""
SUN_KINDS = ("clear", "hazy")
"""The kinds with a sun."""
KERNEL_DEG = 10.0
"""Standard deviation of the Gaussian kernel about each panorama's sun elevation."""
UNIFORM_SHARE = 0.5
"""Share of the elevation prior that stays uniform over solid angle (the samples are few)."""


@dataclass(frozen=True)
class SunPrior:
    """A prior over the sun's cell and the sky's kind (see the module doc).

    Attributes:
        elevations_deg: ``(E,)`` the grid's sun elevations.
        azimuths_deg: ``(A,)`` the grid's world azimuths.
        probability: ``(E, A)`` prior probability of each cell given a sun (sums to 1; constant along azimuth).
        kind_probability: ``(len(PRIOR_KINDS),)`` prior probability of each kind (sums to 1).
        sun_elevations_deg: ``(n,)`` the sun elevations it was fitted to (empty for :func:`uniform_sun_prior`).
        maps: the panoramas it was fitted from.
    """

    elevations_deg: np.ndarray
    azimuths_deg: np.ndarray
    probability: np.ndarray
    kind_probability: np.ndarray
    sun_elevations_deg: np.ndarray
    maps: tuple[str, ...]

    @property
    def log_probability(self) -> np.ndarray:
        """``(E, A)`` the log of :attr:`probability`."""
        return np.log(self.probability)

    @property
    def sun_probability(self) -> float:
        """Prior probability that a sky has a sun (the :data:`SUN_KINDS`' share)."""
        return float(sum(self.kind_probability[PRIOR_KINDS.index(k)] for k in SUN_KINDS))

    def kind(self, name: str) -> float:
        """Prior probability of the kind ``name`` (one of :data:`PRIOR_KINDS`)."""
        if name not in PRIOR_KINDS:
            raise ValueError(f"kind must be one of {', '.join(PRIOR_KINDS)}, got {name!r}")
        return float(self.kind_probability[PRIOR_KINDS.index(name)])

    def save(self, path: str | Path) -> None:
        """Write the prior as safetensors (atomically): its elevation band, kinds and samples, and the maps and
        constants as metadata. The same prior gives the same bytes."""
        from safetensors.numpy import save_file

        from physrelight.io import atomic_path

        # the probability is constant along azimuth: its elevation band alone is stored
        tensors = {"elevations_deg": self.elevations_deg.astype(np.float64),
                   "elevation_probability": self.probability.sum(1).astype(np.float64),
                   "kind_probability": self.kind_probability.astype(np.float64),
                   "sun_elevations_deg": self.sun_elevations_deg.astype(np.float64)}
        # one metadata entry, its keys sorted: safetensors writes a metadata dict in no fixed order
        meta = {"physrelight_sun_prior": json.dumps({"version": 1, "kinds": list(PRIOR_KINDS), "maps": list(self.maps),
                                                     "kernel_deg": KERNEL_DEG, "uniform_share": UNIFORM_SHARE,
                                                     "azimuth_step_deg": AZIMUTH_STEP_DEG}, sort_keys=True)}
        with atomic_path(Path(path), ".safetensors") as tmp:
            save_file(tensors, str(tmp), metadata=meta)


def _grid() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    el = np.array(ELEVATIONS_DEG)
    az = np.arange(0.0, 360.0, AZIMUTH_STEP_DEG)
    return el, az, _cell_solid_angles(el, len(az))


def uniform_sun_prior() -> SunPrior:
    """The prior :func:`physrelight.sun_from_sky.estimate_sun_from_sky` assumes: a sun uniform over solid angle,
    every kind alike."""
    el, az, cell = _grid()
    return SunPrior(elevations_deg=el, azimuths_deg=az, probability=cell / cell.sum(),
                    kind_probability=np.full(len(PRIOR_KINDS), 1.0 / len(PRIOR_KINDS)),
                    sun_elevations_deg=np.zeros(0), maps=())


def fit_sun_prior(sun_elevations_deg: np.ndarray | list[float], kinds: list[str] | tuple[str, ...],
                  maps: tuple[str, ...] = ()) -> SunPrior:
    """Fit the prior to samples.

    Args:
        sun_elevations_deg: ``(n,)`` the elevations (degrees, in (0, 90]) of the suns found in the panoramas.
        kinds: one kind (:data:`PRIOR_KINDS`) per panorama (a panorama may show a sun by its shadows whose disc is
            hidden: it counts as a kind without an elevation).
        maps: the panoramas' names, recorded.

    Returns:
        :class:`SunPrior`: the elevation's kernel density mixed with the uniform prior (:data:`UNIFORM_SHARE`),
        uniform in azimuth; the kinds' shares, add-one smoothed.

    Raises:
        ValueError: an elevation outside (0, 90], an unknown kind, no kinds.
    """
    e = np.asarray(sun_elevations_deg, dtype=np.float64).ravel()
    if not np.all(np.isfinite(e)) or np.any(e <= 0) or np.any(e > 90):
        raise ValueError(f"sun elevations must lie in (0, 90] degrees, got {e.tolist()}")
    bad = [k for k in kinds if k not in PRIOR_KINDS]
    if bad or not kinds:
        raise ValueError(f"kinds must be a non-empty list of {', '.join(PRIOR_KINDS)}; got {list(kinds)!r}")
    el, az, cell = _grid()
    uniform = cell / cell.sum()
    if len(e):
        # the kernel's density over elevation, per unit of elevation; a cell's share is it times the cell's
        # elevation width (the bands between midpoints), spread evenly over the azimuths
        edges = np.concatenate([[el[0]], (el[1:] + el[:-1]) / 2, [90.0]])
        from scipy.stats import norm

        band = np.zeros(len(el))
        for x in e:
            band += norm.cdf(edges[1:], x, KERNEL_DEG) - norm.cdf(edges[:-1], x, KERNEL_DEG)
        band /= band.sum()
        kde = np.repeat((band / len(az))[:, None], len(az), 1)
        prob = UNIFORM_SHARE * uniform + (1 - UNIFORM_SHARE) * kde
    else:
        prob = uniform
    counts = np.array([sum(k == name for k in kinds) for name in PRIOR_KINDS], dtype=np.float64) + 1.0
    return SunPrior(elevations_deg=el, azimuths_deg=az, probability=prob / prob.sum(),
                    kind_probability=counts / counts.sum(), sun_elevations_deg=e, maps=tuple(maps))


@functools.lru_cache(maxsize=4)
def _load(path: str) -> SunPrior:
    from safetensors import safe_open
    from safetensors.numpy import load_file

    t = load_file(path)
    with safe_open(path, "np") as f:
        raw = (f.metadata() or {}).get("physrelight_sun_prior")
    if raw is None:
        raise ValueError(f"{path} is not a sun prior (no physrelight_sun_prior metadata)")
    meta = json.loads(raw)
    if meta.get("kinds") != list(PRIOR_KINDS):
        raise ValueError(f"{path}: its kinds {meta.get('kinds')} are not {list(PRIOR_KINDS)}")
    el, az, _ = _grid()
    if not (np.allclose(t["elevations_deg"], el) and meta.get("azimuth_step_deg") == AZIMUTH_STEP_DEG):
        raise ValueError(f"{path}: its grid is not the posterior's (refit it: scripts/fit_sun_prior.py)")
    band = t["elevation_probability"]
    prob = np.repeat((band / band.sum() / len(az))[:, None], len(az), 1)
    return SunPrior(elevations_deg=el, azimuths_deg=az, probability=prob,
                    kind_probability=t["kind_probability"], sun_elevations_deg=t["sun_elevations_deg"],
                    maps=tuple(meta.get("maps", [])))


def load_sun_prior(path: str | Path | None = None) -> SunPrior:
    """The prior saved at ``path`` (None: the shipped :data:`SUN_PRIOR`).

    Raises:
        ValueError: the file is missing, not a sun prior, or on another grid.
    """
    p = Path(SUN_PRIOR if path is None else path)
    if not p.is_file():
        raise ValueError(f"no sun prior at {p}")
    return _load(str(p.resolve()))
