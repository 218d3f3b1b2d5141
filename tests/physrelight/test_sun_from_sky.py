"""Specification of the sun read from a photo's sky (physrelight.sun_from_sky): on Hosek-Wilkie skies rendered by
Mitsuba's own ``sunsky`` (not the fitted table) through known cameras the sun comes back where the sky shows it,
its posterior covers it where the sky says little, an overcast sky has no sun, a tone curve, a white balance,
clipping and a cloud are survived as stated, and bad input reads no sun or is refused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from physrelight import envmap, sh
from physrelight import sun_from_sky as sfs
from physrelight.colour import LUMINANCE, linear_to_srgb, srgb_to_linear
from physrelight.panorama import camera_rays, level_camera, view_intrinsics
from physrelight.sky_model import overcast_sky, sunsky_radiance

H, W, FOV = 120, 160, 60.0


def _camera(yaw: float, pitch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    K = view_intrinsics(FOV, W, H)
    R = level_camera(yaw, pitch)[:3, :3]
    return K, R, camera_rays(K, R, H, W).numpy()[:, :, 0]


def _mitsuba_sky(elev: float, azim: float, turbidity: float, yaw: float, pitch: float):
    """Mitsuba's ``sunsky`` (sky and sun, ground albedo 0.2) along the pixel-centre rays of a level camera; the sky
    mask is the rays above the horizon. Returns linear image ``(H, W, 3)``, mask, K, R and the sun ``(3,)``."""
    pytest.importorskip("mitsuba", reason="Mitsuba 3 is needed to render the reference skies (pip install mitsuba)")
    from synth.lighting import _mitsuba, _sunsky_dict, eval_emitter

    mi = _mitsuba()
    s = envmap.direction_from_angles(elev, azim)
    emitter = mi.load_dict(_sunsky_dict(mi, s, turbidity, 0.2, sky_scale=1.0, sun_scale=1.0))
    K, R, rays = _camera(yaw, pitch)
    img = np.clip(eval_emitter(mi, emitter, rays.reshape(-1, 3)).reshape(H, W, 3), 0.0, None)
    return img, rays[..., 1] > 0, K, R, s


def _cases(seed: int, n: int, facing: str) -> list[tuple[float, float, float, float, float]]:
    """``n`` seeded skies ``(elevation 5-60, azimuth, turbidity 2-6, camera yaw, pitch 8-20)``; the camera faces
    the sun (within 20 deg), across (90 deg to either side) or away (180 +- 20 deg)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        e, a, t = rng.uniform(5, 60), rng.uniform(0, 360), rng.uniform(2, 6)
        off = {"sun": rng.uniform(-20, 20), "across": 90.0 * rng.choice([-1, 1]),
               "away": 180.0 + rng.uniform(-20, 20)}[facing]
        out.append((e, a, t, a - off, rng.uniform(8, 20)))
    return out


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b, -1.0, 1.0))))


def _display(img: np.ndarray, mask: np.ndarray, white_balance: np.ndarray, ev: float = 1.0) -> np.ndarray:
    """A camera's display image: a white-balance shift, an exposure putting the sky's median luminance at
    ``0.18 * 2^ev``, the sRGB curve, clipped at 1."""
    lin = img * white_balance
    lin = lin * (0.18 * 2.0 ** ev / np.median(lin[mask] @ np.array(LUMINANCE)))
    return np.clip(np.asarray(linear_to_srgb(lin)), 0.0, 1.0)


def _cloud(display: np.ndarray, mask: np.ndarray, seed: int) -> np.ndarray:
    """A grey-white cloud disc (display 0.85, radius 0.12 of the width) over the upper part of the sky."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:H, :W]
    blob = (yy - rng.uniform(0.1, 0.35) * H) ** 2 + (xx - rng.uniform(0.2, 0.8) * W) ** 2 < (0.12 * W) ** 2
    return np.where((blob & mask)[..., None], np.array([0.85, 0.85, 0.87]), display)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_01_a_sun_in_view_is_found_within_5_degrees() -> None:
    """Mitsuba skies (linear radiance, turbidity 2-6, sun 5-60 deg up) with the camera facing the sun: the MAP sun
    is within 5 deg, in ``relight --sun``'s convention its azimuth is the offset from the camera's heading, and the
    posterior is a normalised grid."""
    for e, a, t, yaw, pitch in _cases(1, 5, "sun"):
        img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
        p = sfs.estimate_sun_from_sky(img, mask, K, R, linear=True)
        assert p.has_sun, p.reason
        assert _angle(p.sun_direction, s) < 5.0, (e, a, t, yaw, pitch, p.elevation_deg, p.world_azimuth_deg)
        assert p.posterior.shape == (len(p.elevations_deg), len(p.azimuths_deg))
        assert p.posterior.sum() == pytest.approx(1.0, abs=1e-9) and (p.posterior >= 0).all()
        rel = (a - yaw + 180.0) % 360.0 - 180.0
        assert abs((p.azimuth_deg - rel + 180.0) % 360.0 - 180.0) < 5.0 / math.cos(math.radians(e))
        assert p.camera_yaw_deg == pytest.approx((yaw + 180.0) % 360.0 - 180.0, abs=1e-6)
        assert 2.0 <= p.turbidity <= 6.0 and 0.0 <= p.mix < 1.0


def test_02_a_sun_90_degrees_to_the_side_is_found_within_20_degrees() -> None:
    """The camera facing across the sun (90 deg to its left or right): the sun is out of the frame, the horizon's
    brightening and the sky's gradient place it within 20 deg."""
    for e, a, t, yaw, pitch in _cases(2, 4, "across"):
        img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
        p = sfs.estimate_sun_from_sky(img, mask, K, R, linear=True)
        assert p.has_sun, p.reason
        assert _angle(p.sun_direction, s) < 20.0, (e, a, t, yaw, pitch, p.elevation_deg, p.world_azimuth_deg)


def test_03_facing_away_the_90_percent_credible_region_covers_the_sun() -> None:
    """The camera facing away from the sun: the 90 % credible region holds the true sun's cell."""
    for e, a, t, yaw, pitch in _cases(3, 4, "away"):
        img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
        p = sfs.estimate_sun_from_sky(img, mask, K, R, linear=True)
        assert p.covers(s, 0.9), (e, a, t, yaw, pitch, p.elevation_deg, p.world_azimuth_deg, p.credible_area_sr)


@pytest.mark.parametrize("yaw, pitch", [(0.0, 5.0), (77.0, 20.0), (200.0, 12.0)])
def test_04_a_cie_overcast_sky_has_no_sun_and_a_flat_azimuth_posterior(yaw: float, pitch: float) -> None:
    """The CIE overcast sky (tinted, linear and as a display image): no sun, and the azimuth marginal is flat:
    its largest over its smallest bin is within 1.05."""
    K, R, rays = _camera(yaw, pitch)
    mask = rays[..., 1] > 0
    lin = overcast_sky(rays)[..., None] * np.array([0.9, 1.0, 1.1])
    for img, linear in ((lin, True), (np.clip(np.asarray(linear_to_srgb(0.5 * lin)), 0, 1), False)):
        p = sfs.estimate_sun_from_sky(img, mask, K, R, linear=linear)
        assert not p.has_sun and "overcast" in p.reason
        assert p.sun_direction is None and p.azimuth_deg is None
        m = p.azimuth_marginal()
        assert m.max() / m.min() < 1.05


def test_05_a_display_photo_with_a_white_balance_and_clipping_keeps_the_sun() -> None:
    """The skies of tests 1-3 as a camera shows them: a white-balance shift (warm or cool, up to 25 % per channel),
    the sRGB curve, exposed one stop over the sky's median so the aureole clips at 1 where it is bright: in view
    still within 5 deg, across within 20 deg, facing away the credible region still covers the sun."""
    warm, cool = np.array([1.15, 1.0, 0.8]), np.array([0.9, 1.0, 1.2])
    for facing, seed, check in (("sun", 5, lambda p, s: _angle(p.sun_direction, s) < 5.0),
                                ("across", 6, lambda p, s: _angle(p.sun_direction, s) < 20.0),
                                ("away", 7, lambda p, s: p.covers(s, 0.9))):
        for k, (e, a, t, yaw, pitch) in enumerate(_cases(seed, 3, facing)):
            img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
            p = sfs.estimate_sun_from_sky(_display(img, mask, warm if k % 2 else cool), mask, K, R)
            assert p.has_sun and check(p, s), (facing, e, a, t, yaw, pitch, p.elevation_deg, p.world_azimuth_deg)


def test_06_clipped_pixels_are_bounds_not_dropped() -> None:
    """A sky whose aureole is clipped (display, exposed two stops over the median): the clipped channels are
    read as bounds: the fitted model is at least as bright as the clip level there (within the 5 % scale of the
    likelihood on the median clipped block) and the sun is still found within 5 deg."""
    e, a, t, yaw, pitch = 25.0, 40.0, 3.0, 45.0, 12.0
    img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
    disp = _display(img, mask, np.ones(3), ev=2.0)
    clipped = (disp >= sfs.CLIP_LEVEL) & mask[..., None]
    assert clipped.any(-1).sum() > 200  # the test means something
    p = sfs.estimate_sun_from_sky(disp, mask, K, R)
    assert p.has_sun and _angle(p.sun_direction, s) < 5.0
    _, _, rays = _camera(yaw, pitch)
    # the photo's linear value the MAP predicts: I = a L^g, with radiance() = a L
    model = p.radiance(rays[clipped.any(-1)]) ** p.exponent * p.level ** (1.0 - p.exponent)
    bound = float(srgb_to_linear(np.array(sfs.CLIP_LEVEL)))
    assert np.median(model[clipped[clipped.any(-1)]]) >= bound * math.exp(-0.05)


def test_07_a_cloud_over_part_of_the_sky_is_an_outlier() -> None:
    """A cloud disc over about a tenth of the sky on the display photos of test 5: in view the sun is still within
    10 deg and across within 25 deg (a sweep of 12 skies each, docs/sun-from-sky.md: at most 7.3 and 21.3 deg;
    facing away only the credible region is claimed there, not here)."""
    cool = np.array([0.9, 1.0, 1.2])
    for facing, seed, tol in (("sun", 8, 10.0), ("across", 9, 25.0)):
        for k, (e, a, t, yaw, pitch) in enumerate(_cases(seed, 3, facing)):
            img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
            disp = _cloud(_display(img, mask, cool), mask, seed * 10 + k)
            p = sfs.estimate_sun_from_sky(disp, mask, K, R)
            assert p.has_sun and _angle(p.sun_direction, s) < tol, (facing, e, a, t, yaw, p.elevation_deg,
                                                                     p.world_azimuth_deg)


def test_08_no_sky_or_too_little_sky_reads_no_sun() -> None:
    """No sky pixels, or fewer than MIN_SKY_PIXELS: no sun, with a reason, and the posterior is the flat prior."""
    K, R, rays = _camera(0.0, 10.0)
    img = np.full((H, W, 3), 0.5)
    for n in (0, sfs.MIN_SKY_PIXELS - 1):
        mask = np.zeros((H, W), bool)
        mask.reshape(-1)[np.flatnonzero(rays[..., 1].reshape(-1) > 0.3)[:n]] = True
        p = sfs.estimate_sun_from_sky(img, mask, K, R)
        assert not p.has_sun and "too few sky pixels" in p.reason and p.sun_direction is None
        m = p.azimuth_marginal()
        assert m.max() / m.min() == pytest.approx(1.0, abs=1e-9)
    # a sky below the horizon is no sky
    p = sfs.estimate_sun_from_sky(img, rays[..., 1] < -0.1, K, R)
    assert not p.has_sun


def test_09_a_night_sky_reads_no_sun() -> None:
    """A very dark display sky (Mitsuba's sky at a 1 % exposure: median display value under DARK_SKY_LEVEL)."""
    K, R, rays = _camera(30.0, 15.0)
    mask = rays[..., 1] > 0
    img = np.clip(np.asarray(linear_to_srgb(1e-3 * sunsky_radiance(rays, envmap.direction_from_angles(20.0, 30.0)))),
                  0, 1)
    p = sfs.estimate_sun_from_sky(img, mask, K, R)
    assert not p.has_sun and "too dark" in p.reason and p.sun_direction is None


def test_10_a_blown_out_sky_reads_no_sun() -> None:
    """A sky clipped to white in every channel (bounds only, no shape to fit): no sun, the flat prior."""
    K, R, rays = _camera(30.0, 15.0)
    mask = rays[..., 1] > 0
    p = sfs.estimate_sun_from_sky(np.ones((H, W, 3)), mask, K, R)
    assert not p.has_sun and "blown out" in p.reason and p.sun_direction is None
    m = p.azimuth_marginal()
    assert m.max() / m.min() == pytest.approx(1.0, abs=1e-9)


def test_11_bad_shapes_and_values_are_refused() -> None:
    K, R, _ = _camera(0.0, 10.0)
    img, mask = np.full((H, W, 3), 0.5), np.ones((H, W), bool)
    with pytest.raises(ValueError, match="image must have shape"):
        sfs.estimate_sun_from_sky(img[..., :2], mask, K, R)
    with pytest.raises(ValueError, match="sky_mask must have the image's shape"):
        sfs.estimate_sun_from_sky(img, mask[1:], K, R)
    with pytest.raises(ValueError, match="boolean"):
        sfs.estimate_sun_from_sky(img, mask.astype(float), K, R)
    with pytest.raises(ValueError, match="K must have shape"):
        sfs.estimate_sun_from_sky(img, mask, K[:2], R)
    with pytest.raises(ValueError, match="world_to_camera"):
        sfs.estimate_sun_from_sky(img, mask, K, R * 2)
    with pytest.raises(ValueError, match="finite"):
        sfs.estimate_sun_from_sky(np.where(mask[..., None], np.nan, img), mask, K, R)
    with pytest.raises(ValueError, match="display image"):
        sfs.estimate_sun_from_sky(img * 3, mask, K, R)
    with pytest.raises(ValueError, match="camera is needed"):
        sfs.estimate_sun_from_sky(img, mask)
    with pytest.raises(ValueError, match="not both"):
        sfs.estimate_sun_from_sky(img, mask, K, R, pitch_deg=10.0, fov_deg=60.0)


def test_12_pitch_and_fov_are_relights_camera() -> None:
    """``pitch_deg``/``fov_deg`` give the same answer as the camera they stand for (level, heading world -Z)."""
    K, R, rays = _camera(0.0, 12.0)
    img = sunsky_radiance(rays, envmap.direction_from_angles(30.0, 15.0))
    mask = rays[..., 1] > 0
    a = sfs.estimate_sun_from_sky(img, mask, K, R, linear=True)
    b = sfs.estimate_sun_from_sky(img, mask, pitch_deg=12.0, fov_deg=FOV, linear=True)
    assert np.array_equal(a.posterior, b.posterior) and a.azimuth_deg == b.azimuth_deg == b.world_azimuth_deg
    assert a.posterior.tobytes() == sfs.estimate_sun_from_sky(img, mask, K, R, linear=True).posterior.tobytes()


def test_13_the_maps_sky_reproduces_the_photo_and_its_sh_is_sky_plus_sun() -> None:
    """On a linear Mitsuba sky the MAP sky (:meth:`radiance`) matches the sky pixels within 5 % (median relative
    error, the sun's disc aside), and :meth:`sh` is the projection of a fine map of that sky plus the sun's delta."""
    e, a, t, yaw, pitch = 30.0, 20.0, 4.0, 10.0, 15.0
    img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, pitch)
    p = sfs.estimate_sun_from_sky(img, mask, K, R, linear=True)
    assert p.has_sun and p.exponent == pytest.approx(1.0, abs=0.1)
    _, _, rays = _camera(yaw, pitch)
    far = mask & (rays @ s < math.cos(math.radians(2.0)))
    model = p.radiance(rays[far])
    rel = np.abs(model - img[far]) / img[far]
    assert np.median(rel) < 0.05
    fine = p.radiance(envmap.directions(256, 512))
    ref = np.asarray(sh.project_envmap(fine, order=2)) + np.asarray(sh.project_sun(p.sun_direction,
                                                                                    p.sun_irradiance(), order=2))
    assert np.abs(p.sh() - ref).max() < 0.02 * np.abs(ref).max()


def test_14_the_turbidity_table_keeps_the_turbidity_3_table() -> None:
    """The turbidity-2-6 table's turbidity-3 slice is the shipped turbidity-3 table (both written by
    ``synth.sunsky_table``), and :func:`hosek_wilkie_sky` at turbidity 3 is ``sunsky_radiance``."""
    from safetensors.numpy import load_file

    from physrelight.sky_model import SUNSKY_TABLE

    multi, single = load_file(str(sfs.SUNSKY_TURBIDITY_TABLE)), load_file(str(SUNSKY_TABLE))
    k = list(multi["turbidities"]).index(3.0)
    assert np.array_equal(multi["radiance"][k], single["radiance"])
    d = envmap.directions(32, 64)
    s = envmap.direction_from_angles(23.0, 70.0)
    assert np.allclose(sfs.hosek_wilkie_sky(d, s, 3.0), sunsky_radiance(d, s), rtol=2e-3, atol=1e-6)


def _in_view_cases() -> list[tuple[float, float, float, float]]:
    """Three seeded skies ``(elevation 8-25, azimuth, turbidity 2-6, camera yaw)`` with the sun inside the frame at
    pitch 12 (the frame's top edge is 34 deg up, its sides 30 deg off the heading)."""
    rng = np.random.default_rng(7)
    out = []
    for _ in range(3):
        e, a, t = rng.uniform(8, 25), rng.uniform(0, 360), rng.uniform(2, 6)
        out.append((e, a, t, a - rng.uniform(-15, 15)))
    return out


def test_15_a_sun_in_the_frame_that_the_photo_does_not_show_is_not_read() -> None:
    """A sky shaped as a sun's, with the sun and its aureole not there (the pixels within 10 deg of it painted the
    sky's median: what a twilight glow or a lit night sky looks like to the model), through a display camera: the
    fit puts the sun in the frame, on open sky, where no pixel is bright, so no sun is read (kind ``"unseen"``, the
    flat prior), never a confident sun. The same skies untouched: the sun within 5 deg (no false alarm)."""
    for e, a, t, yaw in _in_view_cases():
        img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, 12.0)
        disp = _display(img, mask, np.ones(3))
        near = np.degrees(np.arccos(np.clip(_camera(yaw, 12.0)[2] @ s, -1.0, 1.0))) < 10.0
        assert near.any()  # the sun is in view
        p = sfs.estimate_sun_from_sky(disp, mask, K, R)
        assert p.has_sun and _angle(p.sun_direction, s) < 5.0, (e, a, t, p.reason)
        hole = np.where(near[..., None], np.median(disp[mask], 0), disp)
        p = sfs.estimate_sun_from_sky(hole, mask, K, R)
        assert not p.has_sun and p.sky_kind == "unseen" and p.sun_direction is None, (e, a, t, p.sky_kind)
        assert "shows none" in p.reason
        assert p.credible_area_sr > 5.0  # the flat prior's 5.46 sr: nothing is claimed


def test_16_a_sun_in_the_frame_behind_a_building_is_still_read() -> None:
    """The skies of test 15 with a dark building (not sky in the mask) standing over the sun and 8 deg round it: the
    sun is hidden, not missing, so the rule of test 15 does not apply and the sky's gradient still places it
    within 5 deg."""
    yy = np.arange(H)[:, None]
    for e, a, t, yaw in _in_view_cases():
        img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, 12.0)
        disp = _display(img, mask, np.ones(3))
        box = np.degrees(np.arccos(np.clip(_camera(yaw, 12.0)[2] @ s, -1.0, 1.0))) < 8.0
        cols = np.flatnonzero(box.any(0))
        wall = np.zeros((H, W), bool)
        wall[:, cols.min():cols.max() + 1] = True
        wall &= yy >= np.flatnonzero(box.any(1)).min()
        p = sfs.estimate_sun_from_sky(np.where(wall[..., None], 0.2, disp), mask & ~wall, K, R)
        assert p.has_sun and _angle(p.sun_direction, s) < 5.0, (e, a, t, p.reason)


def test_17_unseen_in_frame_rules_out_only_dim_open_sky_inside_the_frame() -> None:
    """``unseen_in_frame`` on a level camera over a sky brightening towards the horizon (luminance 1-1.5) with one
    bright spot (10) and a wall: a direction at the spot is seen; one on the dim open sky high up is ruled out; one
    on the wall (not sky), one outside the frame, one behind the camera are not ruled out; a clipped pixel (inf)
    counts as seen even off the mask."""
    K, R, rays = _camera(0.0, 10.0)
    sky = rays[..., 1] > 0
    bright = 1.5 - 0.5 * rays[..., 1] / rays[..., 1].max()
    bright[20, 120] = 10.0  # a sun's disc
    wall = np.zeros((H, W), bool)
    wall[:, :30] = True
    sky &= ~wall
    bright[15, 60] = np.inf  # a clipped disc the mask left out
    sky[13:18, 58:63] = False

    def at(ix: int, iy: int) -> np.ndarray:
        return rays[iy, ix]

    dirs = np.stack([at(120, 20), at(90, 40), at(10, 30), envmap.direction_from_angles(15.0, 90.0),
                     envmap.direction_from_angles(20.0, 180.0), at(60, 15)])
    got = sfs.unseen_in_frame(dirs, bright, sky, K, R)
    assert got.tolist() == [False, True, False, False, False, False]


def test_18_pixels_no_sky_fits_are_not_read() -> None:
    """A curtain where the sky should be (vertical folds: columns alternately 0.5x and 1.5x a Mitsuba sky's display
    values, eight pixels wide): no hypothesis, sun or sunless, fits it within the model's residual scale, so no sun
    is read (kind ``"unfit"``, the flat prior). The same sky as rendered is read (its fit cost is far below
    :data:`MAX_FIT_COST`)."""
    e, a, t, yaw = _in_view_cases()[0]
    img, mask, K, R, s = _mitsuba_sky(e, a, t, yaw, 12.0)
    disp = _display(img, mask, np.ones(3))
    assert sfs.estimate_sun_from_sky(disp, mask, K, R).has_sun
    folds = np.where((np.arange(W) // 8) % 2 == 0, 0.5, 1.5)[None, :, None]
    p = sfs.estimate_sun_from_sky(np.clip(disp * folds, 0.0, 1.0), mask, K, R)
    assert not p.has_sun and p.sky_kind == "unfit" and p.sun_direction is None, (p.sky_kind, p.reason)
    assert "does not fit" in p.reason and p.credible_area_sr > 5.0
