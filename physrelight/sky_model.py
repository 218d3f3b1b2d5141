"""Analytic sky radiance, and the sky an order-2 SH lighting implies.

A lighting given only as SH coefficients ``(9, 3)`` does not say what its sky looks like, yet
``relight --sh`` has to paint one. :func:`fit_sky` explains the coefficients by a small physical
model, the fewest parts an outdoor sky needs:

* a delta sun (:func:`physrelight.sh.project_sun`) towards ``s``, elevation >= 0;
* the sun's glow, ``2 max(0, d . s)^2`` above the horizon (forward scattering by haze round the sun;
  the exponent :data:`FIT_GLOW_EXPONENT` was chosen among 2-32 on the training panoramas, study 31);
* a clear sky, deep blue (0.30, 0.50, 1.0) at the zenith turning pale (0.80, 0.88, 1.0) and twice as
  bright towards the horizon (:func:`clear_sky`);
* the CIE overcast sky, ``(1 + 2 cos theta) / 3`` (:func:`overcast_sky`);
* a uniform ground below the horizon (lit by the sky and the sun, seen by upward-facing SH only).

Each part has a non-negative weight per channel (its colour), solved by exact non-negative least
squares on the nine coefficients; the sun's direction is searched on a 2-degree grid of the upper
hemisphere and refined to 0.25 degree. The parts' SH come from their lat-long maps
(:func:`physrelight.sh.project_envmap`, 64 x 128). The sky a camera sees (:func:`sky_view`) is the
fitted parts evaluated along each ray, so it is smooth at any resolution by construction: no
blotch, no band. What order-2 SH cannot say (clouds, a treeline), the fit cannot either.

The clear sky of a ``--sun`` target is not fitted but tabulated: :func:`sunsky_radiance`, Mitsuba 3's
Hosek-Wilkie sky (:data:`SUNSKY_TABLE`, written by :mod:`synth.sunsky_table`).

All directions are world frame, Y up (DESIGN.md); radiance in the coefficients' units.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import torch

from physrelight import rotations, sh
from physrelight.envmap import direction_from_angles
from physrelight._checks import Array

__all__ = ["ANGSTROM_ALPHA", "ANGSTROM_BETA", "CLEAR_HORIZON", "CLEAR_ZENITH", "COMPONENTS", "FIT_GLOW_EXPONENT",
           "GLOW_EXPONENT", "HORIZON_Y", "SUNSKY_TABLE", "SUN_RADIUS_DEG", "SUN_TEMPERATURE_K", "SkyFit", "air_mass",
           "cie_1931_cmf", "clear_sky", "fit_sky", "horizon_clamped", "overcast_sky", "rayleigh_optical_depth",
           "sky_view", "sun_colour", "sun_disc", "sun_glow", "sun_transmittance", "sunsky_radiance"]

CLEAR_ZENITH = (0.30, 0.50, 1.0)
CLEAR_HORIZON = (0.80, 0.88, 1.0)
GLOW_EXPONENT = 32
"""The glow of the clear sky of a sun target (``physrelight.target_lighting.sun_sky_map``): the aureole."""
FIT_GLOW_EXPONENT = 2.0
"""The glow's exponent in :func:`fit_sky`: the widest of 32, 16, 8, 4, 2 scored best on the training
panoramas' crops (study 31, round 2; the differences were within 0.2 dB)."""
COMPONENTS = ("sun", "glow", "clear", "overcast", "ground")
"""The parts of :func:`fit_sky`, in the order of :attr:`SkyFit.weights`' rows."""
SUN_RADIUS_DEG = 0.27
"""The sun's angular radius, for drawing its disc in a rendered sky."""
HORIZON_Y = 0.02
"""A model sky is looked up no lower than this (the sine of about 1 degree of elevation): it has no
ground, so a sky pixel below the horizon (a mask or a pitch a little off) shows the sky just above it."""
_MAP_HEIGHT = 64
_COARSE_STEP_DEG = 2.0
_FINE_STEP_DEG = 0.25


def clear_sky(d: np.ndarray) -> np.ndarray:
    """``(..., 3)`` radiance of the clear-sky gradient along unit directions ``d (..., 3)``; 0 below the horizon."""
    cos_z = d[..., 1]
    t = (1.0 - np.clip(cos_z, 0, 1))[..., None] ** 2  # 0 at the zenith, 1 at the horizon
    colour_ = (1 - t) * np.array(CLEAR_ZENITH) + t * np.array(CLEAR_HORIZON)
    return np.where(cos_z[..., None] > 0, colour_ * (1.0 + t), 0.0)


def sun_glow(d: np.ndarray, s: np.ndarray, exponent: float = GLOW_EXPONENT) -> np.ndarray:
    """``(...,)`` the white glow ``2 max(0, d . s)^exponent`` round the sun ``s (3,)``; 0 below the horizon."""
    return np.where(d[..., 1] > 0, 2.0 * np.maximum(0.0, d @ s) ** exponent, 0.0)


def overcast_sky(d: np.ndarray) -> np.ndarray:
    """``(...,)`` the CIE overcast sky ``(1 + 2 cos theta) / 3`` (zenith 1); 0 below the horizon."""
    cos_z = d[..., 1]
    return np.where(cos_z > 0, (1.0 + 2.0 * np.clip(cos_z, 0, 1)) / 3.0, 0.0)


# ----------------------------------------------------------------------------- a clear day's sky

SUNSKY_TABLE = Path(__file__).resolve().parent / "data" / "sunsky_table.safetensors"
"""Mitsuba 3's Hosek-Wilkie clear sky (turbidity 3, ground albedo 0.2) over its sun's irradiance, white-balanced
to its zenith sun, tabulated by :mod:`synth.sunsky_table` (``physrelight`` may not import Mitsuba)."""


@functools.lru_cache(maxsize=1)
def _sunsky_table() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    from safetensors.numpy import load_file

    t = load_file(str(SUNSKY_TABLE))
    out = (t["radiance"].astype(np.float64), t["elevations_deg"], t["view_elevations_deg"], t["azimuths_deg"])
    for a in out:  # shared by every call (cached): read-only
        a.setflags(write=False)
    return out


def _bilinear_cells(rows: np.ndarray, cols: np.ndarray, r: np.ndarray, c: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where ``(r, c)`` falls on the uniform node coordinates ``rows (R,)``, ``cols (C,)``: each point's cell as the
    flat index ``r0 * C + c0`` of its lower corner, and its fractions ``wr, wc (..., 1)`` along rows and columns
    (the lookups of :func:`_blend_bilinear` in two tables share them)."""
    fr = np.clip((r - rows[0]) / (rows[1] - rows[0]), 0, len(rows) - 1)
    fc = np.clip((c - cols[0]) / (cols[1] - cols[0]), 0, len(cols) - 1)
    r0 = np.minimum(fr.astype(np.int64), len(rows) - 2)
    c0 = np.minimum(fc.astype(np.int64), len(cols) - 2)
    return r0 * len(cols) + c0, (fr - r0)[..., None], (fc - c0)[..., None]


@numba.njit(nogil=True, cache=True)
def _blend_bilinear_loop(a: np.ndarray, b: np.ndarray, ncols: int, w: float, idx: np.ndarray, wr: np.ndarray,
                         wc: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover
    """``out (N, 3) = (1 - w) * bilinear(a) + w * bilinear(b)`` at the flat cells ``idx (N,)`` with fractions
    ``wr, wc (N,)`` of the flattened ``(R * ncols, 3)`` grids ``a`` and ``b``, each bilinear lookup
    ``(1 - wr) ((1 - wc) g00 + wc g01) + wr ((1 - wc) g10 + wc g11)`` in that order."""
    for k in range(idx.shape[0]):
        i, r, c = idx[k], wr[k], wc[k]
        j = i + ncols
        for ch in range(out.shape[1]):
            va = (1 - r) * ((1 - c) * a[i, ch] + c * a[i + 1, ch]) + r * ((1 - c) * a[j, ch] + c * a[j + 1, ch])
            vb = (1 - r) * ((1 - c) * b[i, ch] + c * b[i + 1, ch]) + r * ((1 - c) * b[j, ch] + c * b[j + 1, ch])
            out[k, ch] = (1 - w) * va + w * vb


def _blend_bilinear(a: np.ndarray, b: np.ndarray, w: float, cells: tuple[np.ndarray, np.ndarray, np.ndarray]
                    ) -> np.ndarray:
    """``(1 - w) * A + w * B`` for grids ``a, b (R, C, 3)`` float64, ``A`` and ``B`` their bilinear lookups in the
    ``cells`` of :func:`_bilinear_cells` (``(..., 3)``): one compiled loop, the numbers numpy's expression of the same
    formula gives to the bit, without its full-size temporaries (a 12-megapixel sky's lookups: 1.6 s -> 0.1 s)."""
    idx, wr, wc = cells
    shape = idx.shape
    out = np.empty((idx.size, a.shape[-1]), dtype=np.float64)
    flat_a = np.ascontiguousarray(a.reshape(-1, a.shape[-1]))
    flat_b = np.ascontiguousarray(b.reshape(-1, b.shape[-1]))
    _blend_bilinear_loop(flat_a, flat_b, a.shape[1], float(w), np.ascontiguousarray(idx.reshape(-1)),
                         np.ascontiguousarray(wr.reshape(-1)), np.ascontiguousarray(wc.reshape(-1)), out)
    return out.reshape(*shape, a.shape[-1])


def sunsky_radiance(d: np.ndarray, s: Array) -> np.ndarray:
    """``(..., 3)`` a clear day's sky radiance (no sun) along unit directions ``d (..., 3)``, for a sun
    towards unit ``s (3,)``, in units where the sun's irradiance on a surface facing it has luminance 1.

    Mitsuba 3's Hosek-Wilkie ``sunsky`` (turbidity 3, ground albedo 0.2; linear sRGB white-balanced to the
    zenith sun, as :func:`sun_colour` is), looked up in :data:`SUNSKY_TABLE`: bilinear in the view's elevation
    and its azimuth from the sun (3-degree nodes), linear in the sun's elevation between the table's (2-90
    degrees; a sun lower than 2 degrees gets the sky of 2 degrees, where Mitsuba's solar data stop). So the sky
    keeps the model's shape (a dark zenith, a horizon 2-8 times brighter, the aureole, a warm horizon under a
    low sun) and its level against the sun (horizontal irradiance 0.29 of the sun's at 5 degrees up,
    0.19-0.22 from 15 degrees, in luminance). 0 below the horizon.
    """
    d = np.asarray(d, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    if d.shape[-1:] != (3,) or s.shape != (3,) or not np.linalg.norm(s) > 0:
        raise ValueError(f"sunsky_radiance takes directions (..., 3) and a non-zero sun (3,), got {d.shape}, {s.shape}")
    s = s / np.linalg.norm(s)
    radiance, elevations, rows, cols = _sunsky_table()
    e = float(np.clip(math.degrees(math.asin(float(np.clip(s[1], -1.0, 1.0)))), elevations[0], elevations[-1]))
    beta = np.degrees(np.arcsin(np.clip(d[..., 1], 0.0, 1.0)))
    # the view's azimuth from the sun's, both projected on the horizontal plane (either may be vertical)
    dh, sh_ = d[..., [0, 2]], s[[0, 2]]
    nd, ns = np.linalg.norm(dh, axis=-1), float(np.linalg.norm(sh_))
    cos_phi = np.where((nd > 1e-9) & (ns > 1e-9), (dh @ sh_) / np.maximum(nd * ns, 1e-12), 1.0)
    phi = np.degrees(np.arccos(np.clip(cos_phi, -1.0, 1.0)))
    i = int(np.clip(np.searchsorted(elevations, e) - 1, 0, len(elevations) - 2))
    w = (e - elevations[i]) / (elevations[i + 1] - elevations[i])
    cells = _bilinear_cells(rows, cols, beta, phi)  # the same cells in both tables of the sun's elevation
    out = _blend_bilinear(radiance[i], radiance[i + 1], w, cells)
    return np.where(d[..., 1:2] > 0, out, 0.0)


# ----------------------------------------------------------------------------- the sun's colour

SUN_TEMPERATURE_K = 5778.0
"""The sun outside the atmosphere as a black body of its effective temperature."""
ANGSTROM_BETA = 0.05
"""Aerosol optical depth at 1 um (Angstrom's turbidity coefficient): a clear atmosphere (Iqbal 1983: 0 clean,
0.1 clear, 0.2 turbid). With it the sun's colour agrees with Mitsuba 3's Hosek-Wilkie sun (``sunsky``) at
turbidity 2-4 within 5 % in red/green and blue/green from 10 degrees up (tests/physrelight/test_sky_model.py
test_08; 0.05 was picked from 0.05, 0.092 and 0.15 by that agreement, so the test checks its shape over
elevations and turbidities, not an independent value)."""
ANGSTROM_ALPHA = 1.3
"""Angstrom's wavelength exponent of the aerosol optical depth (the value for continental aerosol)."""
_WAVELENGTHS_NM = np.arange(380.0, 781.0, 5.0)


def _lobe(x: np.ndarray, mu: float, s1: float, s2: float) -> np.ndarray:
    return np.exp(-0.5 * ((x - mu) / np.where(x < mu, s1, s2)) ** 2)


def cie_1931_cmf(wavelength_nm: np.ndarray) -> np.ndarray:
    """``(N, 3)`` CIE 1931 2-degree colour-matching functions at ``(N,)`` wavelengths (nm), by the
    multi-lobe Gaussian fit of Wyman, Sloan and Shirley (JCGT 2013; within 1 % of the tabulated
    integrals, checked against colour-science's tables in the tests)."""
    x = np.asarray(wavelength_nm, dtype=np.float64)
    xb = 1.056 * _lobe(x, 599.8, 37.9, 31.0) + 0.362 * _lobe(x, 442.0, 16.0, 26.7) - 0.065 * _lobe(x, 501.1, 20.4, 26.2)
    yb = 0.821 * _lobe(x, 568.8, 46.9, 40.5) + 0.286 * _lobe(x, 530.9, 16.3, 31.1)
    zb = 1.217 * _lobe(x, 437.0, 11.8, 36.0) + 0.681 * _lobe(x, 459.0, 26.0, 13.8)
    return np.stack([xb, yb, zb], -1)


def rayleigh_optical_depth(wavelength_nm: np.ndarray) -> np.ndarray:
    """``(N,)`` Rayleigh optical depth of the whole atmosphere at sea level (Hansen and Travis 1974:
    ``0.008569 l^-4 (1 + 0.0113 l^-2 + 0.00013 l^-4)``, ``l`` in um; colour-science's Bodhaine et al. 1999
    is the tests' reference)."""
    lam = np.asarray(wavelength_nm, dtype=np.float64) / 1000.0
    return 0.008569 * lam ** -4 * (1.0 + 0.0113 * lam ** -2 + 0.00013 * lam ** -4)


def air_mass(elevation_deg: float) -> float:
    """Relative optical air mass towards a sun ``elevation_deg`` up (Kasten and Young 1989; 1 at the
    zenith, about 38 at the horizon; elevations below 0 are taken as 0)."""
    e = max(0.0, float(elevation_deg))
    return 1.0 / (math.sin(math.radians(e)) + 0.50572 * (e + 6.07995) ** -1.6364)


def sun_transmittance(wavelength_nm: np.ndarray, elevation_deg: float) -> np.ndarray:
    """``(N,)`` the direct sunlight's transmittance through a clear atmosphere (Beer-Lambert: Rayleigh
    scattering plus Angstrom's aerosol, :data:`ANGSTROM_BETA`, :data:`ANGSTROM_ALPHA`)."""
    lam = np.asarray(wavelength_nm, dtype=np.float64)
    tau = rayleigh_optical_depth(lam) + ANGSTROM_BETA * (lam / 1000.0) ** -ANGSTROM_ALPHA
    return np.exp(-air_mass(elevation_deg) * tau)


def _sun_rgb(elevation_deg: float) -> np.ndarray:
    from physrelight.colour import M_XYZ_TO_RGB

    lam = _WAVELENGTHS_NM * 1e-9
    planck = 1.0 / (lam ** 5 * (np.exp(1.438776877e-2 / (lam * SUN_TEMPERATURE_K)) - 1.0))
    xyz = ((planck * sun_transmittance(_WAVELENGTHS_NM, elevation_deg))[:, None] * cie_1931_cmf(_WAVELENGTHS_NM)).sum(0)
    return M_XYZ_TO_RGB @ xyz


def sun_colour(elevation_deg: float) -> np.ndarray:
    """``(3,)`` linear sRGB colour of the direct sun ``elevation_deg`` up, of luminance 1, white
    (1, 1, 1) at the zenith (a camera white-balanced for the high sun): warmer and redder as its light
    crosses more air (:func:`sun_transmittance`). Channels are clipped at 0 (the blue of a sun at the
    horizon)."""
    from physrelight.colour import LUMINANCE

    if not math.isfinite(float(elevation_deg)):
        raise ValueError(f"elevation must be a finite number of degrees, got {elevation_deg!r}")
    c = np.clip(_sun_rgb(elevation_deg) / _sun_rgb(90.0), 0.0, None)
    return c / float(np.asarray(LUMINANCE) @ c)


def _project(maps: np.ndarray) -> np.ndarray:
    """``(9, C)`` order-2 SH of ``C`` scalar lat-long maps ``(H, 2H, C)``, three at a time."""
    pad = (-maps.shape[-1]) % 3
    m = np.concatenate([maps, np.zeros(maps.shape[:-1] + (pad,))], -1)
    out = [np.asarray(sh.project_envmap(np.ascontiguousarray(m[..., i:i + 3]), order=2)) for i in range(0, m.shape[-1], 3)]
    return np.concatenate(out, -1)[:, :maps.shape[-1]]


@functools.lru_cache(maxsize=1)
def _fixed_parts() -> np.ndarray:
    """``(9, 3, 3)`` order-2 SH (coefficient, part, channel) of the parts that do not move with the sun:
    the clear sky (each channel divided by its zenith value, so its weight is the zenith's radiance),
    the overcast sky and the ground."""
    from physrelight import envmap

    d = envmap.directions(_MAP_HEIGHT, 2 * _MAP_HEIGHT)
    clear = clear_sky(d) / np.array(CLEAR_ZENITH)
    grey = np.stack([overcast_sky(d), (d[..., 1] < 0).astype(np.float64)], -1)
    clear_sh, grey_sh = _project(clear), _project(grey)  # (9, channel), (9, part)
    return np.concatenate([clear_sh[:, None, :], np.repeat(grey_sh[:, :, None], 3, -1)], 1)


@functools.lru_cache(maxsize=8)
def _glow_by_elevation(exponent: float) -> tuple[np.ndarray, np.ndarray]:
    """Elevations (degrees, every :data:`_COARSE_STEP_DEG` from 0 to 90) and ``(E, 9)`` the glow's SH
    for the sun at each, azimuth 0."""
    from physrelight import envmap

    d = envmap.directions(_MAP_HEIGHT, 2 * _MAP_HEIGHT)
    elev = np.arange(0.0, 90.0 + 1e-9, _COARSE_STEP_DEG)
    glows = np.stack([sun_glow(d, direction_from_angles(e, 0.0), exponent) for e in elev], -1)
    return elev, _project(glows).T


def _glow_sh(elevation_deg: np.ndarray, azimuth_deg: np.ndarray, exponent: float) -> np.ndarray:
    """``(N, 9)`` the glow's SH for suns at ``(N,)`` elevations and azimuths: linear in elevation
    between the tabulated ones, turned exactly in azimuth."""
    elev, table = _glow_by_elevation(float(exponent))
    at0 = np.stack([np.interp(elevation_deg, elev, table[:, k]) for k in range(9)], -1)
    R = rotations.about_y_many(np.atleast_1d(azimuth_deg))
    return np.asarray(sh.rotate(np.repeat(at0[..., None], 3, -1), R))[..., 0]


def _design(elevation_deg: np.ndarray, azimuth_deg: np.ndarray, exponent: float = GLOW_EXPONENT) -> np.ndarray:
    """``(N, 3, 9, 5)``: per channel, the SH of each part (:data:`COMPONENTS`) for suns at the given directions."""
    s = direction_from_angles(elevation_deg, azimuth_deg)
    n = len(s)
    moving = np.stack([np.asarray(sh.basis(s, 2)).reshape(n, 9), _glow_sh(elevation_deg, azimuth_deg, exponent)], -1)
    fixed = np.broadcast_to(_fixed_parts().transpose(2, 0, 1)[None], (n, 3, 9, 3))
    return np.concatenate([np.broadcast_to(moving[:, None], (n, 3, 9, 2)), fixed], -1)


def _nnls_batched(A: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact non-negative least squares ``min ||A x - b||, x >= 0`` for ``A (N, M, K)``, ``b (N, M, C)``
    (every channel its own problem), by trying every support: the optimum is the unconstrained
    solution on its support, which is feasible there, and a feasible support's solution is a
    feasible point. Returns ``x (N, K, C)`` and the squared residuals ``(N, C)``."""
    n, _, k = A.shape
    # Every support's normal equations are blocks of one Gram matrix: form it once.
    gram = A.transpose(1, 2) @ A  # (N, K, K)
    atb = A.transpose(1, 2) @ b  # (N, K, C)
    btb = (b * b).sum(1)  # (N, C)
    best_x = torch.zeros(n, k, b.shape[-1], dtype=A.dtype)
    best_r = btb.clone()  # the empty support
    for size in range(1, k + 1):
        for support in itertools.combinations(range(k), size):
            idx = list(support)
            # a tiny ridge: the parts' SH can be nearly collinear
            G = gram[:, idx][:, :, idx] + 1e-12 * torch.eye(size, dtype=A.dtype)
            g = atb[:, idx]
            xs = torch.linalg.solve(G, g)
            r = (btb - 2 * (xs * g).sum(1) + (xs * (G @ xs)).sum(1)).clamp_min(0)
            ok = (xs >= -1e-12).all(1) & (r < best_r)
            best_r = torch.where(ok, r, best_r)
            x = torch.zeros_like(best_x)
            x[:, idx] = xs.clamp_min(0)
            best_x = torch.where(ok[:, None, :], x, best_x)
    return best_x, best_r


@dataclass(frozen=True)
class SkyFit:
    """The outdoor sky model that best explains an order-2 SH lighting (:func:`fit_sky`).

    Attributes:
        sun_direction: ``(3,)`` unit world direction towards the sun (elevation >= 0).
        weights: ``(5, 3)`` non-negative weight of each part of :data:`COMPONENTS` per channel (the
            sun's row is its irradiance on a surface facing it).
        relative_residual: ``||SH(model) - SH(given)|| / ||SH(given)||`` over all 27 coefficients.
        glow_exponent: the glow's lobe exponent (:func:`sun_glow`).
    """

    sun_direction: np.ndarray
    weights: np.ndarray
    relative_residual: float
    glow_exponent: float = FIT_GLOW_EXPONENT

    def sh(self) -> np.ndarray:
        """``(9, 3)`` order-2 radiance SH of the fitted model, sun and ground included."""
        e = math.degrees(math.asin(float(np.clip(self.sun_direction[1], -1, 1))))
        a = math.degrees(math.atan2(float(self.sun_direction[0]), -float(self.sun_direction[2])))
        return np.einsum("cmk,kc->mc", _design(np.array([e]), np.array([a]), self.glow_exponent)[0], self.weights)

    def radiance(self, d: np.ndarray) -> np.ndarray:
        """``(..., 3)`` the fitted sky (glow, clear and overcast parts; no sun disc, no ground) along
        unit directions ``d (..., 3)``."""
        w = self.weights
        clear = clear_sky(d) / np.array(CLEAR_ZENITH)
        return (sun_glow(d, self.sun_direction, self.glow_exponent)[..., None] * w[1] + clear * w[2]
                + overcast_sky(d)[..., None] * w[3])


def fit_sky(coeffs: Array, glow_exponent: float = FIT_GLOW_EXPONENT) -> SkyFit:
    """The sky model of this module that best explains order-2 radiance SH ``coeffs (9, 3)`` (world frame),
    its glow a lobe of ``glow_exponent`` (:func:`sun_glow`). About 0.3 s at one thread; the last 16 fits are
    remembered (a relighting asks for its target's sun and for its sky), so treat the result as read-only.

    Raises:
        ValueError: ``coeffs`` is not ``(9, 3)`` and finite, or has no positive DC term.
    """
    c = np.asarray(coeffs.detach().cpu().numpy() if isinstance(coeffs, torch.Tensor) else coeffs, dtype=np.float64)
    if c.shape != (9, 3):
        raise ValueError(f"coeffs must be order-2 SH of shape (9, 3), got {c.shape}")
    if not np.all(np.isfinite(c)):
        raise ValueError("coeffs must be finite")
    if not (isinstance(glow_exponent, (int, float)) and 1.0 <= float(glow_exponent) <= 256.0):
        raise ValueError(f"glow_exponent must be a number in [1, 256], got {glow_exponent!r}")
    if not np.all(c[0] > 0):
        raise ValueError(f"coeffs must have a positive DC term in every channel, got {c[0].tolist()}")
    return _fit_sky(c.tobytes(), float(glow_exponent))


@functools.lru_cache(maxsize=16)
def _fit_sky(key: bytes, glow_exponent: float) -> SkyFit:
    c = np.frombuffer(key, dtype=np.float64).reshape(9, 3)

    def solve(elev: np.ndarray, azim: np.ndarray) -> tuple[int, np.ndarray, np.ndarray, float]:
        n = len(elev)
        A = torch.from_numpy(np.ascontiguousarray(_design(elev, azim, glow_exponent))).reshape(n * 3, 9, 5)
        b = torch.from_numpy(np.ascontiguousarray(c.T)).reshape(1, 3, 9, 1).expand(n, 3, 9, 1).reshape(n * 3, 9, 1)
        x, r = _nnls_batched(A, b)
        total = r.reshape(n, 3).sum(1)
        i = int(torch.argmin(total))
        return i, x.reshape(n, 3, 5)[i].T.numpy(), elev[i:i + 1], float(total[i])

    step = _COARSE_STEP_DEG
    e, a = np.meshgrid(np.arange(0.0, 90.0 + 1e-9, step), np.arange(0.0, 360.0, step), indexing="ij")
    e, a = e.ravel(), a.ravel()
    i, _, _, _ = solve(e, a)
    fine = np.arange(-step, step + 1e-9, _FINE_STEP_DEG)
    fe, fa = np.meshgrid(np.clip(e[i] + fine, 0.0, 90.0), a[i] + fine, indexing="ij")
    fe, fa = fe.ravel(), fa.ravel()
    j, w, _, r2 = solve(fe, fa)
    s = direction_from_angles(fe[j], fa[j])
    s, w = s / np.linalg.norm(s), np.array(w)
    s.setflags(write=False)  # remembered by the cache: shared between callers
    w.setflags(write=False)
    return SkyFit(sun_direction=s, weights=w,
                  relative_residual=math.sqrt(r2) / float(np.linalg.norm(c)), glow_exponent=float(glow_exponent))


def horizon_clamped(rays: torch.Tensor) -> torch.Tensor:
    """``rays (..., 3)`` unit world directions with those below :data:`HORIZON_Y` raised to it (a model
    sky has no ground: a sky pixel below the horizon, a mask or a pitch a little off, shows the sky just
    above the horizon rather than black)."""
    low = rays[..., 1] < HORIZON_Y
    raised = torch.cat([rays[..., :1], torch.full_like(rays[..., 1:2], HORIZON_Y), rays[..., 2:]], -1)
    return torch.where(low[..., None], torch.nn.functional.normalize(raised, dim=-1), rays)


def sun_disc(rays: torch.Tensor, sun_direction: Array) -> torch.Tensor:
    """``(...,)`` radiance along ``rays (..., 3)`` of a sun disc of irradiance 1 towards ``sun_direction
    (3,)`` (radius :data:`SUN_RADIUS_DEG`, radiance ``1 / (pi r^2)`` inside)."""
    r = math.radians(SUN_RADIUS_DEG)
    d = torch.tensor(np.array(sun_direction, dtype=np.float64), dtype=rays.dtype)
    return (rays @ d > math.cos(r)).to(rays.dtype) / (math.pi * r * r)


def sky_view(fit: SkyFit, rays: torch.Tensor) -> torch.Tensor:
    """``(h, w, 3)`` the fitted sky along camera rays ``(h, w, S, 3)`` (world frame,
    :func:`physrelight.panorama.camera_rays`), each pixel the mean over its ``S`` rays, with the sun's
    disc (:func:`sun_disc` times the fitted sun's irradiance); rays are :func:`horizon_clamped`."""
    r = horizon_clamped(rays.double())
    out = torch.from_numpy(fit.radiance(r.numpy()))
    out = out + sun_disc(r, fit.sun_direction)[..., None] * torch.from_numpy(np.array(fit.weights[0]))
    return out.mean(-2)
