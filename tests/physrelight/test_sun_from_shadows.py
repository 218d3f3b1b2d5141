"""Specification of the sun read from cast shadows and shading (physrelight.sun_from_shadows): on a box standing on
a plane, path-traced by Mitsuba under a known sun, the shadow edges give the sun's azimuth within 5 degrees, the
left/right shading picks the sun's side, a photo without shadows gives a flat likelihood, and bad input is refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physrelight import sun_from_shadows as sfs
from physrelight.sun_from_sky import AZIMUTH_STEP_DEG, ELEVATIONS_DEG

from .mitsuba_box import azimuth_error, render_box


def _right_mass(cue: sfs.CueLikelihood) -> float:
    """Share of the likelihood (over azimuth) with the sun to the right of the camera (heading world -Z)."""
    m = np.exp(cue.log_likelihood[0])
    return float(m[np.sin(np.radians(cue.azimuths_deg)) > 0].sum() / m.sum())


@pytest.mark.parametrize("elevation, azimuth", [(30.0, 100.0), (30.0, 250.0), (20.0, 340.0)])
def test_01_a_box_on_a_plane_gives_the_suns_azimuth_within_5_degrees(elevation: float, azimuth: float) -> None:
    """The box's shadow edges, read at full resolution (320 x 240, 16 spp: the path tracer's noise kept), mapped to
    the ground through the known camera: the cue's own azimuth within 5 deg, the grid's most likely cell the truth's,
    and the sign right (the edges that reach the box's foot point to the sun, not away from it)."""
    photo = render_box(elevation, azimuth)
    cue = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals,
                                linear=True)
    assert cue.spoke and cue.anchored >= 1, cue.detail
    assert azimuth_error(cue.azimuth_deg, azimuth) < 5.0, (cue.azimuth_deg, cue.detail)
    j = int(np.argmax(cue.log_likelihood[0]))
    assert azimuth_error(cue.azimuths_deg[j], azimuth) <= AZIMUTH_STEP_DEG / 2 + 1.0
    assert cue.log_likelihood.shape == (len(ELEVATIONS_DEG), len(cue.azimuths_deg))
    assert np.all(cue.log_likelihood <= 0) and np.ptp(cue.log_likelihood, axis=0).max() == 0  # no elevation said
    # the other end of the axis is far less likely: the sign is read, not guessed
    assert cue.azimuth_log_likelihood(np.array([azimuth + 180.0]))[0] < -2.0


@pytest.mark.parametrize("azimuth, side", [(100.0, "right"), (250.0, "left"), (60.0, "right"), (300.0, "left")])
def test_02_left_against_right_facing_surfaces_pick_the_suns_side(azimuth: float, side: str) -> None:
    """The box seen corner-on: its face turned to the camera's right against the one turned left. The sun's half
    of the azimuth circle holds the most the cue gives (1 - SHADING_MIN_ERROR, less 0.02 for its soft step at the
    halves' borders): the contrast here is large (|d| > 0.5)."""
    photo = render_box(30.0, azimuth)
    cue = sfs.shading_likelihood(photo.image, photo.normals, photo.sky_mask, photo.K, photo.world_to_camera,
                                 linear=True)
    assert cue.spoke, cue.detail
    share = _right_mass(cue) if side == "right" else 1.0 - _right_mass(cue)
    assert share >= 1.0 - sfs.SHADING_MIN_ERROR - 0.02, (share, cue.detail)


def test_03_a_sun_straight_ahead_lights_both_sides_alike_and_the_shading_cue_stays_undecided() -> None:
    """Sun behind the box, straight along the camera's heading: the two faces are lit alike (both in the box's own
    shade), and the cue splits its likelihood evenly (within 0.1)."""
    photo = render_box(30.0, 0.0)
    cue = sfs.shading_likelihood(photo.image, photo.normals, photo.sky_mask, photo.K, photo.world_to_camera,
                                 linear=True)
    assert abs(_right_mass(cue) - 0.5) < 0.1, cue.detail


def test_04_a_photo_without_shadows_gives_a_flat_likelihood() -> None:
    """The same box under an overcast light (a uniform sky, no sun): no edge on the ground is strong enough, the
    shadow likelihood is exactly flat and says so; the shading cue is all but flat (the two faces see the same sky)."""
    photo = render_box(None, None)
    cue = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals,
                                linear=True)
    assert not cue.spoke and cue.azimuth_deg is None and cue.observations == 0
    assert np.all(cue.log_likelihood == 0.0)
    assert "no straight edge" in cue.detail
    shading = sfs.shading_likelihood(photo.image, photo.normals, photo.sky_mask, photo.K, photo.world_to_camera,
                                     linear=True)
    assert np.ptp(shading.log_likelihood) < 0.05, shading.detail


def test_05_without_normals_or_a_ground_mask_nothing_is_read() -> None:
    """A facade's windows are straight edges too: without knowing the ground the shadow cue stays flat, saying why.
    With the ground given as a mask the shadows are read again."""
    photo = render_box(30.0, 100.0)
    cue = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, linear=True)
    assert not cue.spoke and "ground is not known" in cue.detail
    ground, _ = sfs.ground_and_casters(photo.normals, photo.world_to_camera[:3, :3], photo.sky_mask)
    masked = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, ground_mask=ground,
                                   linear=True)
    assert masked.spoke and azimuth_error(masked.azimuth_deg, 100.0) < 5.0, masked.detail


def test_06_ground_and_casters_part_the_level_ground_from_the_box() -> None:
    """The ground is the large level region; the box's sides are casters; the sky is neither. (The box's lit top
    touches the ground behind it in the image and joins its region: the edge between them is refused as a shadow by
    its dark side, as bright as sunlit ground; test 04 reads the overcast box without a segment.)"""
    photo = render_box(30.0, 100.0)
    ground, casters = sfs.ground_and_casters(photo.normals, photo.world_to_camera[:3, :3], photo.sky_mask)
    up = (np.moveaxis(photo.normals, 0, -1) @ photo.world_to_camera[:3, :3])[..., 1]
    sides = (np.abs(up) < 0.1) & ~photo.sky_mask
    assert sides.sum() > 1000 and casters[sides].all()
    assert not (ground & photo.sky_mask).any() and not (ground & casters).any()
    assert ground.sum() > 0.5 * (~photo.sky_mask).sum()


def test_07_the_same_seed_gives_the_same_likelihood_and_display_images_are_read() -> None:
    """The Hough transform is seeded: two runs give the same bytes. A display (sRGB) version of the photo gives the
    same azimuth within a degree."""
    photo = render_box(30.0, 250.0)
    a = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals,
                              linear=True, seed=3)
    b = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals,
                              linear=True, seed=3)
    assert a.log_likelihood.tobytes() == b.log_likelihood.tobytes()
    from physrelight.colour import linear_to_srgb

    display = np.clip(np.asarray(linear_to_srgb(photo.image / np.percentile(photo.image, 99))), 0.0, 1.0)
    c = sfs.shadow_likelihood(display, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals)
    assert c.spoke and azimuth_error(c.azimuth_deg, a.azimuth_deg) <= 1.0


def test_08_pitch_and_fov_give_relights_camera() -> None:
    """``pitch_deg``/``fov_deg`` is the level camera looking along world -Z: the same reading as the full camera."""
    photo = render_box(30.0, 100.0)
    a = sfs.shadow_likelihood(photo.image, photo.sky_mask, photo.K, photo.world_to_camera, normals=photo.normals,
                              linear=True)
    b = sfs.shadow_likelihood(photo.image, photo.sky_mask, normals=photo.normals, pitch_deg=-20.0, fov_deg=60.0,
                              linear=True)
    assert np.allclose(a.log_likelihood, b.log_likelihood, atol=1e-9)


def test_09_bad_input_is_refused_with_a_message_naming_it() -> None:
    h, w = 40, 60
    img = np.full((h, w, 3), 0.5)
    sky = np.zeros((h, w), bool)
    n = np.zeros((3, h, w))
    cam = dict(pitch_deg=-10.0, fov_deg=60.0)
    cases = [
        (lambda: sfs.shadow_likelihood(img[..., :2], sky, normals=n, **cam), "shape (H, W, 3)"),
        (lambda: sfs.shadow_likelihood(img, sky[:-1], normals=n, **cam), "sky_mask must have the image's shape"),
        (lambda: sfs.shadow_likelihood(img, sky.astype(float), normals=n, **cam), "sky_mask must be boolean"),
        (lambda: sfs.shadow_likelihood(img, sky, normals=n[:2], **cam), "normals must have shape (3, H, W)"),
        (lambda: sfs.shadow_likelihood(img * 3, sky, normals=n, **cam), "display image"),
        (lambda: sfs.shadow_likelihood(img * np.nan, sky, normals=n, **cam), "finite"),
        (lambda: sfs.shadow_likelihood(img, sky, normals=n), "the camera is needed"),
        (lambda: sfs.shadow_likelihood(img, sky, ground_mask=np.ones((h, w)), **cam), "ground_mask must be boolean"),
        (lambda: sfs.shading_likelihood(img, n.transpose(1, 2, 0), sky, **cam), "normals must have shape (3, H, W)"),
        (lambda: sfs.shading_likelihood(-img, n, sky, linear=True, **cam), "non-negative"),
    ]
    for call, words in cases:
        with pytest.raises(ValueError) as err:
            call()
        assert words in str(err.value), (words, str(err.value))


def test_10_a_flat_photo_reads_nothing() -> None:
    """A uniform grey photo, level ground everywhere below the horizon, nothing standing on it: both cues flat."""
    h, w = 60, 80
    from physrelight.panorama import camera_rays, level_camera, view_intrinsics

    K, R = view_intrinsics(60.0, w, h), level_camera(0.0, -10.0)[:3, :3]
    rays = camera_rays(K, R, h, w).numpy()[:, :, 0]
    sky = rays[..., 1] > 0
    normals = np.where(sky[None], 0.0, (R @ np.array([0.0, 1.0, 0.0]))[:, None, None])
    img = np.full((h, w, 3), 0.4)
    cue = sfs.shadow_likelihood(img, sky, normals=normals, pitch_deg=-10.0, fov_deg=60.0)
    shading = sfs.shading_likelihood(img, normals, sky, pitch_deg=-10.0, fov_deg=60.0)
    assert not cue.spoke and not shading.spoke and "too few surfaces" in shading.detail
    assert math.isclose(float(np.abs(cue.log_likelihood).max()), 0.0)
