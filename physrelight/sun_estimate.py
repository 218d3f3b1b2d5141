"""One posterior over the sun from every cue a photo carries: the sky, cast shadows, shading and a prior.

:func:`estimate_sun` multiplies, on the grid of :class:`~physrelight.sun_from_sky.SunPosterior` (sun elevation x
world azimuth):

* the sky's posterior (:func:`physrelight.sun_from_sky.estimate_sun_from_sky`) with its own prior (uniform over
  solid angle) divided out: the sky's likelihood;
* the cast-shadow likelihood (:func:`physrelight.sun_from_shadows.shadow_likelihood`), when normals (or a ground
  mask) say where the ground is;
* the shading likelihood (:func:`physrelight.sun_from_shadows.shading_likelihood`), when normals are given;
* the prior (:mod:`physrelight.sun_prior`; the shipped one by default).

Whether there is a sun: the sky's sun probability with the prior's share of sunny skies in place of the sky's own
(4 of its 5 overcast mixes have a sun), or, where the sky shows none (too little of it, clouds), at least
:data:`MIN_AGREEING_FEET` shadow edges that run into a caster's foot and agree on the azimuth, when those feet are
trusted (:data:`MAX_TRUSTED_SIGN_ERROR`; each such segment is an outlier with probability
:data:`~physrelight.sun_from_shadows.SEGMENT_OUTLIER`; at night no shadow makes a sun). Shading alone (one side
brighter) never makes a sun: paint can do that.

The fallback: where no cue reads a sun, the result has ``has_sun`` False, its posterior is the prior times whatever
the cues said (the prior itself when every cue is flat), and its ``reason`` says so; the caller keeps the lighting
it had without the sun (the SH solved from the shading). :attr:`SunPosterior.cues` records which cues spoke.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from physrelight._checks import Array
from physrelight.envmap import direction_from_angles
from physrelight.sun_from_sky import MIXES, SunPosterior, _with_spread, estimate_sun_from_sky
from physrelight.sun_from_shadows import (SEGMENT_OUTLIER, SIGN_ERROR, CueLikelihood, shading_likelihood,
                                         shadow_likelihood)
from physrelight.sun_prior import SunPrior, load_sun_prior

__all__ = ["FALLBACK", "MAX_TRUSTED_SIGN_ERROR", "MIN_AGREEING_FEET", "estimate_sun"]

FALLBACK = "no sun: keep the lighting solved from the shading (the SH), as before the sun was read"
"""What a result without a sun tells its caller to do (the end of its ``reason``)."""
MIN_AGREEING_FEET = 2
"""Where the sky shows no sun, shadow edges make one only when at least this many reach a caster's foot and agree
on the sun's azimuth (:attr:`physrelight.sun_from_shadows.CueLikelihood.agreeing`): one kerb line that ends at a
building is no sun (study 60)."""
MAX_TRUSTED_SIGN_ERROR = 0.05
"""Shadows alone make a sun only when their feet are trusted (``shadow_sign_error`` at most this: normals that
outline the casters exactly). With the decomposition's coarse normals (the default sign error) they only shape the
posterior of a sun the sky shows: on real crops of the training side, 3 of the 4 suns shadows alone made were wrong
(study 60)."""
_REFINE_HALF_DEG, _REFINE_STEP_DEG = 6.0, 0.5


def _prior(prior: SunPrior | str | None) -> SunPrior | None:
    if prior is None:
        return None
    if isinstance(prior, SunPrior):
        return prior
    if prior == "shipped":
        return load_sun_prior()
    raise ValueError(f"prior must be a SunPrior, 'shipped' or None (the sky's own: uniform), got {prior!r}")


def _sun_odds_reweighted(p_sky: float, prior: SunPrior | None) -> float:
    """The sky's sun probability with the prior's share of sunny skies in place of the sky's own (4 in 5)."""
    if prior is None or p_sky <= 0.0 or p_sky >= 1.0:
        return p_sky
    own = (len(MIXES) - 1) / len(MIXES)
    ratio = (p_sky / (1 - p_sky)) / (own / (1 - own))
    pi = prior.sun_probability
    odds = ratio * pi / (1 - pi)
    return odds / (1 + odds)


def _interp_periodic(row: np.ndarray, grid_az: np.ndarray, az: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``row (A,)`` on the periodic azimuth grid at ``az (N,)`` (degrees)."""
    step = grid_az[1] - grid_az[0]
    f = np.mod(az - grid_az[0], 360.0) / step
    i0 = np.floor(f).astype(int) % len(grid_az)
    w = f - np.floor(f)
    return (1 - w) * row[i0] + w * row[(i0 + 1) % len(grid_az)]


def estimate_sun(image: Array, sky_mask: Array, normals: Array | None = None, K: Array | None = None,
                 world_to_camera: Array | None = None, *, pitch_deg: float | None = None, fov_deg: float | None = None,
                 linear: bool = False, clip_level: float | None = None, prior: SunPrior | str | None = "shipped",
                 ground_mask: Array | None = None, seed: int = 0, shadow_sign_error: float = SIGN_ERROR
                 ) -> SunPosterior:
    """The sun from the sky, cast shadows, shading and a prior, as one posterior (see the module doc).

    Args:
        image: ``(H, W, 3)`` display values in [0, 1] (sRGB; the default) or linear radiance with ``linear=True``.
        sky_mask: ``(H, W)`` bool, True on sky.
        normals: ``(3, H, W)`` camera-frame normals (as the decomposition gives) or None: without them neither the
            shadows (unless ``ground_mask`` is given) nor the shading are read.
        K, world_to_camera, pitch_deg, fov_deg: the camera, as :func:`physrelight.sun_from_sky.estimate_sun_from_sky`.
        linear, clip_level: as :func:`physrelight.sun_from_sky.estimate_sun_from_sky`.
        prior: a :class:`~physrelight.sun_prior.SunPrior`, ``"shipped"`` (:func:`~physrelight.sun_prior.load_sun_prior`)
            or None (the sky's own: uniform over solid angle, its own share of sunny skies).
        ground_mask: ``(H, W)`` bool, where the ground is (overrides the normals' ground for the shadows).
        seed: the shadow cue's Hough transform (same seed, same result).
        shadow_sign_error: how often a shadow edge's foot points the wrong way
            (:func:`~physrelight.sun_from_shadows.shadow_likelihood`'s ``sign_error``): the default for the
            decomposition's coarse normals, 0 for normals that outline the casters exactly.

    Returns:
        :class:`~physrelight.sun_from_sky.SunPosterior` with ``cues`` naming the cues that spoke. With a sun: the
        MAP cell of the product, its azimuth refined to 0.5 degree (the sky's own 1-degree MAP where it alone
        decides the cell), the sky's fit (turbidity, mix, level, exponent: fitted at the sky's own MAP sun, kept
        as they are where the other cues move the sun) where the sky shows a sun, None where only the shadows do. Without one: ``has_sun`` False and the reason, ending in :data:`FALLBACK`.

    Raises:
        ValueError: as the cues' own functions, or a bad ``prior``.
    """
    pr = _prior(prior)
    sky = estimate_sun_from_sky(image, sky_mask, K, world_to_camera, pitch_deg=pitch_deg, fov_deg=fov_deg,
                                linear=linear, clip_level=clip_level)
    cam = dict(pitch_deg=pitch_deg, fov_deg=fov_deg, linear=linear)
    shadows = shadow_likelihood(image, sky_mask, K, world_to_camera, normals=normals, ground_mask=ground_mask,
                                seed=seed, sign_error=shadow_sign_error, **cam)
    shading = (shading_likelihood(image, normals, sky_mask, K, world_to_camera, **cam) if normals is not None
               else None)
    el, az, cell = sky.elevations_deg, sky.azimuths_deg, sky._cell_sr
    if pr is not None and not (np.allclose(pr.elevations_deg, el) and np.allclose(pr.azimuths_deg, az)):
        raise ValueError("the prior's grid is not the posterior's: refit it (scripts/fit_sun_prior.py)")
    log_prior = np.log(cell / cell.sum()) if pr is None else pr.log_probability
    # the sky's likelihood: its posterior over its own uniform prior (exactly flat where it read nothing)
    sky_ll = np.log(np.maximum(sky.posterior, 1e-300)) - np.log(cell / cell.sum())
    sky_ll -= sky_ll.max()
    cues: list[CueLikelihood] = [c for c in (shadows, shading) if c is not None and c.spoke]
    log_post = sky_ll + log_prior + sum((c.log_likelihood for c in cues), np.zeros_like(sky_ll))
    post = np.exp(log_post - log_post.max())
    post /= post.sum()
    spoke = (("sky",) if sky.has_sun else ()) + tuple(c.name for c in cues)

    p_sky = _sun_odds_reweighted(sky.sun_probability, pr) if sky.has_sun else sky.sun_probability
    sky_sun = sky.has_sun and p_sky >= 0.5
    shadow_sun = (shadows.agreeing >= MIN_AGREEING_FEET and shadow_sign_error <= MAX_TRUSTED_SIGN_ERROR
                  and sky.sky_kind != "night")
    notes = [c.detail for c in (shadows, shading) if c is not None]
    if not (sky_sun or shadow_sun):
        why = sky.reason if not sky.has_sun else (
            f"the prior's share of sunny skies ({pr.sun_probability:.2f}) leaves the sky's sun at {p_sky:.2f}")
        reason = f"no cue read a sun (sky: {why}; {'; '.join(notes) or 'no normals: shadows and shading not read'})"
        kind = sky.sky_kind if not sky.has_sun else "overcast"
        out = dataclasses.replace(sky, posterior=post, has_sun=False, reason=f"{reason}. {FALLBACK}",
                                  sun_probability=p_sky, sun_direction=None, elevation_deg=None, azimuth_deg=None,
                                  world_azimuth_deg=None, turbidity=None, mix=None, level=None, exponent=None,
                                  sky_kind=kind, cues=spoke)
        return _with_spread(out)

    i, j = np.unravel_index(int(np.argmax(post)), post.shape)
    only_sky = sky.has_sun and not cues and pr is None
    if sky.has_sun and (only_sky or (abs(el[i] - sky.elevation_deg) <= 2.0 and
                                     abs((az[j] - sky.world_azimuth_deg + 180.0) % 360.0 - 180.0) <= 2.5)):
        # the product's MAP is the sky's cell: keep the sky's own 1-degree refinement there
        e_map, a_map = float(sky.elevation_deg), float(sky.world_azimuth_deg)
        fine = a_map + np.arange(-_REFINE_HALF_DEG, _REFINE_HALF_DEG + 1e-9, _REFINE_STEP_DEG)
        if cues:  # the other cues may still move the azimuth within the cell
            score = _interp_periodic(sky_ll[i], az, fine) + sum(c.azimuth_log_likelihood(fine) for c in cues)
            a_map = float(fine[int(np.argmax(score))]) % 360.0
    else:
        e_map = float(el[i])
        fine = az[j] + np.arange(-_REFINE_HALF_DEG, _REFINE_HALF_DEG + 1e-9, _REFINE_STEP_DEG)
        score = _interp_periodic(sky_ll[i] + log_prior[i], az, fine) + sum(
            (c.azimuth_log_likelihood(fine) for c in cues), np.zeros_like(fine))
        a_map = float(fine[int(np.argmax(score))]) % 360.0
    p_sun = p_sky if sky_sun else 1.0 - (1.0 - sky.sun_probability) * SEGMENT_OUTLIER ** shadows.agreeing
    fit = dict(turbidity=sky.turbidity, mix=sky.mix, level=sky.level, exponent=sky.exponent) if sky.has_sun else \
        dict(turbidity=None, mix=None, level=None, exponent=None)
    kind = sky.sky_kind if sky.has_sun else ("none" if sky.sky_kind in ("none", "blown out") else "hazy")
    out = dataclasses.replace(sky, posterior=post, has_sun=True, reason="", sun_probability=p_sun,
                              sun_direction=direction_from_angles(e_map, a_map), elevation_deg=e_map,
                              azimuth_deg=(a_map - sky.camera_yaw_deg + 180.0) % 360.0 - 180.0,
                              world_azimuth_deg=a_map, sky_kind=kind, cues=spoke, **fit)
    return _with_spread(out)
