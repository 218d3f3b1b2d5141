"""Lat-long environment maps: EXR IO, texel directions and solid angles, brute-force
irradiance (the yardstick for everything SH), resampling, rotation and the sun/sky split.

Layout (Mitsuba 3's ``envmap``; DESIGN.md). A map is ``(H, W, 3)`` linear RGB radiance
with ``W == 2 H``, in the world frame (Y up):

* column ``j`` is at ``u = (j + 0.5) / W`` (texel-centred), with
  ``u = atan2(d.x, -d.z) / 2pi``, so ``d.x = sin(theta) sin(phi)``,
  ``d.z = -sin(theta) cos(phi)`` for ``phi = 2 pi u``;
* row ``i`` is at ``theta = pi i / (H - 1)`` (align-corners), ``d.y = cos(theta)``:
  row 0 is the zenith (+Y), row ``H - 1`` the nadir.

The map is read as the bilinear interpolant of these samples (wrapping in u), the way
Mitsuba looks it up (checked against Mitsuba 3.9.1's ``envmap.eval``). Integrals treat
it the same way: a texel's solid angle is the integral of its bilinear hat function
(they sum to exactly 4 pi), and :func:`physrelight.sh.project_envmap` is exact for
the interpolant. The brute-force :func:`irradiance_reference` is a texel quadrature of
the same function, within ``O(dt^2)`` of it (1e-5 relative at 1024 x 512).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from physrelight import colour, io
from physrelight._checks import (
    Array,
    check_finite,
    check_last_dim,
    check_nonnegative,
    check_rotation,
    to_tensor,
)

LUMINANCE = colour.LUMINANCE
"""Rec. 709 / linear sRGB luminance weights."""

# DWA compression leaves small negative ringing around bright texels (seen down to
# -2e-3 next to a 1.4e3 sun in the shared maps): io.read_radiance clamps it, and refuses
# anything more negative than this (a broken map, not compression noise).
DWA_NEGATIVE_TOLERANCE = io.DWA_NEGATIVE_TOLERANCE


def check_envmap(env: torch.Tensor, name: str = "env") -> None:
    """Raise ``ValueError`` unless ``env`` is an ``(H, W, 3)`` lat-long map, ``W == 2 H``,
    finite and non-negative."""
    if env.ndim != 3 or env.shape[-1] != 3:
        raise ValueError(f"{name} must be an (H, W, 3) lat-long RGB map, got shape {tuple(env.shape)}")
    h, w = env.shape[0], env.shape[1]
    if h < 2 or w != 2 * h:
        raise ValueError(f"{name} must be a 2:1 lat-long map (W == 2 H), got H={h}, W={w}")
    check_finite(env, name)
    check_nonnegative(env, name)


# ------------------------------------------------------------------------ IO


def read(path: str | os.PathLike) -> np.ndarray:
    """Read an EXR (or Radiance ``.hdr``) environment map as ``float32 (H, W, 3)``.

    The alpha channel, if any, is dropped. Slightly negative values from lossy (DWA)
    compression are clamped to 0; NaN/inf or strongly negative values raise
    (:func:`physrelight.io.read_radiance`).
    """
    return io.read_radiance(path)


def write(path: str | os.PathLike, image: Array) -> None:
    """Write a linear ``(H, W, 3)`` image as a float32, ZIP-compressed (lossless) RGB EXR, atomically."""
    t, _ = to_tensor(image, "image")
    if t.ndim != 3 or t.shape[-1] != 3:
        raise ValueError(f"image must have shape (H, W, 3), got {tuple(t.shape)}")
    check_finite(t, "image")
    io.write_exr(path, t)


# ---------------------------------------------------------------- geometry


@functools.lru_cache(maxsize=16)
def _directions(height: int, width: int) -> np.ndarray:
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2 * np.pi * (np.arange(width) + 0.5) / width
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    d = np.stack(np.broadcast_arrays(st * np.sin(phi), ct, -st * np.cos(phi)), axis=-1)
    d.setflags(write=False)
    return d


def _check_resolution(height: int, width: int) -> None:
    if height < 2 or width != 2 * height:
        raise ValueError(f"a lat-long map needs H >= 2 and W == 2 H, got H={height}, W={width}")


def directions(height: int, width: int) -> np.ndarray:
    """``(H, W, 3)`` float64 unit world directions of the texel samples (Y up)."""
    _check_resolution(height, width)
    return _directions(height, width).copy()


def direction_from_angles(elevation_deg: Array, azimuth_deg: Array) -> np.ndarray:
    """``(..., 3)`` float64 unit world directions at ``elevation_deg`` above the horizon and ``azimuth_deg``
    (broadcast together): azimuth 0 is world -Z (where a level camera looks, the map's ``u = 0``), 90 is +X,
    so ``d = (cos e sin a, sin e, -cos e cos a)``. The one place the library turns angles into directions
    (suns, sky tables, cameras' targets)."""
    e = np.radians(np.asarray(elevation_deg, dtype=np.float64))
    a = np.radians(np.asarray(azimuth_deg, dtype=np.float64))
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(a))):
        raise ValueError(f"elevation and azimuth must be finite degrees, got {elevation_deg!r}, {azimuth_deg!r}")
    return np.stack(np.broadcast_arrays(np.cos(e) * np.sin(a), np.sin(e), -np.cos(e) * np.cos(a)), -1)


@functools.lru_cache(maxsize=16)
def _solid_angles(height: int, width: int) -> np.ndarray:
    # The solid angle a texel's value covers under bilinear interpolation: the integral
    # of its hat function, dphi * int hat_i(theta) sin(theta) dtheta, in closed form.
    dt = np.pi / (height - 1)
    theta = dt * np.arange(height)
    band = np.sin(theta) * 4 * np.sin(dt / 2) ** 2 / dt  # 2 (1 - cos dt) / dt, without cancellation
    # 1 - sin(dt)/dt by its Taylor series where the closed form cancels.
    pole = 1 - np.sin(dt) / dt if dt > 0.1 else dt**2 / 6 - dt**4 / 120 + dt**6 / 5040 - dt**8 / 362880
    band[0] = band[-1] = pole
    out = np.repeat((band * 2 * np.pi / width)[:, None], width, axis=1)
    out.setflags(write=False)
    return out


def solid_angles(height: int, width: int) -> np.ndarray:
    """``(H, W)`` float64 texel solid angles; they sum to 4 pi.

    Each is the integral over the sphere of the texel's bilinear hat function, so
    ``sum L_ij dOmega_ij`` is exactly ``int L dw`` of the map as the renderer
    interpolates it. Interior rows: ``sin(theta_i) 2 (1 - cos dt) / dt * 2 pi / W``;
    pole rows: ``(1 - sin(dt) / dt) * 2 pi / W`` (``dt = pi / (H - 1)``); within
    ``O(dt^2)`` of DESIGN.md's ``sin(theta_i) dt 2 pi / W``.
    """
    _check_resolution(height, width)
    return _solid_angles(height, width).copy()


def luminance(env: Array) -> Array:
    """``(..., 3)`` linear RGB -> ``(...)`` luminance (Rec. 709 weights)."""
    t, restore = to_tensor(env, "env")
    check_last_dim(t, 3, "env", "(..., 3)")
    return restore(t @ torch.tensor(LUMINANCE, dtype=t.dtype, device=t.device))


def luminance_integral(env: Array) -> float:
    """``int Y(L(w)) dw`` over the sphere: the scale of the SH irradiance error bounds."""
    t, _ = to_tensor(env, "env")
    check_envmap(t, "env")
    w = torch.tensor(_solid_angles(t.shape[0], t.shape[1]), device=t.device)
    return float((to_tensor(luminance(t), "env")[0].to(torch.float64) * w).sum())


def irradiance_reference(env: Array, normals: Array, chunk_texels: int = 1 << 22) -> Array:
    """Brute-force irradiance ``E(n) = sum_texels L(d) max(0, n . d) dOmega``.

    The yardstick for everything SH: exact for the sampled map, no truncation. Cost
    ``O(N H W)``, chunked over normals so memory stays near ``chunk_texels`` doubles.

    Args:
        env: ``(H, W, 3)`` lat-long radiance, world frame.
        normals: ``(N, 3)`` unit normals in the world frame (normalised here).

    Returns:
        ``(N, 3)`` irradiance.
    """
    e, _ = to_tensor(env, "env")
    n, restore = to_tensor(normals, "normals")
    check_envmap(e, "env")
    check_last_dim(n, 3, "normals", "(N, 3)")
    check_finite(n, "normals")
    if n.ndim != 2:
        raise ValueError(f"normals must have shape (N, 3), got {tuple(n.shape)}")
    norm = torch.linalg.vector_norm(n, dim=-1, keepdim=True)
    if n.numel() and bool((norm < 1e-8).any()):
        raise ValueError("normals holds a zero-length vector")
    h, w = e.shape[0], e.shape[1]
    d = torch.from_numpy(_directions(h, w).reshape(-1, 3).copy()).to(e.device)
    lw = e.reshape(-1, 3).to(torch.float64) * torch.from_numpy(_solid_angles(h, w).reshape(-1, 1).copy()).to(e.device)
    # Texels with no radiance add nothing: skipping them speeds up sparse (sun-only) maps.
    keep = lw.abs().sum(dim=1) > 0
    d, lw = d[keep], lw[keep]
    n64 = (n / norm).to(torch.float64)
    step = max(1, chunk_texels // max(1, d.shape[0]))
    out = [(n64[i:i + step] @ d.T).clamp_min_(0.0) @ lw for i in range(0, n64.shape[0], step)]
    res = torch.cat(out) if out else torch.zeros(0, 3, dtype=torch.float64)
    return restore(res.to(n.dtype))


# ---------------------------------------------------------------- resampling


def _lookup_coordinates(env: Array, dirs: Array) -> tuple[torch.Tensor, torch.Tensor, Callable, torch.Tensor,
                                                          torch.Tensor]:
    """What both lookups share: the checked map ``e (H, W, 3)``, the unit directions ``d (..., 3)`` in its dtype,
    the function that gives results back in the type of ``dirs``, and each direction's continuous texel
    coordinates: texel-centred columns ``x`` (wrapping) and align-corners rows ``y``."""
    e, _ = to_tensor(env, "env")
    d, restore = to_tensor(dirs, "dirs")
    check_envmap(e, "env")
    check_last_dim(d, 3, "dirs", "(..., 3)")
    check_finite(d, "dirs")
    d = d.to(e.dtype)
    d = d / torch.linalg.vector_norm(d, dim=-1, keepdim=True).clamp_min(1e-12)
    h, w = e.shape[0], e.shape[1]
    u = torch.atan2(d[..., 0], -d[..., 2]) / (2 * math.pi)
    u = u - torch.floor(u)
    v = torch.acos(d[..., 1].clamp(-1.0, 1.0)) / math.pi
    return e, d, restore, u * w - 0.5, v * (h - 1)


def _at_poles(out: torch.Tensor, d: torch.Tensor, north: torch.Tensor, south: torch.Tensor) -> torch.Tensor:
    """``out`` with the directions exactly at a pole given ``north`` or ``south``: there the column (atan2 of two
    zeros) is undefined, and the pole is one point, so a lookup uses the pole rows' means, not an arbitrary texel."""
    at_pole = d[..., 1].abs() >= 1.0 - 1e-12
    if bool(at_pole.any()):
        out = torch.where(at_pole[..., None], torch.where(d[..., 1:2] > 0, north, south), out)
    return out


def sample(env: Array, dirs: Array) -> Array:
    """Bilinear lookup of a lat-long map in world directions, as Mitsuba's ``envmap`` does.

    Agrees with Mitsuba 3.9.1 ``envmap.eval`` to float32 rounding (2.6e-6 on random
    directions) except exactly at the poles, where this returns the pole row's mean.

    Args:
        env: ``(H, W, 3)`` map.
        dirs: ``(..., 3)`` directions (normalised here).

    Returns:
        ``(..., 3)`` radiance.
    """
    e, d, restore, x, y = _lookup_coordinates(env, dirs)
    h, w = e.shape[0], e.shape[1]
    x0 = torch.floor(x)
    y0 = torch.floor(y).clamp(0, h - 2)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]
    x0 = x0.long() % w
    x1 = (x0 + 1) % w
    y0 = y0.long()
    y1 = y0 + 1
    top = e[y0, x0] * (1 - fx) + e[y0, x1] * fx
    bot = e[y1, x0] * (1 - fx) + e[y1, x1] * fx
    out = top * (1 - fy) + bot * fy
    return restore(_at_poles(out, d, e[0].mean(dim=0), e[-1].mean(dim=0)))


def sample_bspline(env: Array, dirs: Array) -> Array:
    """Cubic B-spline lookup of a lat-long map in world directions: for views that magnify the map.

    Where a pixel is smaller than a texel (a 640-px photo at 60 degrees sees a 1024-wide map's texel over 3.4
    pixels, a 4000-px one over 23), bilinear interpolation (:func:`sample`) is only continuous: its slope jumps at
    every texel, and an HDR map's bright texels, clipped on display, become squares. The uniform cubic B-spline
    is smooth (C2), never negative (no dark rings round a bright texel, unlike bicubic interpolation) and sums
    its weights to 1, so a constant or a linear function of the texel coordinates comes back exactly and the
    map's mean is kept; it approximates rather than interpolates (a lone bright texel is spread to 4/9 at its
    centre). Same coordinates as :func:`sample` (texel-centred columns, wrapping; align-corners rows, clamped at
    the poles, where the pole rows' means stand in for the columns').

    Args:
        env: ``(H, W, 3)`` map.
        dirs: ``(..., 3)`` directions (normalised here).

    Returns:
        ``(..., 3)`` radiance.
    """
    e, d, restore, x, y = _lookup_coordinates(env, dirs)
    h, w = e.shape[0], e.shape[1]
    x0, y0 = torch.floor(x), torch.floor(y)
    wx, wy = _bspline_weights(x - x0), _bspline_weights(y - y0)
    x0, y0 = x0.long(), y0.long()
    flat = e.reshape(h * w, -1)
    out = torch.zeros(*d.shape[:-1], flat.shape[-1], dtype=e.dtype)
    rows = [(y0 + (a - 1)).clamp(0, h - 1) * w for a in range(4)]
    cols = [(x0 + (b - 1)) % w for b in range(4)]
    for a in range(4):
        for b in range(4):
            # index_select gathers whole texels (rows of flat) faster than advanced indexing, the same values
            texels = flat.index_select(0, (rows[a] + cols[b]).reshape(-1)).reshape(out.shape)
            out += (wy[a] * wx[b])[..., None] * texels
    # at a pole (y = 0 or H - 1, the weights 1/6, 4/6, 1/6 with the outer row clamped to the pole's)
    means = e.mean(dim=1)
    north = (5 * means[0] + means[1]) / 6
    south = (5 * means[-1] + means[-2]) / 6
    return restore(_at_poles(out, d, north, south))


def _bspline_weights(t: torch.Tensor) -> list[torch.Tensor]:
    """The four uniform cubic B-spline weights of the texels at offsets -1, 0, 1, 2 for a fraction ``t`` in [0, 1)."""
    t2, t3 = t * t, t * t * t
    return [(1 - t) ** 3 / 6, (3 * t3 - 6 * t2 + 4) / 6, (-3 * t3 + 3 * t2 + 3 * t + 1) / 6, t3 / 6]


def rotate(env: Array, R: Array) -> Array:
    """Resample a map turned by rotation ``R``: ``env'(w) = env(R^T w)``.

    Same convention as :func:`physrelight.sh.rotation`, so
    ``project_envmap(rotate(env, R)) ~= rotation(R) @ project_envmap(env)`` up to the
    resampling (bilinear) error. A rotation about +Y by a multiple of ``360 / W``
    degrees is an exact column shift.
    """
    e, restore = to_tensor(env, "env")
    r, _ = to_tensor(R, "R")
    check_envmap(e, "env")
    if r.shape != (3, 3):
        raise ValueError(f"R must have shape (3, 3), got {tuple(r.shape)}")
    check_rotation(r, "R")
    d = torch.from_numpy(_directions(e.shape[0], e.shape[1]).copy()).to(e.device, e.dtype)
    src = d @ r.to(e.dtype)  # rows: (R^T w)^T = w^T R
    return restore(sample(e, src).clamp_min(0.0))


def _tent(n_coarse: int, n_fine: int, m: int, periodic: bool) -> np.ndarray:
    """``(n_coarse, n_fine)`` hat weights of coarse samples over a fine grid nested ``m`` times."""
    a = np.zeros((n_coarse, n_fine))
    for f in range(n_fine):
        pos = f / m if not periodic else (f + 0.5) / m - 0.5  # in coarse sample units
        lo = int(np.floor(pos))
        frac = pos - lo
        for c, w in ((lo, 1 - frac), (lo + 1, frac)):
            if periodic:
                a[c % n_coarse, f] += w
            elif 0 <= c < n_coarse:
                a[c, f] += w
    return a


def downsample(env: Array, height: int) -> Array:
    """Resample a map to ``(height, 2 height, 3)`` keeping its integral.

    Each coarse texel is the average of the fine map (as interpolated) under the coarse
    texel's own hat function. The hats sum to one everywhere, so ``int L dw`` is kept up
    to quadrature error (1e-4 relative from 1024 x 512 to 256 x 128), and the low
    orders of the SH with it; detail finer than the coarse texel is averaged away.

    Args:
        env: ``(H, W, 3)`` map.
        height: new height ``H' <= H``.
    """
    e, restore = to_tensor(env, "env")
    check_envmap(e, "env")
    h = e.shape[0]
    if not 2 <= height <= h:
        raise ValueError(f"height must be in [2, {h}] (downsampling only), got {height}")
    if height == h:
        return restore(e.clone())
    m = 2 * int(math.ceil((h - 1) / (height - 1)))
    hs, ws = (height - 1) * m + 1, 2 * height * m
    theta = np.linspace(0.0, np.pi, hs)
    # The sample grid has the lat-long layout (align-corners rows, texel-centred columns), not 2:1;
    # built uncached: it is large and used once per downsampling.
    fine = to_tensor(sample(e.to(torch.float64), torch.tensor(_directions.__wrapped__(hs, ws))), "fine")[0]
    # Quadrature weight sin(theta) of each sample row; at the poles the first sample
    # row away from the pole carries the cap (sin(0) = 0 would drop it).
    w_theta = torch.from_numpy(np.maximum(np.sin(theta), np.sin(np.pi / (hs - 1)) / 4))
    a_theta = torch.from_numpy(_tent(height, hs, m, periodic=False))
    a_phi = torch.from_numpy(_tent(2 * height, ws, m, periodic=True))
    num = torch.einsum("ih,hwc,jw->ijc", a_theta * w_theta, fine, a_phi)
    den = (a_theta * w_theta).sum(dim=1)[:, None] * a_phi.sum(dim=1)[None, :]
    return restore((num / den[..., None]).to(e.dtype))


# ---------------------------------------------------------------- sun / sky split


@dataclass(frozen=True)
class SunSky:
    """An outdoor map split into a sky without the sun and a delta sun.

    Attributes:
        sky: ``(H, W, 3)`` the map with the solar region filled by the surrounding sky.
        direction: ``(3,)`` unit world direction towards the sun, or ``None``.
        irradiance: ``(3,)`` sun irradiance on a surface facing it (W m^-2); zeros when
            no sun was found.
        fraction: the sun's share of ``int Y(L) dw`` of the original map.
    """

    sky: np.ndarray
    direction: np.ndarray | None
    irradiance: np.ndarray
    fraction: float

    @property
    def has_sun(self) -> bool:
        return self.direction is not None


def split_sun(env: Array, radius_deg: float = 3.0, min_fraction: float = 0.01,
              contrast: float = 4.0) -> SunSky:
    """Split an outdoor map into sky + sun: find the solar peak and remove it.

    The brightest texel seeds the search. Texels within ``radius_deg`` of it whose
    luminance exceeds ``contrast`` times the surrounding sky (the median of an annulus
    from ``radius_deg`` to ``2 radius_deg``) form the solar region. Its radiance above
    the surrounding sky becomes a delta sun at the excess-weighted mean direction; the
    region is refilled with the annulus median. Energy is conserved exactly:
    ``int L dw`` of the sky plus the sun's irradiance equals that of the map.

    If the excess carries less than ``min_fraction`` of ``int Y(L) dw`` (an overcast
    sky, a lamp in a courtyard), there is no sun: the map is returned unchanged.

    Args:
        env: ``(H, W, 3)`` lat-long radiance.
        radius_deg: largest angular radius of the solar region (disk plus blur of the
            map, a few texels at 1k).
        min_fraction: smallest energy share for the peak to count as a sun.
        contrast: luminance ratio to the surrounding sky for a texel to join the region.
    """
    e, _ = to_tensor(env, "env")
    check_envmap(e, "env")
    if not 0 < radius_deg < 45:
        raise ValueError(f"radius_deg must be in (0, 45), got {radius_deg}")
    arr = e.detach().cpu().numpy().astype(np.float64)
    h, w = arr.shape[:2]
    dirs = _directions(h, w)
    dw = _solid_angles(h, w)
    y = arr @ np.asarray(LUMINANCE)
    total = float((y * dw).sum())
    peak = np.unravel_index(int(np.argmax(y)), y.shape)
    cosang = dirs @ dirs[peak]
    inner = cosang >= math.cos(math.radians(radius_deg))
    ring = (cosang < math.cos(math.radians(radius_deg))) & (cosang >= math.cos(math.radians(2 * radius_deg)))
    background = np.median(arr[ring], axis=0) if ring.any() else np.zeros(3)
    bg_y = float(background @ np.asarray(LUMINANCE))
    region = inner & (y > contrast * max(bg_y, 1e-12))
    excess = np.clip(arr - background, 0.0, None) * region[..., None]
    sun_e = (excess * dw[..., None]).sum(axis=(0, 1))
    fraction = float(sun_e @ np.asarray(LUMINANCE)) / max(total, 1e-30)
    if total <= 0 or fraction < min_fraction:
        return SunSky(sky=arr.astype(np.float32), direction=None, irradiance=np.zeros(3), fraction=0.0)
    weights = (excess @ np.asarray(LUMINANCE)) * dw
    direction = (dirs * weights[..., None]).sum(axis=(0, 1))
    direction /= np.linalg.norm(direction)
    sky = arr.copy()
    # Keep radiance below the background (rare) and replace the excess by the fill.
    sky[region] = np.minimum(arr[region], background)
    # Exact energy bookkeeping: the sun carries what the sky lost.
    sun_e = ((arr - sky) * dw[..., None]).sum(axis=(0, 1))
    fraction = float(sun_e @ np.asarray(LUMINANCE)) / total
    return SunSky(sky=sky.astype(np.float32), direction=direction, irradiance=sun_e, fraction=fraction)
