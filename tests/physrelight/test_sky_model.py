"""Specification of the sky an SH lighting implies (physrelight.sky_model): the fit is exact NNLS, finds a
sun it was made from, reproduces a sky made of its own parts, renders smooth radiance with the sun's disc
where the sun is, and refuses what is not order-2 SH."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import torch

from physrelight import colour, envmap, panorama, sh
from physrelight import sky_model as sm


def _model_sh(s: np.ndarray, weights: np.ndarray, exponent: float = sm.FIT_GLOW_EXPONENT) -> np.ndarray:
    """Order-2 SH of the model's parts, projected from a fine lat-long map (independent of the fit's tables)."""
    d = envmap.directions(256, 512)
    env = (sm.sun_glow(d, s, exponent)[..., None] * weights[1] + sm.clear_sky(d) / np.array(sm.CLEAR_ZENITH) * weights[2]
           + sm.overcast_sky(d)[..., None] * weights[3] + (d[..., 1] < 0)[..., None] * weights[4])
    return np.asarray(sh.project_envmap(env, order=2)) + np.asarray(sh.project_sun(s, weights[0], order=2))


def test_01_the_nnls_is_exact_against_every_support_by_brute_force() -> None:
    """``_nnls_batched`` finds the non-negative least-squares optimum: it is feasible, and no point of a
    random feasible cloud nor scipy's NNLS does better."""
    scipy_opt = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(0)
    A = rng.normal(size=(64, 9, 5))
    b = rng.normal(size=(64, 9, 1))
    x, r = sm._nnls_batched(torch.from_numpy(A), torch.from_numpy(b))
    x, r = x.numpy(), r.numpy()
    assert (x >= 0).all()
    for i in range(64):
        ref, res = scipy_opt.nnls(A[i], b[i, :, 0])
        assert r[i, 0] == pytest.approx(res ** 2, rel=1e-9, abs=1e-12)
        cloud = np.abs(rng.normal(size=(200, 5)))
        assert (((A[i] @ cloud.T - b[i]) ** 2).sum(0) >= r[i, 0] - 1e-12).all()


@pytest.mark.parametrize("elev, azim", [(37.3, 121.7), (8.6, -64.1), (71.1, 200.4)])
def test_02_a_sky_made_of_the_models_parts_is_found_again(elev: float, azim: float) -> None:
    """A sun off the search grid, a clear sky, haze and ground: the direction comes back within the fine
    step (0.25 deg, up to its diagonal) and the SH within 1 % (the fit's parts are projected at 64 x 128,
    the test's at 256 x 512)."""
    s = envmap.direction_from_angles(np.array(elev), np.array(azim))
    w = np.array([[3.0, 2.7, 2.2], [0.0, 0.0, 0.0], [0.05, 0.08, 0.15], [0.02, 0.02, 0.03], [0.04, 0.035, 0.03]])
    c = _model_sh(s, w)
    fit = sm.fit_sky(c)
    assert math.degrees(math.acos(min(1.0, float(fit.sun_direction @ s)))) < 0.4
    assert fit.relative_residual < 0.01
    assert np.linalg.norm(fit.sh() - c) / np.linalg.norm(c) == pytest.approx(fit.relative_residual, abs=1e-6)
    assert (fit.weights >= 0).all()


def test_03_an_overcast_sky_is_all_overcast_and_renders_as_the_cie_sky() -> None:
    """The CIE overcast sky's SH fits with no sun, and the sky seen through a camera is that sky's radiance."""
    w = np.zeros((5, 3))
    w[3] = [0.7, 0.7, 0.7]
    c = _model_sh(np.array([0.0, 1.0, 0.0]), w)
    fit = sm.fit_sky(c)
    assert fit.relative_residual < 0.01
    assert np.allclose(fit.weights[0], 0.0, atol=1e-3 * 0.7)
    K = panorama.view_intrinsics(60.0, 48, 36)
    rays = panorama.camera_rays(K, panorama.level_camera(0.0, 30.0), 36, 48, 2)
    got = sm.sky_view(fit, rays).numpy()
    d = sm.horizon_clamped(rays.double()).numpy()
    want = (0.7 * sm.overcast_sky(d)).mean(-1)[..., None]
    assert np.abs(got - want).max() < 0.01 * 0.7


def test_04_the_suns_disc_is_where_the_sun_is_and_carries_its_irradiance() -> None:
    """Looking straight at the fitted sun, the disc's pixels integrate to the sun's irradiance."""
    s = envmap.direction_from_angles(np.array(30.0), np.array(0.0))
    w = np.zeros((5, 3))
    w[0], w[2] = [2.0, 2.0, 2.0], [0.05, 0.08, 0.15]
    fit = sm.fit_sky(_model_sh(s, w))
    # a narrow camera pointed at the sun: 0.02 deg pixels, the disc (radius 0.27 deg) well resolved
    n = 64
    K = panorama.view_intrinsics(1.28, n, n)
    yaw = math.degrees(math.atan2(fit.sun_direction[0], -fit.sun_direction[2]))
    T = panorama.level_camera(yaw, math.degrees(math.asin(fit.sun_direction[1])))
    rays = panorama.camera_rays(K, T, n, n, 1)
    img = sm.sky_view(fit, rays).numpy()
    sky_only = fit.radiance(rays[..., 0, :].numpy())
    pixel_sr = (math.radians(1.28) / n) ** 2
    e = ((img - sky_only) * pixel_sr).sum((0, 1))
    assert np.allclose(e, fit.weights[0], rtol=0.05)
    assert (img[n // 2, n // 2] > img[0, 0]).all()


def test_05_rays_below_the_horizon_see_the_sky_just_above_it() -> None:
    d = torch.tensor([[0.0, -0.5, -math.sqrt(0.75)], [0.0, 0.6, -0.8]], dtype=torch.float64)
    got = sm.horizon_clamped(d)
    assert sm.HORIZON_Y <= float(got[0, 1]) < 2 * sm.HORIZON_Y
    assert torch.allclose(got.norm(dim=-1), torch.ones(2, dtype=torch.float64))
    assert got[0, 0] == 0.0 and float(got[0, 2]) < 0  # the same azimuth
    assert torch.equal(got[1], d[1])


@pytest.mark.parametrize("bad, match", [
    (np.ones((9, 2)), "shape"), (np.full((9, 3), np.nan), "finite"), (np.zeros((9, 3)), "positive DC"),
])
def test_06_what_is_not_order_2_sh_is_refused(bad: np.ndarray, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        sm.fit_sky(bad)


def test_06b_a_bad_glow_exponent_is_refused() -> None:
    with pytest.raises(ValueError, match="glow_exponent"):
        sm.fit_sky(np.eye(9, 3) + 1.0, glow_exponent=0.0)


def test_07_the_suns_colour_is_built_from_references_colour_science_holds() -> None:
    """The colour-matching functions (an analytic fit) and the Rayleigh depth (Hansen and Travis) against
    colour-science's tables and Bodhaine et al.; the air mass is 1 at the zenith and about 38 at the
    horizon (Kasten and Young); the zenith sun is white, and every sun has luminance 1."""
    colour_science = pytest.importorskip("colour")
    from colour.phenomena import rayleigh_optical_depth

    wl = np.arange(380.0, 781.0, 5.0)
    ref = colour_science.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(
        colour_science.SpectralShape(380, 780, 5)).values
    assert np.allclose(sm.cie_1931_cmf(wl).sum(0), ref.sum(0), rtol=0.01)
    assert np.abs(sm.cie_1931_cmf(wl) - ref).max() < 0.03
    assert np.allclose(sm.rayleigh_optical_depth(wl), rayleigh_optical_depth(wl * 1e-7), rtol=0.005)
    assert sm.air_mass(90.0) == pytest.approx(1.0, abs=1e-3) and 37.0 < sm.air_mass(0.0) < 39.0
    assert np.allclose(sm.sun_colour(90.0), 1.0)
    for e in (0.0, 3.0, 10.0, 30.0, 60.0):
        c = sm.sun_colour(e)
        assert float(np.asarray(colour.LUMINANCE) @ c) == pytest.approx(1.0) and (c >= 0).all()
    reds = [sm.sun_colour(e)[0] / sm.sun_colour(e)[2] for e in (60.0, 30.0, 10.0, 5.0)]
    assert all(a < b for a, b in zip(reds, reds[1:]))  # redder as the sun sinks


@pytest.mark.parametrize("turbidity", [2.0, 3.0, 4.0])
def test_08_the_suns_colour_is_mitsubas_hosek_wilkie_sun(turbidity: float) -> None:
    """Red/green and blue/green of the sun against Mitsuba 3's ``sunsky`` sun (Hosek-Wilkie), both relative
    to the sun 89 degrees up: within 5 % from 10 degrees up; at 5 degrees red within 5 % and blue within
    25 % (near the horizon the two atmospheres differ most: ozone, the aerosol's profile)."""
    pytest.importorskip("mitsuba")
    from synth import lighting as L

    def mitsuba_sun(e: float) -> np.ndarray:
        return L.sunsky(0, elevation_deg=e, azimuth_deg=0.0, turbidity=turbidity, albedo=0.2, resolution=16).sun_irradiance

    zenith = mitsuba_sun(89.0)
    for e, tol_b in ((5.0, 0.25), (10.0, 0.05), (20.0, 0.05), (40.0, 0.05), (60.0, 0.05)):
        m = mitsuba_sun(e) / zenith
        c = sm.sun_colour(e) / sm.sun_colour(89.0)
        assert c[0] / c[1] == pytest.approx(m[0] / m[1], rel=0.05), e
        assert c[2] / c[1] == pytest.approx(m[2] / m[1], rel=tol_b), e


def test_09_any_order_2_lighting_gets_a_valid_sky() -> None:
    """Where the model cannot explain the SH (random coefficients, an indoor studio's lamps) the fit is still
    a sky: finite non-negative weights, a sun above the horizon, a residual no worse than no sky at all (1),
    and finite radiance along any ray."""
    rng = np.random.default_rng(0)
    rays = torch.nn.functional.normalize(torch.randn(16, 24, 2, 3, generator=torch.Generator().manual_seed(0),
                                                     dtype=torch.float64), dim=-1)
    for _ in range(4):
        c = rng.normal(size=(9, 3))
        c[0] = np.abs(c[0]) + 0.1
        fit = sm.fit_sky(c)
        assert np.isfinite(fit.weights).all() and (fit.weights >= 0).all()
        assert fit.sun_direction[1] >= -1e-12 and 0.0 <= fit.relative_residual <= 1.0 + 1e-9
        assert torch.isfinite(sm.sky_view(fit, rays)).all()


def test_10_the_batched_turn_about_y_is_about_y() -> None:
    from physrelight import rotations

    angles = np.array([-170.0, -33.3, 0.0, 12.5, 90.0, 271.0])
    got = rotations.about_y_many(angles)
    assert got.shape == (6, 3, 3)
    assert np.allclose(got, np.stack([rotations.about_y(a) for a in angles]), atol=1e-15)
    with pytest.raises(ValueError, match="angles"):
        rotations.about_y_many(np.array([np.nan]))


def test_11_the_clear_sky_of_a_sun_target_is_smooth_symmetric_and_dark_below_the_horizon() -> None:
    """``sunsky_radiance`` (the shipped Hosek-Wilkie table; its agreement with Mitsuba is tests/synth/test_sunsky_table.py):
    mirror-symmetric about the sun's vertical plane, 0 below the horizon, brighter at the horizon than at the zenith
    and warm there under a low sun, continuous in the sun's elevation across the table's nodes, and it refuses a bad
    sun. Its level against the sun (luminance of horizontal irradiance) falls as the sun climbs to 20 degrees
    (0.29 at 5 degrees up), then stays near 0.2."""
    d = envmap.directions(32, 64)
    for e in (3.0, 20.0, 60.0):
        s = np.array([0.0, math.sin(math.radians(e)), -math.cos(math.radians(e))])
        L = sm.sunsky_radiance(d, s)
        mirrored = sm.sunsky_radiance(d * np.array([-1.0, 1.0, 1.0]), s)
        np.testing.assert_allclose(L, mirrored, rtol=1e-12, atol=1e-15)
        assert np.all(L[d[..., 1] <= 0] == 0) and np.all(L[d[..., 1] > 0.05] > 0)
        lum = L @ np.asarray(colour.LUMINANCE)
        zenith = lum[0].mean()
        horizon_behind = sm.sunsky_radiance(np.array([0.0, 0.03, 1.0]), s) @ np.asarray(colour.LUMINANCE)
        assert horizon_behind > 1.5 * zenith
    low = sm.sunsky_radiance(np.array([0.0, 0.03, 1.0]), np.array([0.0, 0.05, -1.0]))
    assert low[0] > low[2]  # the horizon opposite a sun 3 degrees up is warm, not blue
    up = np.array([[0.0, 1.0, 0.0]])

    def horizontal(e: float) -> float:
        s = np.array([0.0, math.sin(math.radians(e)), -math.cos(math.radians(e))])
        return float(sh.irradiance(sh.project_envmap(sm.sunsky_radiance(d, s), order=2), up)[0] @ np.asarray(colour.LUMINANCE))

    for node in (2.5, 3.0, 10.0, 50.0, 80.0):  # no step where the interpolation changes nodes
        assert abs(horizontal(node + 1e-7) - horizontal(node - 1e-7)) < 1e-6
    ratios = np.array([horizontal(e) for e in np.arange(2.0, 90.01, 1.0)])
    assert np.all(np.diff(ratios[:19]) < 0), ratios[:19]  # the sky's share falls as the sun climbs to 20 degrees
    assert 0.25 < ratios[3] < 0.33 and np.all((0.17 < ratios[18:]) & (ratios[18:] < 0.23))
    for bad in (np.zeros(3), np.ones(2)):
        with pytest.raises(ValueError, match="sun"):
            sm.sunsky_radiance(d, bad)


def test_12_the_compiled_table_lookup_is_numpys_bilinear_blend_to_the_bit() -> None:
    """sunsky_radiance looks its two tables (the sun's elevations either side) up at the same cells in one compiled
    loop: the numbers numpy's expression of ``(1 - w) bilinear(a) + w bilinear(b)`` gives, to the bit, at the grid's
    nodes, its edges (clipped) and in between."""
    from physrelight.sky_model import _blend_bilinear, _bilinear_cells

    rng = np.random.default_rng(12)
    a, b = rng.random((31, 61, 3)) * 5, rng.random((31, 61, 3)) * 5
    rows, cols = np.arange(31) * 3.0, np.arange(61) * 3.0
    r = np.concatenate([rng.uniform(-5, 95, 500), rows, [90.0, 0.0]])
    c = np.concatenate([rng.uniform(-5, 185, 500), cols[:31], [180.0, 0.0]])
    cells = _bilinear_cells(rows, cols, r.reshape(-1, 1), c.reshape(-1, 1))
    idx, wr, wc = cells

    def bilinear(grid: np.ndarray) -> np.ndarray:
        flat, n = grid.reshape(-1, 3), grid.shape[1]
        g00, g01, g10, g11 = flat[idx], flat[idx + 1], flat[idx + n], flat[idx + n + 1]
        return (1 - wr) * ((1 - wc) * g00 + wc * g01) + wr * ((1 - wc) * g10 + wc * g11)

    w = 0.3712
    got = _blend_bilinear(a, b, w, cells)
    assert got.shape == (len(r), 1, 3)
    assert np.array_equal(got, (1 - w) * bilinear(a) + w * bilinear(b))
