"""Specification of the target's sky seen through the photo's camera (:mod:`physrelight.sky_view`).
(Moved from tests/learned/test_relight_real.py with the functions, issue 41; the tests that need the shipped
relighter stay there.)"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from physrelight import colour, envmap, panorama
from physrelight.envmap import direction_from_angles
from physrelight.sky_model import HORIZON_Y
from physrelight.sky_view import target_sky
from physrelight.target_lighting import overcast_level

FOREST = Path(__file__).resolve().parents[2] / "physrelight" / "data" / "hdri" / "forest.exr"


def test_01_a_magnified_target_sky_is_smooth_and_an_overcast_one_is_the_cie_sky_per_ray() -> None:
    """Seen through a camera that magnifies the map (a texel over several pixels), the target's sky is the map's
    cubic B-spline (no slope jumps at the texel edges, which bilinear has and which a clipped bright texel turns
    into a square): along a row its largest second difference is a fraction of bilinear's. At the crop renderer's
    scale (test 02) it stays bilinear. The overcast sky is the CIE formula along each pixel's ray, not a
    64-row map looked up (whose linear pieces band a large photo's gradient)."""
    env = torch.from_numpy(envmap.read(FOREST))
    K = panorama.view_intrinsics(20.0, 400, 40)  # about 9 pixels per texel at the centre
    assert panorama.texel_magnification(K, env.shape[1]) > 5
    T = panorama.level_camera(0.0, 40.0)
    sky = target_sky(env, K, T, 40, 400).double()
    np.testing.assert_allclose(sky.numpy(), panorama.view(env, K, T, 40, 400, 1, interpolation="bspline"), rtol=1e-5)
    bilinear = torch.from_numpy(np.asarray(panorama.view(env, K, T, 40, 400, 1))).double()
    curvature = lambda img: float((img[:, 2:] - 2 * img[:, 1:-1] + img[:, :-2]).abs().amax())  # noqa: E731
    assert curvature(sky) < 0.35 * curvature(bilinear)
    small = panorama.view_intrinsics(55.0, 48, 36)
    assert panorama.texel_magnification(small, env.shape[1]) < 1
    # overcast: the formula per ray, at the level that gives order-2 irradiance 1 on a horizontal surface
    K2 = panorama.view_intrinsics(60.0, 64, 48)
    T2 = panorama.level_camera(0.0, 20.0)
    over = target_sky(direction_from_angles(45.0, 0.0), K2, T2, 48, 64, sky="overcast").double().numpy()
    rays = panorama.camera_rays(K2, T2, 48, 64, 1)[..., 0, :].double().numpy()
    cos_z = np.maximum(rays[..., 1], HORIZON_Y)
    np.testing.assert_allclose(over[..., 1], overcast_level() * (1 + 2 * cos_z) / 3, rtol=1e-4)  # float32 rays
    np.testing.assert_allclose(over[..., 0], over[..., 2])


def test_02_a_low_suns_disc_is_red_as_its_light() -> None:
    """A ``--sun`` target 4 degrees up, seen by a level camera looking at it: the brightest pixel is the sun's
    disc, and what the disc adds to the sky beside it has the colour of the sun's light at that elevation
    (:func:`physrelight.sky_model.sun_colour`, red over green over blue) within 2 % per channel."""
    from physrelight.sky_model import sun_colour

    K = panorama.view_intrinsics(40.0, 97, 65)  # odd sizes: the centre pixel's ray is the sun's direction
    view = target_sky(direction_from_angles(4.0, 0.0), K, panorama.level_camera(0.0, 4.0), 65, 97).double().numpy()
    lum = view @ np.asarray(colour.LUMINANCE)
    r, c = np.unravel_index(int(np.argmax(lum)), lum.shape)
    assert (r, c) == (32, 48) and lum[r, c] > 100 * lum[r, c + 12]
    disc = view[r, c] - view[r, c + 12]  # the sky 5 degrees to the side is the sky under the disc, near enough
    want = sun_colour(4.0)
    assert want[0] > 1.5 * want[2] and disc[0] > disc[1] > disc[2]
    np.testing.assert_allclose(disc / (disc @ np.asarray(colour.LUMINANCE)), want, rtol=0.02)


@pytest.mark.parametrize("threads", [1, 2])
def test_03_a_model_sky_by_strips_of_rows_is_the_sky_evaluated_in_one_piece(threads) -> None:
    """The clear sky, the overcast sky and the fitted sky are evaluated by strips of STRIP_ROWS rows on torch's
    threads (rays by :func:`physrelight.panorama.pixel_rays`): every pixel as the whole image evaluated at once gives
    it, to the bit, at any thread count."""
    from physrelight import sky_view
    from physrelight.sky_model import fit_sky, horizon_clamped, sky_view as model_view, sun_disc, sunsky_radiance
    from physrelight.target_lighting import Sun, clear_sky_sun, sun_rgb, target_lighting

    h, w = 2 * sky_view.STRIP_ROWS + 9, 40
    K, R = panorama.view_intrinsics(70.0, w, h), panorama.level_camera(30.0, 20.0)
    rays = horizon_clamped(panorama.pixel_rays(K, R, h, w))
    sun = Sun(25.0, 40.0)
    d = clear_sky_sun(sun.direction)
    whole = torch.from_numpy(sunsky_radiance(rays.double().numpy(), d)).float()
    whole = whole + (sun_disc(rays, d)[..., None] * torch.from_numpy(sun_rgb(d))).float()
    from physrelight.sky_model import overcast_sky

    grey = torch.from_numpy(overcast_sky(rays.double().numpy()) * overcast_level()).float()[..., None].expand(-1, -1, 3)
    coeffs = target_lighting(sun, None, "clear")
    fitted = model_view(fit_sky(coeffs), panorama.pixel_rays(K, R, h, w)[..., None, :]).float()
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        assert torch.equal(target_sky(sun, K, R, h, w, "clear"), whole)
        assert torch.equal(target_sky(sun, K, R, h, w, "overcast"), grey)
        assert torch.equal(sky_view.fitted_sky(coeffs, K, R, h, w), fitted)
    finally:
        torch.set_num_threads(before)
