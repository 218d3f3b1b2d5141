"""Specification of the physics pieces of the real-photo relight path: quotient relighting
(:mod:`physrelight.quotient`), the guided filter (:mod:`physrelight.guided_filter`) and the output's
exposure (:mod:`physrelight.exposure`)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import exposure, guided_filter, quotient, sh


def _scene(seed: int = 0, h: int = 24, w: int = 32):
    g = torch.Generator().manual_seed(seed)
    n = torch.randn(1, 3, h, w, generator=g)
    n[:, 2] = n[:, 2].abs() + 0.2  # facing the camera
    n = n / n.norm(dim=1, keepdim=True)
    albedo = torch.rand(1, 3, h, w, generator=g) * 0.8 + 0.1
    L = torch.from_numpy(np.asarray(sh.project_sun(np.array([0.3, 0.6, 0.74]) / np.linalg.norm([0.3, 0.6, 0.74]),
                                                   np.array([1.0, 0.9, 0.8])))).float()[None]
    L[:, 0] += 0.6  # and a sky
    return n, albedo, L


def test_01_quotient_returns_the_photo_exactly_when_relit_to_its_own_lighting() -> None:
    n, albedo, L = _scene()
    photo = albedo * torch.rand_like(albedo)  # any photo: the quotient never looks at how it was made
    assert torch.equal(quotient.quotient_relight(photo, n, L, L), photo)
    s = torch.rand(1, 1, *photo.shape[-2:])
    assert torch.equal(quotient.quotient_relight(photo, n, L, L, source_shadow=s, target_shadow=s), photo)


def test_02_quotient_is_invariant_to_the_albedo_lighting_scale() -> None:
    n, albedo, L = _scene(1)
    Lt = torch.roll(L, 1, dims=2) * 1.3
    photo = albedo * torch.clamp_min(sh.shading(L.double(), n.permute(0, 2, 3, 1).double()).permute(0, 3, 1, 2),
                                     0).float()
    a = quotient.quotient_relight(photo, n, L, Lt)
    for k in (1e-3, 7.0):  # albedo / k and lighting * k make the same photo
        torch.testing.assert_close(quotient.quotient_relight(photo, n, L * k, Lt * k), a, rtol=1e-5, atol=1e-7)


def test_03_quotient_of_an_unguarded_lambertian_photo_is_the_target_rendering() -> None:
    n, albedo, L = _scene(2)
    Lt = L.clone()
    Lt[:, 1:4] *= -1  # the light from the other side
    from physrelight import image_model

    photo = image_model.render(albedo, n, L)
    want = image_model.render(albedo, n, Lt).clamp_min(0)
    got = quotient.quotient_relight(photo, n, L, Lt, guard=1e-9)
    lit = image_model.shading(n, L).min(1, keepdim=True).values > 0.05
    torch.testing.assert_close(got[lit.expand_as(got)], want[lit.expand_as(want)], rtol=1e-4, atol=1e-6)


def test_04_guided_filter_keeps_constants_and_affine_functions_of_the_guide() -> None:
    g = torch.Generator().manual_seed(3)
    guide = torch.rand(1, 1, 30, 40, generator=g)
    const = torch.full((1, 2, 30, 40), 0.7)
    torch.testing.assert_close(guided_filter.guided_filter(guide, const, 3, 1e-3), const)
    affine = 2.0 * guide - 0.5
    torch.testing.assert_close(guided_filter.guided_filter(guide, affine, 3, 1e-8), affine, rtol=1e-3, atol=1e-3)
    box = guided_filter.box_filter(guide.double(), 2)
    brute = torch.stack([guide.double()[0, 0, max(0, i - 2): i + 3, max(0, j - 2): j + 3].mean()
                         for i in range(30) for j in range(40)]).reshape(30, 40)
    torch.testing.assert_close(box[0, 0], brute)


@pytest.mark.parametrize("shape", [(2, 3, 37, 53), (1, 1, 5, 90), (1, 2, 64, 3)])
@pytest.mark.parametrize("radius", [17, 26, 52, 200])
def test_04b_the_summed_area_box_filter_is_the_direct_mean(shape, radius) -> None:
    """Past ``_POOL_MAX_RADIUS`` the box filter uses summed-area tables (cumulative sums sliced in place); it is
    the direct mean of the pixels inside the image (two cut-at-the-border pools) to rounding, windows wider than
    the image included (every pixel sees the whole row or column)."""
    g = torch.Generator().manual_seed(radius)
    x = torch.randn(*shape, generator=g, dtype=torch.float64)
    k = 2 * radius + 1
    rows = torch.nn.functional.avg_pool2d(x, (1, k), stride=1, padding=(0, radius), count_include_pad=False)
    direct = torch.nn.functional.avg_pool2d(rows, (k, 1), stride=1, padding=(radius, 0), count_include_pad=False)
    assert torch.allclose(guided_filter.box_filter(x, radius), direct, atol=1e-12, rtol=0)
    if radius >= max(shape[-2:]):
        assert torch.allclose(guided_filter.box_filter(x, radius), x.mean((-2, -1), keepdim=True).expand_as(x),
                              atol=1e-12, rtol=0)


@pytest.mark.parametrize("h, w, radius, dtype", [(37, 53, 17, torch.float32), (5, 90, 200, torch.float64),
                                                  (64, 3, 26, torch.float32), (1300, 15000, 600, torch.float32)])
def test_04d_the_box_filters_window_counts_are_those_of_a_plane_of_ones_to_the_bit(h, w, radius, dtype) -> None:
    """The summed-area path divides by window counts computed from their closed form (``_window_count``), not by
    filtering a plane of ones; they are those very numbers, also where a row's running sums of the column counts pass
    ``2**24`` and float32 rounds them (15000 columns of 1201-pixel counts), so the box filter's output is unchanged
    bit for bit."""
    ones = torch.ones(1, 1, h, w, dtype=dtype)
    filtered = guided_filter._window_sums(guided_filter._window_sums(ones, radius, -2), radius, -1)
    assert torch.equal(guided_filter._window_count(h, w, radius, dtype), filtered)
    if w * min(h, 2 * radius + 1) > 2**24:  # the rounding the closed form must reproduce is there: not the exact counts
        def n(size: int) -> torch.Tensor:
            i = torch.arange(size, dtype=torch.float64)
            return (i + radius).clamp_max(size - 1) - (i - radius).clamp_min(0) + 1
        assert not torch.equal(filtered.double()[0, 0], n(h)[:, None] * n(w)[None, :])


def test_05_guided_upsampling_keeps_a_step_edge_within_one_pixel() -> None:
    """A mask brought up 8x from a working resolution, guided by the full-resolution photo's step:
    its 1/2 crossing lands within a pixel of the photo's edge."""
    H, W, edge = 64, 96, 37  # the edge is not on the coarse grid
    guide = torch.zeros(1, 1, H, W)
    guide[..., edge:] = 1.0
    full_mask = (torch.arange(W) < edge).float().expand(1, 1, H, W)
    low = torch.nn.functional.interpolate(full_mask, size=(H // 8, W // 8), mode="area")
    up = guided_filter.guided_upsample(guide, low, eps=1e-3)
    col = (up[0, 0, H // 2] > 0.5).float()
    found = int(col.sum())  # the mask is 1 left of its edge
    assert abs(found - edge) <= 1, (found, edge)
    assert bool((col[:found] == 1).all())  # one crossing: a step, not a ripple


def test_06_auto_exposure_brings_the_foreground_to_the_sources_key() -> None:
    g = torch.Generator().manual_seed(4)
    source = torch.rand(1, 3, 20, 30, generator=g) * 0.5 + 0.05
    relit = source * 3.7
    fg = torch.ones(1, 1, 20, 30, dtype=torch.bool)
    fg[..., :4, :] = False
    gain = exposure.exposure_gain("auto", relit, source, fg)
    key = exposure.log_average(source, fg)
    assert key > exposure.DARK_KEY
    torch.testing.assert_close(exposure.log_average(relit * gain[:, None, None, None], fg), key)
    dark = source * 0.01  # a dark photo: the relit one goes to middle grey
    gain = exposure.exposure_gain("auto", relit, dark, fg)
    torch.testing.assert_close(exposure.log_average(relit * gain[:, None, None, None], fg),
                               torch.tensor([exposure.MIDDLE_GREY]))
    # keep and stops
    assert float(exposure.exposure_gain("keep", relit, source, fg)) == 1.0
    assert float(exposure.exposure_gain(-2, relit, source, fg)) == 0.25


def test_07_auto_exposure_does_not_clip_the_sky() -> None:
    source = torch.full((1, 3, 10, 10), 0.02)  # dark: auto aims at middle grey
    relit = source.clone()
    sky = torch.zeros(1, 1, 10, 10, dtype=torch.bool)
    sky[..., :3, :] = True
    relit[:, :, :3] = 0.5  # a bright sky over a dark scene
    gain = float(exposure.exposure_gain("auto", relit, source, ~sky, highlights=sky))
    assert math.isclose(gain, 2.0, rel_tol=1e-5)  # 0.5 * gain = 1: white, not beyond
    assert float(exposure.exposure_gain("auto", relit, source, ~sky)) > 8


def test_07b_auto_exposure_takes_a_sky_larger_than_torch_quantile_does() -> None:
    """A 24-megapixel photo's sky can hold more than 2**24 pixels, more than ``torch.quantile`` takes: the sky's
    99th percentile is still found (``physrelight.stats.quantile``) and the same case as test 07 holds."""
    h, w = 4200, 4100  # 17.2 M pixels, all but the last row sky
    source = torch.full((1, 3, h, w), 0.02)
    relit = torch.full((1, 3, h, w), 0.5)
    sky = torch.ones(1, 1, h, w, dtype=torch.bool)
    sky[..., -1, :] = False
    relit[..., -1, :] = 0.02
    assert int(sky.sum()) > 2 ** 24
    assert math.isclose(float(exposure.exposure_gain("auto", relit, source, ~sky, highlights=sky)), 2.0, rel_tol=1e-5)


def _grey(level: float, h: int = 10, w: int = 10) -> torch.Tensor:
    """``(1, 3, h, w)`` a grey image of luminance ``level`` (Rec. 709 weights sum to 1)."""
    return torch.full((1, 3, h, w), level, dtype=torch.float64)


def test_07c_a_source_is_dark_below_two_stops_under_middle_grey() -> None:
    """:data:`DARK_KEY` is 0.045, two stops under middle grey: a source keyed at 0.04 is dark (the relit
    foreground goes to 0.18), one keyed at 0.05 or 0.085 is not (the relit foreground takes its key). Cases sit
    either side of 0.045 and below 0.09, so a threshold moved by a factor of two is seen."""
    assert math.isclose(exposure.DARK_KEY, exposure.MIDDLE_GREY / 4, rel_tol=1e-9)
    relit = _grey(0.3)
    for key, want in ((0.04, exposure.MIDDLE_GREY), (0.05, 0.05), (0.085, 0.085)):
        gain = exposure.exposure_gain("auto", relit, _grey(key), None)
        assert math.isclose(float(gain) * 0.3, want, rel_tol=1e-9), (key, float(gain) * 0.3)


def test_07d_the_sky_guard_is_the_skys_99th_percentile() -> None:
    """Over a dark scene (auto aims at middle grey: gain 18 on a foreground of 0.01), a sky of 1000 pixels with 3 %
    at luminance 4 (a bright cloud: more than 1 %) holds the gain to 1/4; with only 0.5 % at 100 (the sun's disc,
    under 1 %) the rest of the sky (0.25) sets it: 4. A 90th percentile would give 4 in the first case."""
    h, w = 40, 25  # the sky is the top 1000 pixels
    source = _grey(0.01, 2 * h, w)
    sky = torch.zeros(1, 1, 2 * h, w, dtype=torch.bool)
    sky[..., :h, :] = True
    for n_bright, level, want in ((30, 4.0, 0.25), (5, 100.0, 4.0)):
        relit = _grey(0.01, 2 * h, w)
        relit[..., :h, :] = 0.25
        relit.view(1, 3, -1)[..., :n_bright] = level  # the first pixels of the top row
        gain = float(exposure.exposure_gain("auto", relit, source, ~sky, highlights=sky))
        assert math.isclose(gain, want, rel_tol=1e-6), (n_bright, gain)
        assert float(exposure.exposure_gain("auto", relit, source, ~sky)) == pytest.approx(18.0)


def test_07e_a_black_or_blinding_relighting_keeps_a_finite_gain_of_at_most_16_stops() -> None:
    """A relit foreground that is black (luminance floored at 1e-6) would need a gain of 0.18 / 1e-6; one at 1e6
    would need 2e-7: both are limited to ``2**+-16``, exactly."""
    source = _grey(0.18)
    assert float(exposure.exposure_gain("auto", _grey(0.0), source)) == 2.0**16
    assert float(exposure.exposure_gain("auto", _grey(1e6), source)) == 2.0**-16
    assert float(exposure.exposure_gain("auto", _grey(0.36), source)) == pytest.approx(0.5)


@pytest.mark.parametrize("bad", ["bright", "nan", "1e9", ""])
def test_08_exposure_values_are_checked(bad) -> None:
    with pytest.raises(ValueError, match="exposure"):
        exposure.parse_exposure(bad)
    assert exposure.parse_exposure(" AUTO ") == "auto" and exposure.parse_exposure("+1.5") == 1.5


def test_sun_of_inverts_project_sun_and_sun_shading_is_the_exact_clamped_cosine() -> None:
    """``sh.sun_of(project_sun(s, E)) == (s, E)`` (1e-6); ``image_model.sun_shading`` equals
    ``E max(0, n . s) / pi`` computed by hand, and the order-2 SH shading of the same sun is its
    band-limited version: within 0.1 E/pi of it everywhere (the known ringing) but not equal."""
    import math

    from physrelight import image_model, sh

    rng = np.random.default_rng(7)
    for _ in range(5):
        s = rng.normal(size=3)
        s /= np.linalg.norm(s)
        e = rng.uniform(0.5, 3.0, 3)
        d, e2 = sh.sun_of(sh.project_sun(s, e))
        np.testing.assert_allclose(d, s, atol=1e-6)
        np.testing.assert_allclose(e2, e, rtol=1e-6)
    n = torch.nn.functional.normalize(torch.randn(1, 3, 16, 16, generator=torch.Generator().manual_seed(1),
                                                  dtype=torch.float64), dim=1)
    n[..., :2, :] = 0.0  # no surface
    sun = torch.from_numpy(sh.project_sun(s, e))
    got = image_model.sun_shading(n, sun)
    cos = (n * torch.from_numpy(s)[None, :, None, None]).sum(1, keepdim=True).clamp_min(0)
    torch.testing.assert_close(got, cos * torch.from_numpy(e)[None, :, None, None] / math.pi)
    assert float(got[..., :2, :].abs().max()) == 0.0
    band_limited = image_model.shading(n, sun)
    gap = (band_limited - got)[..., 2:, :].abs() / torch.from_numpy(e / math.pi)[None, :, None, None]
    assert 0.01 < float(gap.max()) < 0.1


def test_quotient_with_the_sun_exact_returns_the_photo_at_its_own_lighting_and_is_scale_free() -> None:
    """With ``sun_cosine`` the quotient still gives the photo back bit for bit when relit to its own
    lighting (with or without its shadow), is invariant to the albedo/lighting scale, and a lighting
    without a sun (zero sun SH) gives exactly the plain quotient."""
    from physrelight import sh

    g = torch.Generator().manual_seed(3)
    photo = torch.rand(1, 3, 12, 12, generator=g)
    n = torch.nn.functional.normalize(torch.randn(1, 3, 12, 12, generator=g), dim=1)
    sun = torch.from_numpy(sh.project_sun(np.array([0.3, 0.8, 0.52]) / np.linalg.norm([0.3, 0.8, 0.52]),
                                          np.array([2.0, 1.8, 1.5]))).float()[None]
    L = sun + torch.rand(1, 9, 3, generator=g) * 0.2
    L[:, 0] += 0.5
    v = (torch.rand(1, 1, 12, 12, generator=g) > 0.3).float()
    assert torch.equal(quotient.quotient_relight(photo, n, L, L, source_sun=sun, target_sun=sun, sun_cosine=True),
                       photo)
    assert torch.equal(quotient.quotient_relight(photo, n, L, L, source_shadow=v, target_shadow=v, source_sun=sun,
                                                 target_sun=sun, sun_cosine=True), photo)
    Lt = torch.rand(1, 9, 3, generator=g) * 0.3
    Lt[:, 0] += 0.6
    a = quotient.quotient_relight(photo, n, L, Lt + sun, source_sun=sun, target_sun=sun, sun_cosine=True)
    b = quotient.quotient_relight(photo, n, 3 * L, 3 * (Lt + sun), source_sun=3 * sun, target_sun=3 * sun,
                                  sun_cosine=True)
    torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-7)
    zero = torch.zeros_like(sun)
    torch.testing.assert_close(quotient.quotient_relight(photo, n, L, Lt, source_sun=zero, target_sun=zero,
                                                         sun_cosine=True),
                               quotient.quotient_relight(photo, n, L, Lt), rtol=1e-6, atol=1e-7)
