"""Specification of the one posterior over the sun (physrelight.sun_estimate.estimate_sun): where the sky alone is
ambiguous (the camera facing away from the sun) the cast shadows narrow it to the truth; flat cues give the prior;
without a sky, shadows alone give the sun's azimuth; a night photo, an overcast one and one with nothing to read fall
back as stated, never to a confident wrong sun; and the cues that spoke are recorded."""

from __future__ import annotations

import numpy as np
import pytest

from physrelight import sun_estimate as se
from physrelight.colour import linear_to_srgb
from physrelight.sun_from_sky import estimate_sun_from_sky, lighting_preview
from physrelight.sun_prior import fit_sun_prior, load_sun_prior

from .mitsuba_box import azimuth_error, render_box


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _mass_near(p, azimuth: float, half: float = 20.0) -> float:
    m = p.azimuth_marginal()
    return float(m[np.array([azimuth_error(a, azimuth) <= half for a in p.azimuths_deg])].sum())


def _pillar_facing_away(seed: int):
    """A pillar on a plane under Mitsuba's sunsky (turbidity 2-6, sun 15-40 deg up), the camera 2 m up, pitched 5 deg
    down, facing away from the sun (180 +- 15-35 deg): its shadow runs away from the camera, beside the pillar."""
    rng = np.random.default_rng(seed)
    el, az, t = rng.uniform(15, 40), rng.uniform(0, 360), rng.uniform(2, 6)
    off = 180.0 + rng.choice([-1, 1]) * rng.uniform(15, 35)
    photo = render_box(el, az, yaw=az + off, pitch=-5.0, eye_height=2.0, size=(0.5, 1.2, 0.5), sky="sunsky",
                       turbidity=t)
    return photo, el, az


@pytest.mark.parametrize("seed", [7, 8, 9])
def test_01_facing_away_the_sky_is_ambiguous_and_the_shadows_narrow_it_to_within_20_degrees(seed: int) -> None:
    """The sky alone, facing away, holds little of its mass within 20 deg of the sun (its MAP sits near the sun's
    mirror); with the pillar's shadow and the renderer's exact normals (``shadow_sign_error=0``: the casters' feet
    are exact) the MAP azimuth is within 20 deg and most of the mass lies there. With the default sign error (meant
    for the decomposition's coarse normals) the sign is a weaker vote: the 90 % credible region still holds the sun."""
    photo, el, az = _pillar_facing_away(seed)
    sky = estimate_sun_from_sky(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, linear=True)
    assert _mass_near(sky, az) < 0.3, (sky.world_azimuth_deg, az)
    p = se.estimate_sun(photo.image, photo.sky_mask, photo.normals, photo.K, photo.world_to_camera, linear=True,
                        shadow_sign_error=0.0)
    assert p.has_sun and "shadows" in p.cues and "sky" in p.cues, p.reason
    assert azimuth_error(p.world_azimuth_deg, az) < 20.0, (p.world_azimuth_deg, az, p.cues)
    assert _mass_near(p, az) > 0.8 and _mass_near(p, az) > 3 * _mass_near(sky, az)
    assert p.posterior.sum() == pytest.approx(1.0, abs=1e-9)
    # the sky's fit is kept (the sky shows the sun's sky): the MAP lighting can be drawn
    assert p.turbidity is not None and p.sh().shape == (9, 3)
    default = se.estimate_sun(photo.image, photo.sky_mask, photo.normals, photo.K, photo.world_to_camera, linear=True)
    assert default.covers(photo.sun, 0.9) and _mass_near(default, az) > 3 * _mass_near(sky, az)


def test_02_flat_cues_give_the_prior_and_the_stated_fallback() -> None:
    """No sky in the frame, no normals: every cue is flat; the posterior is the prior exactly, no sun, no cue spoke,
    and the reason ends with the fallback. The same with normals of a bare, evenly lit ground."""
    h, w = 60, 80
    img = np.full((h, w, 3), 0.45)
    prior = load_sun_prior()
    p = se.estimate_sun(img, np.zeros((h, w), bool), pitch_deg=-20.0, fov_deg=60.0)
    assert not p.has_sun and p.cues == () and p.sun_direction is None
    assert p.reason.endswith(se.FALLBACK)
    np.testing.assert_allclose(p.posterior, prior.probability, rtol=1e-12, atol=0)
    normals = np.zeros((3, h, w))
    normals[1] = 1.0  # level ground seen by a level camera... pitched: up in the camera frame
    from physrelight.panorama import level_camera

    up = level_camera(0.0, -20.0)[:3, :3] @ np.array([0.0, 1.0, 0.0])
    normals = np.broadcast_to(up[:, None, None], (3, h, w)).copy()
    q = se.estimate_sun(img, np.zeros((h, w), bool), normals, pitch_deg=-20.0, fov_deg=60.0)
    assert not q.has_sun and q.cues == ()
    np.testing.assert_allclose(q.posterior, prior.probability, rtol=1e-12, atol=0)
    # another prior is honoured the same way
    other = fit_sun_prior([10.0], ["clear"])
    r = se.estimate_sun(img, np.zeros((h, w), bool), pitch_deg=-20.0, fov_deg=60.0, prior=other)
    np.testing.assert_allclose(r.posterior, other.probability, rtol=1e-12, atol=0)


def test_03_without_normals_and_prior_the_result_is_the_skys_own() -> None:
    """``prior=None`` and no normals: nothing but the sky speaks, with its own prior: the same posterior and sun."""
    photo = render_box(30.0, 20.0, pitch=5.0, eye_height=2.0, sky="sunsky")
    sky = estimate_sun_from_sky(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, linear=True)
    p = se.estimate_sun(photo.image, photo.sky_mask, None, photo.K, photo.world_to_camera, linear=True, prior=None)
    assert sky.has_sun and p.has_sun and p.cues == ("sky",)
    np.testing.assert_allclose(p.posterior, sky.posterior, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(p.sun_direction, sky.sun_direction, atol=1e-12)
    assert p.summary() == {**sky.summary(), "sun_spread": p.summary()["sun_spread"]}


def test_04_with_no_sky_in_view_the_shadows_alone_give_the_suns_azimuth() -> None:
    """No sky given, the renderer's exact normals (trusted feet): two of the box's shadow edges reach its feet and
    agree, which makes a sun; its azimuth within 5 deg (the shadows and the shading the only cues); the sky's fit is
    unknown, so the MAP sky is refused rather than drawn wrong, and the preview draws the SH it is given. One foot
    alone makes no sun (a kerb ending at a building would), nor do feet not trusted (the default sign error)."""
    photo = render_box(20.0, 340.0)  # pitch -20: the frame's top is above the horizon, but give no sky
    no_sky = np.zeros_like(photo.sky_mask)
    p = se.estimate_sun(photo.image, no_sky, photo.normals, photo.K, photo.world_to_camera, linear=True,
                        shadow_sign_error=0.0)
    assert p.has_sun and p.cues[0] == "shadows" and "sky" not in p.cues
    assert azimuth_error(p.world_azimuth_deg, 340.0) < 5.0
    assert p.turbidity is None and p.level is None and p.sky_kind == "none"
    for call in (lambda: p.radiance(np.array([0.0, 1.0, 0.0])), p.sh, p.sun_irradiance):
        with pytest.raises(ValueError, match="shadows or shading"):
            call()
    assert lighting_preview(np.zeros((9, 3)), p).shape == (128, 256, 3)
    one_foot = render_box(30.0, 250.0)  # its shadow shows one foot
    q = se.estimate_sun(one_foot.image, no_sky, one_foot.normals, one_foot.K, one_foot.world_to_camera, linear=True,
                        shadow_sign_error=0.0)
    assert not q.has_sun and "shadows" in q.cues and q.reason.endswith(se.FALLBACK)
    # with the decomposition's normals (the default sign error) shadows alone make no sun: they only shape one
    coarse = se.estimate_sun(photo.image, no_sky, photo.normals, photo.K, photo.world_to_camera, linear=True)
    assert not coarse.has_sun and coarse.reason.endswith(se.FALLBACK)


def test_05_a_night_photo_and_an_overcast_one_fall_back_without_a_sun() -> None:
    """Night: the box photo darkened until its sky reads too dark, shadows and all: no sun (no shadow makes a sun
    at night). Overcast: the box under the CIE overcast sky: no sun, no shadows; the reason ends with the fallback."""
    photo = render_box(30.0, 100.0)
    dark = np.clip(np.asarray(linear_to_srgb(photo.image * 0.002)), 0.0, 1.0)
    sky = photo.sky_mask.copy()
    sky[:40] = True  # the frame's top is sky
    p = se.estimate_sun(dark, sky, photo.normals, photo.K, photo.world_to_camera)
    assert not p.has_sun and p.sky_kind == "night" and p.reason.endswith(se.FALLBACK), p.reason
    overcast = render_box(None, None, pitch=0.0, eye_height=2.0, sky="overcast")
    q = se.estimate_sun(overcast.image, overcast.sky_mask, overcast.normals, overcast.K, overcast.world_to_camera,
                        linear=True)
    assert not q.has_sun and "shadows" not in q.cues and q.reason.endswith(se.FALLBACK), q.reason


def test_06_bad_input_is_refused() -> None:
    img = np.full((40, 60, 3), 0.5)
    sky = np.zeros((40, 60), bool)
    with pytest.raises(ValueError, match="prior must be"):
        se.estimate_sun(img, sky, pitch_deg=0.0, fov_deg=60.0, prior="uniform")
    with pytest.raises(ValueError, match="sky_mask must be boolean"):
        se.estimate_sun(img, sky.astype(int), pitch_deg=0.0, fov_deg=60.0)
    with pytest.raises(ValueError, match="normals must have shape"):
        se.estimate_sun(img, sky, np.zeros((40, 60, 3)), pitch_deg=0.0, fov_deg=60.0)
