"""The sun read from a photo's visible sky, as a posterior over its position.

A clear sky is bright towards the sun (the aureole), brighter towards the horizon, and its horizon is
brighter on the sun's side: through a known camera (pitch and field of view, or a full
``world_to_camera``), the sky pixels say where the sun is even when it is out of the frame.
:func:`estimate_sun_from_sky` fits a physical sky to them and returns a :class:`SunPosterior`.

The sky model, per channel ``c`` along a world direction ``d``::

    L_c(d) = (1 - m) HW_c(d; s, T) / Z(s, T) + m O(d)

* ``HW``: Mitsuba 3's Hosek-Wilkie sky (no sun) for a sun towards ``s`` at turbidity ``T``
  (:data:`SUNSKY_TURBIDITY_TABLE`, written by :mod:`synth.sunsky_table` ``--turbidities``; T = 2-6),
  divided by its zenith luminance ``Z``, so the overcast mix ``m`` is the overcast part's share of the zenith;
* ``O``: the CIE overcast sky (:func:`physrelight.sky_model.overcast_sky`, zenith 1). ``m = 1`` has no sun.

The photo's response: a display image (the default) is linearised with the sRGB curve; what the camera did
beyond that (exposure, white balance, a tone curve) is modelled as ``I_c = a_c L_c^g``: a free level per
channel ``a_c`` and one gamma-like exponent ``g`` in [:data:`MIN_EXPONENT`, :data:`MAX_EXPONENT`], fitted
in closed form for every hypothesis (linear in log space).

The likelihood, in log space over blocks of sky pixels (:func:`sky_blocks`): a residual
``r = log I_obs - log I_model`` costs ``log(1 + (r / sigma)^2)`` (Cauchy: a cloud is an outlier, not a
pull), ``sigma`` = :data:`LOG_SIGMA`; a clipped channel (display value >= ``clip_level``) is a bound,
"at least this bright": it costs only where the model is darker than the bound (one-sided), it is never
dropped. Neighbouring pixels of a real sky are not independent (clouds, haze, the tone curve), so the summed
cost is scaled to :data:`EFFECTIVE_SAMPLES_PER_SR` independent observations per steradian of sky (a tempered
likelihood; the number sets how wide the posterior is, checked by the tests' coverage). Priors: the sun
uniform over the sky's solid angle (elevation 2-90 degrees), the turbidity uniform on 2-6, the mix uniform
on :data:`MIXES`. The posterior over the sun's position marginalises turbidity and mix, the sunless
``m = 1`` included (it adds the same to every cell: an overcast sky gives a flat posterior).

Conventions: world frame Y up, azimuth as :func:`physrelight.envmap.direction_from_angles` (0 = world -Z,
90 = +X: clockwise seen from above). ``relight --sun ELEV AZIM`` counts the azimuth from straight ahead of the
camera: :attr:`SunPosterior.azimuth_deg` is that (the world azimuth minus the camera's heading; with
``pitch_deg``/``fov_deg`` the camera looks along world -Z and the two agree).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from physrelight import sh
from physrelight._checks import Array
from physrelight.camera import project
from physrelight.colour import LUMINANCE, srgb_to_linear
from physrelight.envmap import direction_from_angles
from physrelight.panorama import camera_rays, level_camera, view_intrinsics
from physrelight.sky_model import overcast_sky, sun_colour

__all__ = ["AZIMUTH_STEP_DEG", "CLIP_LEVEL", "DARK_SKY_LEVEL", "EFFECTIVE_SAMPLES_PER_SR", "ELEVATIONS_DEG", "LOG_SIGMA",
           "MAX_BLOCKS_PER_SIDE", "MAX_CLIPPED_SKY", "MAX_EXPONENT", "MAX_FIT_COST", "MAX_UNSEEN_SHARE", "MIN_EXPONENT",
           "MIN_SKY_PIXELS", "MIXES", "PREVIEW_SIZE", "SEEN_QUANTILE", "SEEN_RADIUS_DEG", "SKY_KINDS", "SkyBlocks",
           "SUNSKY_TURBIDITY_TABLE", "SunPosterior", "estimate_sun_from_sky", "hosek_wilkie_sky", "lighting_preview",
           "sky_blocks", "unseen_in_frame"]

SUNSKY_TURBIDITY_TABLE = Path(__file__).resolve().parent / "data" / "sunsky_turbidity_table.safetensors"
"""Mitsuba 3's Hosek-Wilkie sky at turbidities 2-6 (``(5, 23, 31, 61, 3)`` float16, 1.3 MB), per turbidity in the
units of :data:`physrelight.sky_model.SUNSKY_TABLE` (over its sun's irradiance luminance, white-balanced to its
zenith sun); written by ``python -m synth.sunsky_table --turbidities``."""
AZIMUTH_STEP_DEG = 5.0
"""The posterior grid's azimuth step (72 columns, centred on multiples of 5 degrees)."""
ELEVATIONS_DEG = tuple(float(e) for e in np.arange(2.0, 90.0, 4.0))
"""The posterior grid's sun elevations: 2, 6, ..., 86 degrees (the table's lowest sun is 2 degrees)."""
MIXES = (0.0, 0.25, 0.5, 0.75, 1.0)
"""The overcast mixes ``m`` tried (1 = the CIE overcast sky alone: no sun)."""
LOG_SIGMA = 0.05
"""Scale of the Cauchy cost of a log residual: 5 % (a real clear sky about the smooth model, clouds aside)."""
EFFECTIVE_SAMPLES_PER_SR = 20.0
"""Independent observations a steradian of sky is worth (the tempered likelihood's total weight is this times the
sky's solid angle: half the frame of a 60-degree view is about 0.45 sr, 9 observations; a sliver of sky says little)."""
MIN_EXPONENT, MAX_EXPONENT = 0.7, 1.4
"""Range of the photo's gamma-like exponent ``g`` (``I = a L^g``)."""
MIN_SKY_PIXELS = 256
"""Fewer sky pixels than this (inside the frame, above the horizon) read no sun."""
CLIP_LEVEL = 0.98
"""A display value at or above this is clipped: the pixel is at least this bright (a one-sided bound)."""
MAX_CLIPPED_SKY = 0.8
"""A sky more than this share of which is clipped in every channel reads no sun (blown out)."""
DARK_SKY_LEVEL = 0.03
"""A display photo whose sky's median luminance (display value) is below this reads no sun (night)."""
MAX_BLOCKS_PER_SIDE = 16
"""The sky is read in blocks of pixels, at most this many along the image's longer side."""
SEEN_RADIUS_DEG = 4.0
"""A sun in the frame is looked for within this angle of where a hypothesis puts it (the grid's cells are 4 x 5
degrees: the true sun lies within about 3.2 degrees of its cell's centre)."""
SEEN_QUANTILE = 0.999
"""A sun in the frame on open sky is the brightest thing in the sky, and in a display photo its disc is clipped: the
pixels within :data:`SEEN_RADIUS_DEG` of it reach at least this quantile of the sky's luminance (clipped pixels
count as brighter than any). Where none does, the sun is not there. A high quantile, not the maximum: a few stray
pixels (a lamp's flare or a star inside the sky mask) do not set the bar."""
MAX_UNSEEN_SHARE = 0.5
"""A sky whose fit puts more than this share of the sun's posterior in the frame where no sun is seen reads no sun
(kind ``"unseen"``): the model explains the sky only with a sun the photo does not show (a twilight glow after
sunset, a lit night sky, a haze the model does not hold)."""
MAX_FIT_COST = 2.5
"""A sky whose best hypothesis (sun or sunless) leaves a mean robust cost per block above this reads no sun (kind
``"unfit"``): ``log(1 + (r / LOG_SIGMA)^2)`` averaged over the sky is 2.5 at typical log residuals of about 17 %,
where real skies the model reads sit at 0.2-1.8 (study 65: training-side crops and the rooms)."""
SKY_KINDS = ("clear", "hazy", "overcast", "night", "blown out", "unseen", "unfit", "none")
"""What :attr:`SunPosterior.sky_kind` says of a sky: a sun with the MAP overcast mix 0 or above 0; no sun because
the sunless sky explains it best, it is too dark, too clipped, its fit puts the sun in the frame where none is seen,
no sky the model draws fits it, or there is too little of it."""
PREVIEW_SIZE = (128, 256)
"""``(H, W)`` of :func:`lighting_preview`'s lat-long image."""
_PART_CLIPPED = 1e300  # the seen check's brightness of a pixel clipped in some channels, not all (all: inf)
_SEEN_POOL = 256  # the seen check reads the image max-pooled to at most this many blocks along its longer side
_REFINE_HALF_DEG, _REFINE_STEP_DEG = 6.0, 1.0
_FLOOR = 1e-3  # linear values are floored here (relative to the sky's median) before the log
_IRLS_STEPS = 2


@functools.lru_cache(maxsize=1)
def _table() -> tuple[torch.Tensor, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    from safetensors.numpy import load_file

    t = load_file(str(SUNSKY_TURBIDITY_TABLE))
    return (torch.from_numpy(t["radiance"].astype(np.float32)), t["turbidities"], t["elevations_deg"],
            t["view_elevations_deg"], t["azimuths_deg"])


def _table_at_elevations(sun_elevations_deg: np.ndarray) -> torch.Tensor:
    """``(T, E, R, C, 3)`` the table linear in the sun's elevation at ``sun_elevations_deg (E,)``."""
    radiance, _, elevations, _, _ = _table()
    e = np.clip(sun_elevations_deg, elevations[0], elevations[-1])
    i = np.clip(np.searchsorted(elevations, e) - 1, 0, len(elevations) - 2)
    w = torch.from_numpy(((e - elevations[i]) / (elevations[i + 1] - elevations[i])).astype(np.float32))
    w = w[None, :, None, None, None]
    return (1 - w) * radiance[:, i] + w * radiance[:, i + 1]


def _lerp_index(x: torch.Tensor, nodes: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
    """Lower node index and weight of ``x`` on uniform ``nodes`` (clamped to their range)."""
    f = ((x - float(nodes[0])) / float(nodes[1] - nodes[0])).clamp(0, len(nodes) - 1)
    i0 = f.floor().long().clamp_max(len(nodes) - 2)
    return i0, f - i0


def _sky_at(tab: torch.Tensor, view_elev: torch.Tensor, rel_azimuth: torch.Tensor) -> torch.Tensor:
    """``(T, E, A, B, 3)`` table slices ``tab (T, E, R, C, 3)`` at blocks of view elevation ``view_elev (B,)``
    and azimuth from the sun ``rel_azimuth (A, B)`` (degrees, any sign: the sky is mirror-symmetric)."""
    _, _, _, rows, cols = _table()
    r0, wr = _lerp_index(view_elev, rows)
    # rows first: (T, E, B, C, 3)
    by_row = (1 - wr)[None, None, :, None, None] * tab[:, :, r0] + wr[None, None, :, None, None] * tab[:, :, r0 + 1]
    phi = torch.remainder(rel_azimuth + 180.0, 360.0) - 180.0
    c0, wc = _lerp_index(phi.abs(), cols)  # (A, B)
    b = torch.arange(by_row.shape[2])
    lo = by_row[:, :, b[None, :], c0]  # (T, E, A, B, 3)
    hi = by_row[:, :, b[None, :], c0 + 1]
    return (1 - wc)[None, None, ..., None] * lo + wc[None, None, ..., None] * hi


def _zenith_luminance(tab: torch.Tensor) -> torch.Tensor:
    """``(T, E)`` luminance of the tabulated sky at the zenith (its last row)."""
    return tab[:, :, -1, 0, :] @ torch.tensor(LUMINANCE, dtype=tab.dtype)


def hosek_wilkie_sky(d: Array, sun_direction: Array, turbidity: float) -> np.ndarray:
    """``(..., 3)`` Mitsuba 3's Hosek-Wilkie sky (no sun) along unit world directions ``d (..., 3)`` for a sun
    towards ``sun_direction (3,)`` at ``turbidity`` in [2, 6] (linear between the table's), in the units of
    :func:`physrelight.sky_model.sunsky_radiance` (the sun's irradiance has luminance 1). 0 below the horizon.

    Raises:
        ValueError: bad shapes, a zero sun, or a turbidity outside [2, 6].
    """
    d = np.asarray(d, dtype=np.float64)
    s = np.asarray(sun_direction, dtype=np.float64)
    if d.shape[-1:] != (3,) or s.shape != (3,) or not np.linalg.norm(s) > 0:
        raise ValueError(f"hosek_wilkie_sky takes directions (..., 3) and a non-zero sun (3,), got {d.shape}, {s.shape}")
    _, turbidities, _, _, _ = _table()
    if not (math.isfinite(turbidity) and turbidities[0] <= turbidity <= turbidities[-1]):
        raise ValueError(f"turbidity must lie in [{turbidities[0]:g}, {turbidities[-1]:g}], got {turbidity!r}")
    s = s / np.linalg.norm(s)
    e = math.degrees(math.asin(float(np.clip(s[1], -1, 1))))
    tab = _table_at_elevations(np.array([e]))  # (T, 1, R, C, 3)
    flat = d.reshape(-1, 3)
    beta = torch.from_numpy(np.degrees(np.arcsin(np.clip(flat[:, 1], 0, 1))).astype(np.float32))
    az = np.degrees(np.arctan2(flat[:, 0], -flat[:, 2])) - math.degrees(math.atan2(s[0], -s[2]))
    out = _sky_at(tab, beta, torch.from_numpy(az.astype(np.float32))[None])[:, 0, 0].double().numpy()  # (T, N, 3)
    k = int(np.clip(np.searchsorted(turbidities, turbidity) - 1, 0, len(turbidities) - 2))
    w = (turbidity - turbidities[k]) / (turbidities[k + 1] - turbidities[k])
    out = (1 - w) * out[k] + w * out[k + 1]
    return np.where(flat[:, 1:2] > 0, out, 0.0).reshape(d.shape)


@dataclass(frozen=True)
class SkyBlocks:
    """The sky pixels of a photo, in blocks (:func:`sky_blocks`).

    Attributes:
        directions: ``(B, 3)`` unit world directions (the mean of the block's sky rays).
        log_value: ``(B, 3)`` median log linear value of the block's unclipped sky pixels per channel (or the
            log of the clip level where the channel is a bound).
        clipped: ``(B, 3)`` bool: most of the block's sky pixels are clipped in that channel (a lower bound).
        weight: ``(B,)`` the block's share of the sky pixels (sums to 1).
        solid_angle: the sky's solid angle (sr), the pixels' own.
        sky_pixels: the number of sky pixels read.
    """

    directions: np.ndarray
    log_value: np.ndarray
    clipped: np.ndarray
    weight: np.ndarray
    sky_pixels: int
    solid_angle: float


def _block_median(idx: np.ndarray, v: np.ndarray, nb: int) -> np.ndarray:
    """``(nb,)`` the median of the values ``v (N,)`` in each block ``idx (N,)`` (0 where a block has none)."""
    order = np.lexsort((v, idx))
    vs = v[order]
    n = np.bincount(idx, minlength=nb)
    start = np.cumsum(n) - n
    lo = np.clip(start + (n - 1) // 2, 0, max(len(vs) - 1, 0))
    hi = np.clip(start + n // 2, 0, max(len(vs) - 1, 0))
    return np.where(n > 0, 0.5 * (vs[lo] + vs[hi]) if len(vs) else 0.0, 0.0)


def sky_blocks(linear: np.ndarray, clipped: np.ndarray, sky: np.ndarray, rays: np.ndarray,
               clip_value: float, pixel_sr: np.ndarray) -> SkyBlocks:
    """The sky pixels ``sky (H, W)`` of a linear image ``linear (H, W, 3)`` with clipped channels
    ``clipped (H, W, 3)`` and world rays ``rays (H, W, 3)``, in square blocks (at most
    :data:`MAX_BLOCKS_PER_SIDE` along the longer side); a block is kept when a quarter of it is sky.
    ``clip_value`` is the linear value of a clipped channel (its bound); ``pixel_sr (H, W)`` each pixel's solid angle."""
    h, w = sky.shape
    bs = max(1, math.ceil(max(h, w) / MAX_BLOCKS_PER_SIDE))
    nbw = math.ceil(w / bs)
    idx = ((np.arange(h) // bs)[:, None] * nbw + (np.arange(w) // bs)[None, :])[sky]
    nb = math.ceil(h / bs) * nbw
    count = np.bincount(idx, minlength=nb).astype(np.float64)
    size = np.bincount(((np.arange(h) // bs)[:, None] * nbw + (np.arange(w) // bs)[None, :]).ravel(), minlength=nb)
    keep = count >= 0.25 * size
    dsum = np.stack([np.bincount(idx, rays[sky][:, k], nb) for k in range(3)], -1)
    lin, clp = linear[sky], clipped[sky]
    # black pixels are floored at a thousandth of the sky's median (not its brightest: the sun's disc is 1e4 times it)
    typical = max(float(np.median(lin)), clip_value if clp.all() else 0.0, 1e-30)
    logv = np.log(np.maximum(lin, _FLOOR * typical))
    unclipped = np.stack([np.bincount(idx, ~clp[:, k], nb) for k in range(3)], -1)
    is_clipped = unclipped < 0.5 * count[:, None]
    # the median, not the mean: the sun's disc or a cloud's edge inside a block does not move it
    med = np.stack([_block_median(idx[~clp[:, k]], logv[~clp[:, k], k], nb) for k in range(3)], -1)
    mean_log = np.where(is_clipped, math.log(max(clip_value, 1e-30)), med)
    d = dsum[keep]
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
    return SkyBlocks(directions=d, log_value=mean_log[keep], clipped=is_clipped[keep],
                     weight=count[keep] / max(count[keep].sum(), 1.0), sky_pixels=int(sky.sum()),
                     solid_angle=float(pixel_sr[sky].sum()))


def unseen_in_frame(directions: np.ndarray, brightness: np.ndarray, sky: np.ndarray, K: np.ndarray,
                    world_to_camera: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: which world directions ``(N, 3)`` a sun cannot take because the photo would show it there.

    A direction is ruled out when it projects inside the frame, at least a quarter of the pixels within
    :data:`SEEN_RADIUS_DEG` of it are sky (open sky: a sun behind a building or a tree is not ruled out), and none
    of the sky pixels there is as bright as the sky's :data:`SEEN_QUANTILE` quantile. A pixel clipped in every channel
    counts as seen, sky or not (a sun's disc the sky mask left out); a lit wall does not.

    Args:
        directions: ``(N, 3)`` unit world directions.
        brightness: ``(H, W)`` the photo's luminance; ``inf`` where every channel is clipped, above any luminance
            (1e300) where some are: a sun in view is clipped in every channel where the sky is in some.
        sky: ``(H, W)`` bool, the sky pixels read.
        K: ``(3, 3)`` intrinsics; world_to_camera: ``(3, 3)`` rotation.

    The image is max-pooled to at most :data:`_SEEN_POOL` blocks along its longer side first (a block is sky when
    half of it is).
    """
    return _seen_check(brightness, sky, K, world_to_camera)(directions)


def _seen_check(brightness: np.ndarray, sky: np.ndarray, K: np.ndarray,
                world_to_camera: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """:func:`unseen_in_frame` for one photo as a function of the directions ``(N, 3)`` alone: the sky's threshold,
    the pooled image and its rays are made once, for every set of directions asked about (the grid, then the MAP's
    refinement)."""
    h, w = sky.shape
    if not sky.any():
        return lambda directions: np.zeros(len(np.asarray(directions).reshape(-1, 3)), dtype=bool)
    # clipped (inf) pixels as the largest float, so the quantile's interpolation stays finite
    threshold = float(np.quantile(np.minimum(brightness[sky], np.finfo(np.float64).max), SEEN_QUANTILE))
    b = max(1, math.ceil(max(h, w) / _SEEN_POOL))
    hp, wp = math.ceil(h / b), math.ceil(w / b)
    lum = np.full((hp * b, wp * b), -np.inf)
    # the sky's pixels, and any clipped one (a sun's disc the sky mask left out); not a lit wall's
    lum[:h, :w] = np.where(sky | np.isposinf(brightness), brightness, -np.inf)
    share = np.zeros((hp * b, wp * b))
    share[:h, :w] = sky
    pooled = lum.reshape(hp, b, wp, b).max((1, 3)).ravel()
    is_sky = (share.reshape(hp, b, wp, b).mean((1, 3)) >= 0.5).ravel()
    Kp = np.array(K, dtype=np.float64)
    Kp[:2] /= b  # block centres: the pixel-centre convention scales with the block
    rays = camera_rays(Kp, world_to_camera, hp, wp).numpy()[:, :, 0].reshape(-1, 3)
    cos_r = math.cos(math.radians(SEEN_RADIUS_DEG))
    K_t = torch.from_numpy(np.asarray(K, dtype=np.float64))

    def unseen(directions: np.ndarray) -> np.ndarray:
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(len(d), dtype=bool)
        if len(d) == 0:
            return out
        uv, depth = project(torch.from_numpy((world_to_camera @ d.T)[None]), K_t)
        u, v, z = uv[0, 0].numpy(), uv[0, 1].numpy(), depth[0, 0].numpy()
        inside = np.flatnonzero((z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h))
        for start in range(0, len(inside), 64):
            idx = inside[start:start + 64]
            near = (rays @ d[idx].T) > cos_r  # (P, n)
            n_sky = (near & is_sky[:, None]).sum(0)
            brightest = np.minimum(np.where(near, pooled[:, None], -np.inf).max(0), np.finfo(np.float64).max)
            out[idx] = (n_sky > 0) & (n_sky >= 0.25 * near.sum(0)) & (brightest < threshold)
        return out

    return unseen


@dataclass(frozen=True)
class SunPosterior:
    """Where the sun is, read from the sky (:func:`estimate_sun_from_sky`).

    Attributes:
        azimuths_deg: ``(A,)`` the grid's world azimuths (:func:`physrelight.envmap.direction_from_angles`).
        elevations_deg: ``(E,)`` the grid's sun elevations.
        posterior: ``(E, A)`` posterior probability of each cell (sums to 1; flat prior over solid angle
            where there is nothing to read).
        has_sun: whether the sky shows a sun: enough sky, not night, and the sunless hypothesis (``m = 1``)
            holds less than half the posterior.
        reason: why there is no sun (empty when ``has_sun``).
        sun_probability: posterior mass of the hypotheses with a sun (``m < 1``); 0 when nothing was read.
        sun_direction: ``(3,)`` MAP unit world direction towards the sun (Y up), refined to 1 degree; None
            without a sun.
        elevation_deg, azimuth_deg: the MAP sun in ``relight --sun``'s convention (azimuth clockwise from
            straight ahead of the camera); None without a sun.
        world_azimuth_deg: the MAP sun's world azimuth; None without a sun.
        azimuth_std_deg: circular standard deviation of the azimuth marginal (degrees; it grows without bound as
            the marginal flattens: capped at 360).
        elevation_std_deg: standard deviation of the elevation marginal (degrees).
        credible_area_sr: solid angle of the smallest set of cells holding 90 % of the posterior.
        turbidity, mix: the MAP turbidity and overcast mix ``m``.
        level: ``(3,)`` the MAP's per-channel level ``a_c`` (photo linear units per unit of the model sky).
        exponent: the MAP's gamma-like exponent ``g``.
        camera_yaw_deg: the camera's heading (world azimuth of its forward direction).
        sky_kind: what the sky is (:data:`SKY_KINDS`): ``"clear"`` (a sun, MAP mix 0), ``"hazy"`` (a sun, MAP mix
            above 0), ``"overcast"``, ``"night"``, ``"blown out"``, ``"unseen"`` (the fit's sun in the frame, where
            the photo shows none: :data:`MAX_UNSEEN_SHARE`), ``"unfit"`` (no hypothesis fits the pixels:
            :data:`MAX_FIT_COST`), ``"none"`` (too little sky to read).
        cues: the cues that spoke (:func:`physrelight.sun_estimate.estimate_sun`: ``"sky"``, ``"shadows"``,
            ``"shading"``); empty from :func:`estimate_sun_from_sky` alone.

    Where the sun was read from shadows or shading while the sky showed none, the sky's fit (``turbidity``,
    ``mix``, ``level``, ``exponent``) is None: :meth:`radiance`, :meth:`sun_irradiance`, :meth:`envmap` and
    :meth:`sh` refuse (there is no sky to draw), and :func:`lighting_preview` draws the SH it is given.
    """

    azimuths_deg: np.ndarray
    elevations_deg: np.ndarray
    posterior: np.ndarray
    has_sun: bool
    reason: str
    sun_probability: float
    sun_direction: np.ndarray | None
    elevation_deg: float | None
    azimuth_deg: float | None
    world_azimuth_deg: float | None
    azimuth_std_deg: float
    elevation_std_deg: float
    credible_area_sr: float
    turbidity: float | None
    mix: float | None
    level: np.ndarray | None
    exponent: float | None
    camera_yaw_deg: float
    sky_kind: str = "clear"
    _cell_sr: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    cues: tuple[str, ...] = ()

    def azimuth_marginal(self) -> np.ndarray:
        """``(A,)`` the posterior summed over elevation."""
        return self.posterior.sum(0)

    def credible_region(self, level: float = 0.9) -> np.ndarray:
        """``(E, A)`` bool: the smallest set of cells (highest posterior density per solid angle first) holding
        ``level`` of the posterior."""
        if not 0.0 < level <= 1.0:
            raise ValueError(f"level must lie in (0, 1], got {level!r}")
        density = (self.posterior / self._cell_sr).ravel()
        order = np.argsort(-density, kind="stable")
        cum = np.cumsum(self.posterior.ravel()[order])
        n = int(np.searchsorted(cum, level * cum[-1] - 1e-12)) + 1
        out = np.zeros(density.size, dtype=bool)
        out[order[:n]] = True
        return out.reshape(self.posterior.shape)

    def covers(self, direction: Array, level: float = 0.9) -> bool:
        """Whether the cell holding the unit world ``direction (3,)`` is in the ``level`` credible region."""
        d = np.asarray(direction, dtype=np.float64)
        if d.shape != (3,) or not np.linalg.norm(d) > 0:
            raise ValueError(f"direction must be a non-zero (3,) vector, got shape {d.shape}")
        d = d / np.linalg.norm(d)
        e = math.degrees(math.asin(float(np.clip(d[1], -1, 1))))
        a = math.degrees(math.atan2(d[0], -d[2])) % 360.0
        i = int(np.argmin(np.abs(self.elevations_deg - e)))
        j = int(np.argmin(np.abs((self.azimuths_deg - a + 180.0) % 360.0 - 180.0)))
        return bool(self.credible_region(level)[i, j])

    def radiance(self, d: Array) -> np.ndarray:
        """``(..., 3)`` the MAP sky (no sun disc) along unit world directions ``d (..., 3)``, in the photo's linear
        units taking ``g = 1`` (``a_c L_c``); 0 below the horizon.

        Raises:
            ValueError: there is no sun (nothing to draw).
        """
        if not self.has_sun:
            raise ValueError(f"no sun was read from this sky ({self.reason}): there is no MAP sky to draw")
        if self.level is None:
            raise ValueError("the sun was read from shadows or shading, not from the sky: there is no MAP sky to draw")
        d = np.asarray(d, dtype=np.float64)
        hw = hosek_wilkie_sky(d, self.sun_direction, self.turbidity)
        z = float(hosek_wilkie_sky(np.array([0.0, 1.0, 0.0]), self.sun_direction, self.turbidity) @ np.array(LUMINANCE))
        model = (1 - self.mix) * hw / z + self.mix * overcast_sky(d)[..., None]
        return model * self.level

    def sun_irradiance(self) -> np.ndarray:
        """``(3,)`` the MAP sun's irradiance on a surface facing it, in :meth:`radiance`'s units: the table's sun
        (luminance 1 against its sky) coloured by :func:`physrelight.sky_model.sun_colour`, times the sky's share
        ``(1 - m) / Z`` and the level."""
        if not self.has_sun:
            raise ValueError(f"no sun was read from this sky ({self.reason})")
        if self.level is None:
            raise ValueError("the sun was read from shadows or shading, not from the sky: its irradiance is unknown")
        z = float(hosek_wilkie_sky(np.array([0.0, 1.0, 0.0]), self.sun_direction, self.turbidity) @ np.array(LUMINANCE))
        return (1 - self.mix) / z * sun_colour(self.elevation_deg) * self.level

    def envmap(self, height: int = 64) -> np.ndarray:
        """``(height, 2 height, 3)`` float32 lat-long map (DESIGN.md layout) of the MAP sky (:meth:`radiance`;
        the sun is not drawn: see :meth:`sh`); black below the horizon (no ground)."""
        from physrelight.envmap import directions

        if not (isinstance(height, int) and height >= 4):
            raise ValueError(f"height must be an integer >= 4, got {height!r}")
        return self.radiance(directions(height, 2 * height)).astype(np.float32)

    def summary(self) -> dict:
        """The posterior as plain JSON values: ``sun`` (``{"azimuth_deg", "elevation_deg"}`` in ``relight --sun``'s
        convention, or None), ``sun_spread`` (``azimuth_std_deg``, ``elevation_std_deg``, ``credible_area_sr`` of the
        90 % region, ``credible_level``), ``sun_probability``, ``sky_kind``, ``turbidity``, ``mix``, ``level``
        (``[r, g, b]`` or None), ``exponent``, ``reason`` (empty with a sun)."""
        sun = None if not self.has_sun else {"azimuth_deg": round(float(self.azimuth_deg), 3),
                                              "elevation_deg": round(float(self.elevation_deg), 3)}
        return {"sun": sun,
                "sun_spread": {"azimuth_std_deg": round(float(self.azimuth_std_deg), 3),
                               "elevation_std_deg": round(float(self.elevation_std_deg), 3),
                               "credible_area_sr": round(float(self.credible_area_sr), 4), "credible_level": 0.9},
                "sun_probability": round(float(self.sun_probability), 4), "sky_kind": self.sky_kind,
                "turbidity": None if self.turbidity is None else float(self.turbidity),
                "mix": None if self.mix is None else float(self.mix),
                "level": None if self.level is None else [float(x) for x in self.level],
                "exponent": None if self.exponent is None else round(float(self.exponent), 4),
                "reason": self.reason}

    def sh(self) -> np.ndarray:
        """``(9, 3)`` order-2 radiance SH (world frame) of the MAP: the sky's map projected
        (:func:`physrelight.sh.project_envmap`) plus the sun as a delta (:func:`physrelight.sh.project_sun`)."""
        sky = np.asarray(sh.project_envmap(self.envmap(64).astype(np.float64), order=2))
        return sky + np.asarray(sh.project_sun(self.sun_direction, self.sun_irradiance(), order=2))


def _camera(K: Array | None, world_to_camera: Array | None, pitch_deg: float | None, fov_deg: float | None,
            height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    if (K is None) != (world_to_camera is None):
        raise ValueError("give K and world_to_camera together, or pitch_deg and fov_deg")
    if K is None:
        if pitch_deg is None or fov_deg is None:
            raise ValueError("the camera is needed: give K and world_to_camera, or pitch_deg and fov_deg")
        if not (isinstance(pitch_deg, (int, float)) and math.isfinite(pitch_deg) and -90 < pitch_deg < 90):
            raise ValueError(f"pitch_deg must be a number in (-90, 90), got {pitch_deg!r}")
        if not isinstance(fov_deg, (int, float)):
            raise ValueError(f"fov_deg must be a number of degrees, got {fov_deg!r}")
        return view_intrinsics(float(fov_deg), width, height), level_camera(0.0, float(pitch_deg))[:3, :3]
    if pitch_deg is not None or fov_deg is not None:
        raise ValueError("give K and world_to_camera, or pitch_deg and fov_deg, not both")
    K = np.asarray(K.detach().cpu() if isinstance(K, torch.Tensor) else K, dtype=np.float64)
    R = np.asarray(world_to_camera.detach().cpu() if isinstance(world_to_camera, torch.Tensor) else world_to_camera,
                   dtype=np.float64)
    if K.shape != (3, 3):
        raise ValueError(f"K must have shape (3, 3), got {K.shape}")
    if R.shape == (4, 4):
        R = R[:3, :3]
    if R.shape != (3, 3):
        raise ValueError(f"world_to_camera must have shape (3, 3) or (4, 4), got {R.shape}")
    return K, R


def _cell_solid_angles(elevations: np.ndarray, n_az: int) -> np.ndarray:
    """``(E, A)`` solid angle of each grid cell (elevation bands between midpoints, 2 and 90 at the ends)."""
    edges = np.radians(np.concatenate([[elevations[0]], (elevations[1:] + elevations[:-1]) / 2, [90.0]]))
    band = np.sin(edges[1:]) - np.sin(edges[:-1])
    return np.repeat((band * 2 * math.pi / n_az)[:, None], n_az, 1)


def _fit(blocks: SkyBlocks, tab: torch.Tensor, sun_elev: np.ndarray, sun_az: np.ndarray
         ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Fit level and exponent for every hypothesis: sun elevations ``(E,)`` x azimuths ``(A,)`` x turbidities x
    the mixes below 1. Returns the log-likelihoods ``(T, M, E, A)`` and the MAP's fitted ``a (T, M, E, A, 3)``
    (log), ``g (T, M, E, A)``, plus the sunless ``m = 1`` log-likelihood (scalar)."""
    d = torch.from_numpy(blocks.directions.astype(np.float32))
    view_elev = torch.rad2deg(torch.asin(d[:, 1].clamp(0, 1)))
    view_az = torch.rad2deg(torch.atan2(d[:, 0], -d[:, 2]))
    rel = view_az[None, :] - torch.from_numpy(sun_az.astype(np.float32))[:, None]  # (A, B)
    hw = _sky_at(tab, view_elev, rel)  # (T, E, A, B, 3)
    z = _zenith_luminance(tab)[:, :, None, None, None]
    ovc = torch.from_numpy(overcast_sky(blocks.directions.clip(-1, 1)).astype(np.float32))
    # a block just below the horizon (a mask or pitch a little off) reads the sky just above it
    ovc = ovc.clamp_min(1.0 / 3.0)[:, None]  # (B, 1)
    mixes = torch.tensor([m for m in MIXES if m < 1.0])
    hwn = (hw / z).clamp_min(1e-6)
    mb = mixes[None, :, None, None, None, None]
    x = torch.log((1 - mb) * hwn[:, None] + mb * ovc)  # (T, M, E, A, B, 3)
    ll, a, g = _irls(x, blocks)
    ll_overcast, _, _ = _irls(torch.log(ovc.expand(-1, 3))[None], blocks)
    return ll, a, g, ll_overcast[0]


def _irls(x: torch.Tensor, blocks: SkyBlocks) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Robust fit of ``y = g x + a_c`` for model logs ``x (..., B, 3)`` against the blocks' logs: iteratively
    reweighted least squares of the Cauchy cost, clipped channels one-sided. Returns the tempered
    log-likelihood ``(...)``, ``a (..., 3)`` and ``g (...)``."""
    y = torch.from_numpy(blocks.log_value.astype(np.float32))
    clipped = torch.from_numpy(blocks.clipped)
    wb = torch.from_numpy(blocks.weight.astype(np.float32))[:, None].expand(-1, 3)
    omega = torch.where(clipped, torch.zeros_like(wb), wb).expand(x.shape)
    inv_var = 1.0 / LOG_SIGMA ** 2
    for step in range(_IRLS_STEPS + 1):
        ox = omega * x
        s = omega.sum(-2).clamp_min(1e-12)  # (..., 3)
        sx = ox.sum(-2)
        sy = torch.einsum("...bc,bc->...c", omega, y)  # contractions: no (..., B, 3) temporaries
        sxx = (ox * x).sum(-2)
        sxy = torch.einsum("...bc,bc->...c", ox, y)
        del ox
        num = (sxy - sx * sy / s).sum(-1)
        den = (sxx - sx * sx / s).sum(-1).clamp_min(1e-12)
        g = (num / den).clamp(MIN_EXPONENT, MAX_EXPONENT)
        a = (sy - g[..., None] * sx) / s
        r = x * (-g[..., None, None])
        r.add_(y).sub_(a[..., None, :])
        # a clipped channel is a bound: only a model darker than it (r > 0) costs or pulls
        satisfied = clipped & (r < 0) if clipped.any() else None
        if satisfied is not None:
            r.masked_fill_(satisfied, 0.0)
        u = r.square_().mul_(inv_var)
        if step < _IRLS_STEPS:
            omega = (1.0 + u).reciprocal_().mul_(wb)
            if satisfied is not None:
                omega.masked_fill_(satisfied, 0.0)
    cost = (u.log1p_() * wb).sum((-2, -1)) / 3.0
    return -EFFECTIVE_SAMPLES_PER_SR * blocks.solid_angle * cost, a, g


def _no_sun(reason: str, yaw: float, kind: str, sun_probability: float = 0.0,
            posterior: np.ndarray | None = None) -> SunPosterior:
    el = np.array(ELEVATIONS_DEG)
    az = np.arange(0.0, 360.0, AZIMUTH_STEP_DEG)
    cell = _cell_solid_angles(el, len(az))
    post = cell / cell.sum() if posterior is None else posterior
    out = SunPosterior(azimuths_deg=az, elevations_deg=el, posterior=post, has_sun=False, reason=reason,
                       sun_probability=sun_probability, sun_direction=None, elevation_deg=None, azimuth_deg=None,
                       world_azimuth_deg=None, azimuth_std_deg=0.0, elevation_std_deg=0.0, credible_area_sr=0.0,
                       turbidity=None, mix=None, level=None, exponent=None, camera_yaw_deg=yaw, sky_kind=kind,
                       _cell_sr=cell)
    return _with_spread(out)


def _with_spread(p: SunPosterior) -> SunPosterior:
    m = p.azimuth_marginal()
    ang = np.radians(p.azimuths_deg)
    R = min(1.0, float(np.hypot((m * np.cos(ang)).sum(), (m * np.sin(ang)).sum())))
    circ = math.degrees(math.sqrt(-2.0 * math.log(max(R, 1e-12))))
    me = p.posterior.sum(1)
    mean_e = float((me * p.elevations_deg).sum())
    std_e = float(math.sqrt(max(0.0, (me * (p.elevations_deg - mean_e) ** 2).sum())))
    area = float((p.credible_region(0.9) * p._cell_sr).sum())
    object.__setattr__(p, "azimuth_std_deg", min(circ, 360.0))
    object.__setattr__(p, "elevation_std_deg", std_e)
    object.__setattr__(p, "credible_area_sr", area)
    return p


def estimate_sun_from_sky(image: Array, sky_mask: Array, K: Array | None = None, world_to_camera: Array | None = None,
                          *, pitch_deg: float | None = None, fov_deg: float | None = None, linear: bool = False,
                          clip_level: float | None = None) -> SunPosterior:
    """The sun's position read from the sky pixels of a photo, as a posterior (see the module doc).

    Args:
        image: ``(H, W, 3)`` the photo: display values in [0, 1] (sRGB-encoded; the default) or, with
            ``linear=True``, linear radiance (any non-negative scale).
        sky_mask: ``(H, W)`` bool, True on sky pixels.
        K: ``(3, 3)`` intrinsics (:mod:`physrelight.camera`), with ``world_to_camera`` ``(3, 3)`` or ``(4, 4)``
            (rotation used); or neither, and ``pitch_deg`` (up positive) with ``fov_deg`` (horizontal), the
            camera ``relight`` assumes (heading world -Z, level).
        linear: the image is linear radiance rather than display values.
        clip_level: values at or above it (in the image's own units) are clipped: read as bounds. None (the
            default): :data:`CLIP_LEVEL` for a display image, nothing clipped for a linear one.

    Returns:
        :class:`SunPosterior`. ``has_sun`` is False, with a reason, when fewer than :data:`MIN_SKY_PIXELS` sky
        pixels lie above the horizon, when a display photo's sky is darker than :data:`DARK_SKY_LEVEL` (night),
        when more than :data:`MAX_CLIPPED_SKY` of it is clipped in every channel, when no hypothesis fits the
        pixels (:data:`MAX_FIT_COST`; kind ``"unfit"``), when the sunless sky explains the pixels best (then the
        posterior is flat or nearly so), or when more than :data:`MAX_UNSEEN_SHARE` of the sun's posterior lies in
        the frame where the photo shows no sun (:func:`unseen_in_frame`; kind ``"unseen"``). Below that share those
        cells are ruled out.

    Raises:
        ValueError: shapes, non-finite or negative values, a mask that is not boolean, a bad camera.
    """
    img = np.asarray(image.detach().cpu() if isinstance(image, torch.Tensor) else image, dtype=np.float64)
    mask = np.asarray(sky_mask.detach().cpu() if isinstance(sky_mask, torch.Tensor) else sky_mask)
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"image must have shape (H, W, 3), got {img.shape}")
    if mask.shape != img.shape[:2]:
        raise ValueError(f"sky_mask must have the image's shape (H, W) = {img.shape[:2]}, got {mask.shape}")
    if mask.dtype != bool:
        raise ValueError(f"sky_mask must be boolean, got dtype {mask.dtype}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image must be finite")
    if img.min(initial=0.0) < 0:
        raise ValueError(f"image must be non-negative, got a minimum of {img.min():g}")
    if clip_level is not None and not (isinstance(clip_level, (int, float)) and clip_level > 0):
        raise ValueError(f"clip_level must be a positive number or None, got {clip_level!r}")
    h, w = mask.shape
    Kc, R = _camera(K, world_to_camera, pitch_deg, fov_deg, h, w)
    rays = camera_rays(Kc, R, h, w).numpy()[:, :, 0]  # validates K and the rotation
    fwd = R.T @ np.array([0.0, 0.0, -1.0])
    yaw = math.degrees(math.atan2(fwd[0], -fwd[2])) if np.hypot(fwd[0], fwd[2]) > 1e-9 else 0.0

    sky = mask & (rays[..., 1] > -0.05)  # a little below the horizon is kept (a pitch a little off)
    if int(sky.sum()) < MIN_SKY_PIXELS:
        return _no_sun(f"too few sky pixels: {int(sky.sum())} < {MIN_SKY_PIXELS}", yaw, "none")
    if clip_level is None and not linear:
        clip_level = CLIP_LEVEL
    if linear:
        lin = img
        clipped = img >= clip_level if clip_level is not None else np.zeros(img.shape, bool)
        clip_value = float(clip_level) if clip_level is not None else 0.0
    else:
        if img.max() > 1.0 + 1e-6:
            raise ValueError(f"a display image holds values in [0, 1], got a maximum of {img.max():g} "
                             "(pass linear=True for radiance)")
        luminance = img[sky] @ np.array(LUMINANCE)
        if float(np.median(luminance)) < DARK_SKY_LEVEL:
            return _no_sun(f"the sky is too dark to read (median display luminance {float(np.median(luminance)):.3f}"
                           f" < {DARK_SKY_LEVEL})", yaw, "night")
        lin = np.asarray(srgb_to_linear(img))
        clipped = img >= clip_level if clip_level is not None else np.zeros(img.shape, bool)
        clip_value = float(srgb_to_linear(np.array(clip_level))) if clip_level is not None else 0.0
    # a pinhole pixel's solid angle: cos^3 of its angle off the axis over fx fy
    pixel_sr = np.clip(rays @ fwd, 0, 1) ** 3 / abs(float(Kc[0, 0] * Kc[1, 1]))
    blocks = sky_blocks(lin, clipped, sky, rays, clip_value, pixel_sr)
    if len(blocks.weight) < 4:
        return _no_sun(f"the sky covers too few blocks to read ({len(blocks.weight)} < 4)", yaw, "none")
    blown = float(blocks.weight[blocks.clipped.all(-1)].sum())
    if blown > MAX_CLIPPED_SKY:
        # bounds alone do not shape a sky: every bright enough model satisfies them
        return _no_sun(f"the sky is blown out ({blown:.0%} of it clipped in every channel > {MAX_CLIPPED_SKY:.0%})",
                       yaw, "blown out")

    el = np.array(ELEVATIONS_DEG)
    az = np.arange(0.0, 360.0, AZIMUTH_STEP_DEG)
    cell = _cell_solid_angles(el, len(az))
    prior = np.log(cell / cell.sum())
    _, turbidities, _, _, _ = _table()
    with torch.no_grad():
        ll, a, g, ll_ovc = _fit(blocks, _table_at_elevations(el), el, az)  # (T, M, E, A)
    ll = ll.double().numpy()
    # the best hypothesis's mean robust cost per unit of sky: a sky the model cannot draw is not read
    fit_cost = -max(float(ll.max()), float(ll_ovc)) / (EFFECTIVE_SAMPLES_PER_SR * blocks.solid_angle)
    if fit_cost > MAX_FIT_COST:
        return _no_sun(f"the sky model does not fit these sky pixels (mean robust cost {fit_cost:.2f} > "
                       f"{MAX_FIT_COST}: typical residuals over 20 %): not a sky it can draw (a wall, a ceiling, a "
                       "lamp, broken cloud)", yaw, "unfit")
    n_mix = len(MIXES)
    # joint log posterior: the sun's cell prior, uniform turbidity and mix (the sunless m = 1 one of the mixes)
    log_mix_prior = -math.log(n_mix) - math.log(len(turbidities))
    joint = ll + prior[None, None] + log_mix_prior
    top = max(float(joint.max()), float(ll_ovc) - math.log(n_mix))
    sun_mass = np.exp(joint - top)  # (T, M, E, A)
    ovc_mass = math.exp(float(ll_ovc) - math.log(n_mix) - top)  # spread over the cells by their prior
    post = sun_mass.sum((0, 1)) + ovc_mass * np.exp(prior)
    total = float(post.sum())
    post = post / total
    p_sun = float(sun_mass.sum()) / total

    if p_sun < 0.5:
        out = _no_sun(f"the sunless (overcast) sky explains the sky best (sun probability {p_sun:.2f})", yaw,
                      "overcast", p_sun, post)
        return out
    # a sun in the frame on open sky would be seen there: the cells where it is not are ruled out
    # clipped pixels rank above every unclipped one, and those clipped in every channel above those clipped in some
    bright = np.where(clipped.all(-1), np.inf, np.where(clipped.any(-1), _PART_CLIPPED, lin @ np.array(LUMINANCE)))
    unseen_at = _seen_check(bright, sky, Kc, R)
    unseen = unseen_at(direction_from_angles(el[:, None], az[None, :]).reshape(-1, 3)).reshape(len(el), len(az))
    if unseen.any():
        unseen_share = float(sun_mass[..., unseen].sum() / sun_mass.sum())
        if unseen_share > MAX_UNSEEN_SHARE:
            ie, ia = np.unravel_index(int(np.argmax(np.where(unseen, sun_mass.sum((0, 1)), -1.0))), unseen.shape)
            ahead = (float(az[ia]) - yaw + 180.0) % 360.0 - 180.0
            return _no_sun(f"the sky's fit puts the sun in the frame ({el[ie]:.0f} deg up, {ahead:.0f} deg from "
                           f"straight ahead; {unseen_share:.0%} of its posterior) where the photo shows none: a glow "
                           "after sunset, a lit night sky or a haze the sky model does not hold", yaw, "unseen",
                           p_sun * (1.0 - unseen_share))  # the fit is not trusted: the flat prior
        joint = np.where(unseen[None, None], -np.inf, joint)
        sun_mass = np.where(unseen[None, None], 0.0, sun_mass)
        post = sun_mass.sum((0, 1)) + ovc_mass * np.exp(prior)
        total = float(post.sum())
        post = post / total
        p_sun = float(sun_mass.sum()) / total
        if p_sun < 0.5:
            return _no_sun(f"the sunless (overcast) sky explains the sky best once the suns the photo would show "
                           f"are ruled out (sun probability {p_sun:.2f})", yaw, "overcast", p_sun, post)

    i_t, i_m, i_e, i_a = np.unravel_index(int(np.argmax(joint)), joint.shape)
    # refine the MAP on a 1-degree grid round it, turbidity and mix searched again
    fe = np.clip(el[i_e] + np.arange(-_REFINE_HALF_DEG, _REFINE_HALF_DEG + 1e-9, _REFINE_STEP_DEG), 2.0, 90.0)
    fa = az[i_a] + np.arange(-_REFINE_HALF_DEG, _REFINE_HALF_DEG + 1e-9, _REFINE_STEP_DEG)
    fe = np.unique(fe)
    with torch.no_grad():
        fll, fit_a, fg, _ = _fit(blocks, _table_at_elevations(fe), fe, fa)
    fjoint = fll.double().numpy() + np.log(np.cos(np.radians(fe)))[None, None, :, None]
    if unseen.any():  # the MAP cell's centre is among the fine hypotheses and is not ruled out
        fine = direction_from_angles(fe[:, None], fa[None, :]).reshape(-1, 3)
        fine_unseen = unseen_at(fine).reshape(len(fe), len(fa))
        fjoint = np.where(fine_unseen[None, None], -np.inf, fjoint)
    j_t, j_m, j_e, j_a = np.unravel_index(int(np.argmax(fjoint)), fjoint.shape)
    e_map, a_map = float(fe[j_e]), float(fa[j_a]) % 360.0
    mixes = [m for m in MIXES if m < 1.0]
    out = SunPosterior(azimuths_deg=az, elevations_deg=el, posterior=post, has_sun=True, reason="",
                       sun_probability=p_sun, sun_direction=direction_from_angles(e_map, a_map),
                       elevation_deg=e_map, azimuth_deg=(a_map - yaw + 180.0) % 360.0 - 180.0,
                       world_azimuth_deg=a_map, azimuth_std_deg=0.0, elevation_std_deg=0.0, credible_area_sr=0.0,
                       turbidity=float(turbidities[j_t]), mix=float(mixes[j_m]),
                       level=np.exp(fit_a[j_t, j_m, j_e, j_a].double().numpy()), exponent=float(fg[j_t, j_m, j_e, j_a]),
                       camera_yaw_deg=yaw, sky_kind="clear" if mixes[j_m] == 0.0 else "hazy", _cell_sr=cell)
    return _with_spread(out)


def _latlong_pixel(d: np.ndarray, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Column and row (float) of unit world directions ``d (..., 3)`` in :func:`lighting_preview`'s picture."""
    u = np.mod(np.arctan2(d[..., 0], -d[..., 2]) / (2 * math.pi) + 0.5, 1.0)  # straight ahead in the middle
    v = np.arccos(np.clip(d[..., 1], -1.0, 1.0)) / math.pi
    return u * width - 0.5, v * (height - 1)


def lighting_preview(sh_world: Array, posterior: SunPosterior | None = None, K: Array | None = None,
                     world_to_camera: Array | None = None, image_size: tuple[int, int] | None = None) -> np.ndarray:
    """``(128, 256, 3)`` uint8 lat-long picture of an estimated lighting (:data:`PREVIEW_SIZE`), for a person to look
    at: DESIGN.md's layout turned half a turn so that world -Z (straight ahead of ``relight``'s camera) is the middle
    column and the azimuth grows to the right as ``relight --sun``'s does (the edges are behind the camera).

    With a ``posterior`` that has a sun: its MAP sky (:meth:`SunPosterior.envmap`) above the horizon, flat dark grey
    below it (the sky says nothing of the ground), the 90 % credible region outlined in cyan and the MAP sun as a red
    ring. Without: the order-2 radiance SH ``sh_world (9, 3)`` (world frame) everywhere, clamped at 0. Either way the
    frame of the camera (``K (3, 3)``, ``world_to_camera (3, 3)`` or ``(4, 4)``, ``image_size (H, W)``, when given)
    is drawn in yellow. Tone-mapped: the 99th percentile luminance to 0.8, then the sRGB curve.
    """
    from PIL import Image, ImageDraw
    from scipy import ndimage

    from physrelight.colour import linear_to_srgb
    from physrelight.envmap import directions

    c = np.asarray(sh_world.detach().cpu() if isinstance(sh_world, torch.Tensor) else sh_world, dtype=np.float64)
    if c.shape != (9, 3) or not np.all(np.isfinite(c)):
        raise ValueError(f"sh_world must be finite order-2 SH of shape (9, 3), got {c.shape}")
    h, w = PREVIEW_SIZE
    d = directions(h, w).astype(np.float64)
    d = np.roll(d, w // 2, axis=1)  # straight ahead in the middle
    with_sun = posterior is not None and posterior.has_sun and posterior.level is not None
    above = d[..., 1] > 0
    radiance = posterior.radiance(d) if with_sun else np.clip(np.asarray(sh.basis(d, order=2)) @ c, 0.0, None)
    lum = radiance @ np.array(LUMINANCE)
    white = float(np.percentile(lum[above] if with_sun else lum, 99.0))
    scale = 0.8 / white if white > 0 else 1.0
    img = np.asarray(linear_to_srgb(np.clip(radiance * scale, 0.0, 1.0)))
    if with_sun:
        img = np.where(above[..., None], img, 0.2)
    canvas = Image.fromarray(np.round(img * 255).astype(np.uint8))
    draw = ImageDraw.Draw(canvas)
    if K is not None and world_to_camera is not None and image_size is not None:
        R = np.asarray(world_to_camera, dtype=np.float64)[:3, :3]
        ih, iw = image_size
        rays = camera_rays(np.asarray(K, dtype=np.float64), R, ih, iw).numpy()[:, :, 0]
        border = np.concatenate([rays[0], rays[-1], rays[:, 0], rays[:, -1]])
        x, y = _latlong_pixel(border, h, w)
        for xi, yi in zip(np.round(x).astype(int) % w, np.clip(np.round(y).astype(int), 0, h - 1)):
            canvas.putpixel((int(xi), int(yi)), (255, 220, 0))
    if with_sun:
        # the credible region's cells, looked up per texel: its outline
        el, az = posterior.elevations_deg, posterior.azimuths_deg
        t_el = np.degrees(np.arcsin(np.clip(d[..., 1], -1, 1)))
        t_az = np.degrees(np.arctan2(d[..., 0], -d[..., 2])) % 360.0
        i = np.argmin(np.abs(t_el[..., None] - el), -1)
        j = np.argmin(np.abs((t_az[..., None] - az + 180.0) % 360.0 - 180.0), -1)
        region = posterior.credible_region(0.9)[i, j] & (t_el >= el[0] - 2.0)
        # border_value 1: no outline along the seam (the region wraps round) or the zenith row
        edge = region & ~ndimage.binary_erosion(region, structure=np.ones((3, 3), bool), border_value=1)
        arr = np.asarray(canvas).copy()
        arr[edge] = (0, 230, 255)
        canvas = Image.fromarray(arr)
        draw = ImageDraw.Draw(canvas)
        x, y = _latlong_pixel(np.asarray(posterior.sun_direction, dtype=np.float64), h, w)
        r = 4
        for dx in (-w, 0, w):  # the ring wraps round the seam
            draw.ellipse((x + dx - r, y - r, x + dx + r, y + r), outline=(255, 40, 40), width=2)
    return np.asarray(canvas)
