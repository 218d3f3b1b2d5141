"""Specification of physrelight.sky_mask, the sky mask's classical processing: the band round the boundary decided by
colour at full resolution, the sky grown by colour into a lattice's gaps, the smoothness test's roughness with the
photo's noise taken out (moved from tests/learned/test_relight_real.py with the functions, issue 41)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from physrelight import colour
from physrelight.full_resolution import resize_short_side
from physrelight.guided_filter import box_filter
from physrelight.sky_mask import (VARIANCE_FLOOR, _boundary_band, _dilate, _local_gaussian_nll, _local_gaussian_nll_at,
                                   _local_mean, _roughness, grow_sky_by_colour, label_components, log_noise_sigma,
                                   refine_sky_boundary,
                                   resized_noise_roughness, sky_roughness)


def test_01_a_lattice_against_the_sky_is_decided_at_full_resolution() -> None:
    """A 2-px dark pole in a smooth sky: the working-resolution mask blurs it away, the colour
    refinement of the band round the boundary gives it back to the foreground to the pixel."""
    H, W = 64, 96
    img = torch.ones(1, 3, H, W) * torch.tensor([0.3, 0.5, 0.9])[None, :, None, None]
    img[..., 40:, :] = torch.tensor([0.2, 0.25, 0.1])[None, :, None, None]  # ground
    img[..., :40, 50:52] = 0.02  # the pole
    coarse = torch.zeros(1, 1, H, W, dtype=torch.bool)
    coarse[..., :36, :] = True
    coarse[..., :36, 46:56] = False  # the working mask: a fat blob round the pole, the horizon 4 px high
    got = refine_sky_boundary(coarse, img, band=6)[0, 0]
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[:40] = True
    truth[:40, 50:52] = False
    assert bool((got == truth).all())


def test_02_a_textured_foreground_keeps_its_outliers_against_a_smooth_sky() -> None:
    """Foreground texels between the sky's colour and the foreground's mean but well inside the
    foreground's spread (a pale leaf in a varied canopy): the Gaussian band ('gauss', the default)
    keeps them foreground because the sky's variance is small; the nearest mean ('local') hands
    them to the sky. Both keep the step horizon."""
    H, W = 64, 96
    g = torch.Generator().manual_seed(0)
    sky_c = torch.tensor([0.3, 0.5, 0.9])
    img = torch.ones(1, 3, H, W) * sky_c[None, :, None, None]
    fg = torch.tensor([0.08, 0.12, 0.05])
    # a canopy whose log colour varies by +-1 (a factor e) about its mean, every channel together
    tex = torch.exp(torch.empty(1, 1, H - 30, W).uniform_(-1.0, 1.0, generator=g))
    img[..., 30:, :] = fg[None, :, None, None] * tex
    pale = torch.zeros(H, W, dtype=torch.bool)
    pale[33:35, 10:90:6] = True  # pale texels: log colour nearer the sky's mean than the canopy's mean
    img[0, :, pale] = (fg * torch.exp(torch.tensor(1.6)))[:, None].clamp(max=1.0) * torch.tensor([1.0, 1.4, 2.6])[:, None]
    coarse = torch.zeros(1, 1, H, W, dtype=torch.bool)
    coarse[..., :34, :] = True  # the working mask's horizon 4 px low
    x = torch.log(img.clamp_min(1e-4))[0]
    mu_sky, mu_fg = x[:, :20].mean((1, 2)), x[:, 40:].mean((1, 2))
    d_sky = ((x[:, pale] - mu_sky[:, None]) ** 2).sum(0)
    d_fg = ((x[:, pale] - mu_fg[:, None]) ** 2).sum(0)
    assert bool((d_sky < d_fg).all())  # the case the nearest mean gets wrong
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[:30] = True
    local = refine_sky_boundary(coarse, img, band=6, refine="local")[0, 0]
    gauss = refine_sky_boundary(coarse, img, band=6, refine="gauss")[0, 0]
    assert bool(local[pale].all())  # the old rule calls every pale texel sky
    assert not bool(gauss[pale].any())
    assert bool((gauss[:30] == truth[:30]).all())
    assert float((gauss != truth).float().mean()) < float((local != truth).float().mean())


@pytest.mark.parametrize("min_share, kept", [(None, True), (0.0, False)])
def test_03_an_object_narrower_than_the_band_is_not_decided_by_a_few_strangers(min_share, kept) -> None:
    """A cream pole 10 px wide against a blue sky, the band 8 px: every pole pixel is in the band and the pole
    has no sure pixels of its own. The only sure foreground within the window is the small core of a dark
    box beside it; the photo's foreground as a whole (a varied town) has the pole's colours in its spread.
    With the default :data:`MIN_SURE_SHARE` that starved local Gaussian gives way to the whole foreground's and
    the pole stays; with 0 (before study 44) the box's narrow Gaussian puts the pole thousands of nats away and
    the band hands the pole to the sky (what happened to rocket.jpg's body)."""
    H, W = 128, 128
    g = torch.Generator().manual_seed(0)
    img = torch.ones(1, 3, H, W) * torch.tensor([0.05, 0.1, 0.3])[None, :, None, None]
    img = img * torch.linspace(0.8, 1.2, H)[None, None, :, None]  # a smooth sky gradient
    img[..., 100:, :] = torch.exp(torch.empty(1, 3, H - 100, W).uniform_(-2.5, 0.0, generator=g))  # the town
    img[..., 30:60, 58:82] = 0.02  # a dark box in the sky, 8 px of sky from the pole
    img[..., 20:100, 40:50] = torch.tensor([0.6, 0.55, 0.45])[None, :, None, None]  # the pole, on the ground
    truth = torch.zeros(1, 1, H, W, dtype=torch.bool)
    truth[..., :100, :] = True
    truth[..., 30:60, 58:82] = False
    truth[..., 20:100, 40:50] = False
    got = refine_sky_boundary(truth, img, band=8, min_share=min_share)[0, 0]
    pole = torch.zeros(H, W, dtype=torch.bool)
    pole[20:100, 40:50] = True
    if kept:
        assert not bool(got[pole].any())
        assert bool(got[:100][truth[0, 0, :100]].all())  # and the sky stays sky
    else:
        assert float(got[pole].float().mean()) > 0.2


@pytest.mark.parametrize("band", [3, 16, 17, 40, 400])
def test_04_the_bands_one_pass_forms_equal_their_definitions(band) -> None:
    """The colour band's speed-ups give the same bits: its pixels from one window count of the sky (wide bands)
    equal the two dilations, and its Gaussians from one box filter of the weight and both moments equal
    :func:`_local_mean` of ``x`` and of ``x^2`` (the gate at ``MIN_SURE_SHARE`` and at 0)."""
    g = torch.Generator().manual_seed(band)
    h, w = 90, 130
    blobs = F.interpolate(torch.rand(1, 1, 9, 13, generator=g), size=(h, w), mode="bilinear") > 0.5
    assert torch.equal(_boundary_band(blobs, band), _dilate(blobs, band) & _dilate(~blobs, band))
    x = torch.randn(1, 3, h, w, generator=g)
    wt = (blobs & (torch.rand(1, 1, h, w, generator=g) < 0.7)).float()
    for share in (0.0, 0.125):
        mu = _local_mean(wt, x, band, share)
        var = (_local_mean(wt, x * x, band, share) - mu * mu).clamp_min(0) + VARIANCE_FLOOR
        want = ((x - mu) ** 2 / var + torch.log(var)).sum(1, keepdim=True)
        assert torch.equal(_local_gaussian_nll(x, wt, band, share), want)


def _lattice_scene(H: int = 64, W: int = 96):
    """A noisy sky whose log colour is a quadratic of the position, a lattice tower (2-px dark bars
    every 6 px) in columns 30-65 from the top down to the ground at row 48, and a textured ground.
    Returns ``(image (1, 3, H, W), coarse mask, true sky, bars)``: the coarse mask calls the whole
    tower and the ground foreground, as a working-resolution segmenter does."""
    g = torch.Generator().manual_seed(1)
    v = torch.linspace(-0.5, 0.5, H)[:, None].expand(H, W)
    u = torch.linspace(-0.7, 0.7, W)[None, :].expand(H, W)
    base = torch.log(torch.tensor([0.25, 0.45, 0.9]))[:, None, None]
    logsky = base + (0.6 * v + 0.2 * u * u)[None] + 0.01 * torch.randn(3, H, W, generator=g)
    img = torch.exp(logsky)[None]
    ground = torch.exp(torch.empty(1, 1, H - 48, W).uniform_(-0.5, 0.5, generator=g))
    img[..., 48:, :] = torch.tensor([0.15, 0.18, 0.08])[None, :, None, None] * ground
    bars = torch.zeros(H, W, dtype=torch.bool)
    cols, rows = torch.arange(W), torch.arange(H)
    in_tower = (cols >= 30) & (cols < 66)
    bars[:48] = in_tower[None, :] & ((((cols - 30) % 6) < 2)[None, :] | (((rows[:48] % 6) < 2)[:, None]))
    img[0, :, bars] = 0.03
    truth = torch.zeros(H, W, dtype=torch.bool)
    truth[:48] = True
    truth &= ~bars
    coarse = truth.clone()
    coarse[:, 30:66] = False
    return img, coarse[None, None], truth, bars


def test_05_the_sky_inside_a_lattice_is_grown_back_by_its_colour() -> None:
    """Growth by the smooth sky-colour model (the opt-in ``relight --sky-grow``) finds the sky
    between a lattice's bars that the coarse mask calls solid, and adds no bar or ground pixel."""
    img, coarse, truth, bars = _lattice_scene()
    got = grow_sky_by_colour(coarse, img, reach=40, max_spread=0.1)[0, 0]
    holes = truth & ~coarse[0, 0]
    assert bool(holes.any())
    assert float(got[holes].float().mean()) > 0.99
    assert not bool(got[bars].any()) and not bool(got[48:].any())
    assert bool(got[coarse[0, 0]].all())  # nothing is removed
    assert torch.equal(grow_sky_by_colour(coarse, img, reach=0), coarse)
    # a reach shorter than the distance to the tower's middle leaves its middle alone
    short = grow_sky_by_colour(coarse, img, reach=6)[0, 0]
    assert not bool(short[holes & (torch.arange(96) >= 40)[None, :] & (torch.arange(96) < 56)[None, :]].any())


def test_06_the_growth_neither_extrapolates_the_sky_nor_trusts_a_mixed_mask() -> None:
    """(a) A ground whose colour is the sky's gradient carried on below the horizon is added when the
    sky model is extrapolated, and not when it is clamped to the fitted pixels (the default).
    (b) A mask that already holds a dark façade gives the model a wide spread: with ``max_spread``
    nothing is added. Bad arguments are refused by name."""
    H, W = 64, 96
    g = torch.Generator().manual_seed(2)
    v = torch.linspace(-0.5, 0.5, H)[:, None, None].expand(H, W, 1).permute(2, 0, 1)
    logsky = torch.log(torch.tensor([0.25, 0.45, 0.9]))[:, None, None] - 2.0 * v  # brighter toward the horizon
    img = torch.exp(logsky + 0.01 * torch.randn(3, H, W, generator=g))[None]
    img[..., 30:44, :] = 0.03  # a dark treeline
    img[..., 44:, :] *= torch.exp(torch.empty(1, 1, H - 44, W).uniform_(-0.4, 0.4, generator=g))  # textured ground
    sky = torch.zeros(1, 1, H, W, dtype=torch.bool)
    sky[..., :30, :] = True
    loose = grow_sky_by_colour(sky, img, reach=40, clamp=False)[0, 0]
    tight = grow_sky_by_colour(sky, img, reach=40)[0, 0]
    assert float(loose[44:].float().mean()) > 0.1  # the ground texels within the gate: about a sixth
    assert not bool(tight[30:].any())
    img2, coarse, truth, bars = _lattice_scene()
    mixed = coarse.clone()
    mixed[..., :40, 66:90] = True  # a dark façade taken for sky
    img2[..., :40, 66:90] = torch.tensor([0.05, 0.04, 0.03])[None, :, None, None]
    assert torch.equal(grow_sky_by_colour(mixed, img2, reach=40, max_spread=0.1), mixed)
    for kw, word in ((dict(reach=-1), "reach"), (dict(reach=4, chi2=0.0), "chi2"), (dict(reach=4, order=3), "order")):
        with pytest.raises(ValueError, match=word):
            grow_sky_by_colour(coarse, img2, **kw)
    with pytest.raises(ValueError, match="image"):
        grow_sky_by_colour(coarse, img2[..., :10, :], reach=4)


def test_07_the_growths_local_gaussian_at_its_candidates_is_the_whole_images() -> None:
    """The growth reads the local Gaussian of the non-sky pixels only at its candidates, from summed-area tables
    (``_local_gaussian_nll_at``): equal to the whole-image box-filter version (``_local_gaussian_nll``) at every
    pixel, for windows narrower and wider than the image, near its edges and where no weighted pixel is near."""
    g = torch.Generator().manual_seed(3)
    for h, w, r, density in ((40, 60, 3, 0.4), (64, 96, 17, 0.4), (120, 80, 40, 0.05), (50, 50, 200, 0.4),
                             (30, 70, 2, 0.01)):
        x = torch.randn(1, 3, h, w, generator=g, dtype=torch.float64)
        wt = (torch.rand(1, 1, h, w, generator=g) < density).double()
        full = _local_gaussian_nll(x, wt, r)[0, 0].flatten()
        at = _local_gaussian_nll_at(x, wt, r, torch.arange(h * w))
        torch.testing.assert_close(at, full, rtol=1e-10, atol=1e-10)
        some = torch.randperm(h * w, generator=g)[:17]
        torch.testing.assert_close(_local_gaussian_nll_at(x, wt, r, some), full[some], rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("display", [0.15, 0.5, 0.9])
def test_08_the_smoothness_tests_roughness_takes_the_noise_out(display) -> None:
    """On a flat patch of display value ``display`` with white display noise (sd 0.02), the 3 x 3 roughness of log
    luminance is the noise, brought to log luminance by the display curve's slope there (a z-test of its mean
    square against 8/9 of the predicted variance), and :func:`sky_roughness` takes it out: its median is 0. A
    textured patch beside a noiseless flat one keeps its roughness."""
    g = torch.Generator().manual_seed(int(display * 100))
    d = (display + 0.02 * torch.randn(96, 96, generator=g)).clamp(0, 1)
    lum = colour.from_ldr(d)
    s = log_noise_sigma(lum)
    y = float(colour.from_ldr(torch.tensor(display)))
    step = colour.to_ldr(torch.tensor(y * 1.001)) - colour.to_ldr(torch.tensor(y / 1.001))
    dlog_ddisplay = 2 * math.log(1.001) / float(step)
    sigma_log = 0.02 * dlog_ddisplay  # the display noise in log luminance at this brightness
    assert abs(float(s.median()) / sigma_log - 1.0) < 0.15
    r2 = _roughness(lum)[1:-1, 1:-1] ** 2  # interior windows: 9 pixels each
    expected = 8.0 / 9.0 * sigma_log ** 2
    # windows overlap: use every third one in each direction (independent), about 1000 of them
    sample = r2[::3, ::3].flatten().double()
    z = (float(sample.mean()) - expected) / (float(sample.std()) / math.sqrt(sample.numel()))
    assert abs(z) < 4.0
    assert float(sky_roughness(lum).median()) == 0.0
    assert float(sky_roughness(lum, noise_aware=False).median()) > 0.5 * math.sqrt(expected)
    tex = torch.ones(96, 96) * 0.5
    tex[:, 48:] = torch.exp(torch.empty(96, 48).uniform_(-1.0, 1.0, generator=g)) * 0.2
    assert torch.allclose(sky_roughness(tex)[:, 50:], _roughness(tex)[:, 50:])


@pytest.mark.parametrize("size, working", [((96, 96), (96, 96)), ((96, 128), (24, 32)), ((120, 180), (40, 60)),
                                           ((80, 120), (128, 192)), ((100, 150), (128, 192))])
def test_09_the_noise_roughness_after_resizing_is_the_resized_noises(size, working) -> None:
    """:func:`resized_noise_roughness` against brute force: fresh white noise (another seed, several draws) resized
    as the segmenter's resizing does, its mean 3 x 3 variance within 5 %. Unresized it is 8/9, and
    area-shrunk by an integer factor f it is 8/9 / f^2 (independent means of f^2 samples), exactly as stated."""
    gain = resized_noise_roughness(size, working)
    g = torch.Generator().manual_seed(11)
    draws = []
    for _ in range(8):
        y = resize_short_side(torch.randn(1, 1, *size, generator=g, dtype=torch.float64), min(working))
        assert tuple(y.shape[-2:]) == working
        m = box_filter(y, 1)
        draws.append(float((box_filter(y * y, 1) - m * m)[0, 0, 1:-1, 1:-1].mean()))
    assert abs(gain / float(np.mean(draws)) - 1.0) < 0.05
    if size == working:
        assert gain == 8.0 / 9.0
    elif size[0] % working[0] == 0 and size[0] // working[0] == size[1] // working[1]:
        f = size[0] // working[0]
        assert abs(gain / (8.0 / 9.0 / f ** 2) - 1.0) < 0.05


def _labels_by_max_pooling(mask: torch.Tensor) -> torch.Tensor:
    """The labelling :func:`label_components` replaced, kept as the reference: every mask pixel starts with its flat
    index + 1 and takes the largest label of its 3 x 3 neighbourhood on the mask until nothing changes (up to
    ``H * W`` passes)."""
    h, w = mask.shape
    lab = torch.where(mask, torch.arange(1, h * w + 1, dtype=torch.float64).reshape(h, w),
                      torch.zeros(h, w, dtype=torch.float64))
    m = mask.to(torch.float64)
    for _ in range(h * w):
        new = F.max_pool2d(lab[None, None], 3, stride=1, padding=1)[0, 0] * m
        if torch.equal(new, lab):
            break
        lab = new
    return lab.to(torch.int64)


def _diagonal_only() -> torch.Tensor:
    """Components joined through corners only: a staircase of single pixels, a V and a checkerboard patch."""
    m = torch.zeros(12, 15, dtype=torch.bool)
    for i in range(10):
        m[i + 1, i + 2] = True  # a staircase of single pixels
    m[0, 12] = m[1, 13] = m[0, 14] = True  # a V
    m[8:12:2, 0:6:2] = True  # a checkerboard patch: every pixel touches the next through a corner
    m[9:12:2, 1:6:2] = True
    return m


@pytest.mark.parametrize("shape, density", [((1, 1), 1.0), ((1, 40), 0.6), ((40, 1), 0.6), ((2, 2), 0.5),
                                            ((17, 23), 0.4), ((33, 9), 0.55), ((64, 96), 0.5), ((48, 80), 0.62)])
def test_10_the_one_pass_labels_are_the_max_pooled_ones(shape, density) -> None:
    """:func:`label_components` (``scipy.ndimage.label``, 8-connected, then each component named by its largest flat
    index + 1) gives exactly the labels of the max-label propagation it replaced: on random masks (several seeds, at
    the percolation threshold of 8-connectivity, where components are long and branched), single rows and columns
    and components joined through corners only."""
    g = torch.Generator().manual_seed(shape[0] * 1000 + shape[1])
    masks = [torch.rand(*shape, generator=g) < density for _ in range(3)]
    masks += [torch.zeros(shape, dtype=torch.bool), torch.ones(shape, dtype=torch.bool)]
    for m in masks:
        got = label_components(m)
        assert got.dtype == torch.int64 and got.shape == m.shape
        assert torch.equal(got, _labels_by_max_pooling(m))
    diag = _diagonal_only()
    got = label_components(diag)
    assert torch.equal(got, _labels_by_max_pooling(diag))
    assert got[1, 2] == got[10, 11] == 10 * 15 + 11 + 1  # the staircase is one component, named by its last pixel
    assert got[0, 12] == got[1, 13] == got[0, 14] == 1 * 15 + 13 + 1 and got[8, 0] == got[11, 5] == 11 * 15 + 5 + 1
    assert len(torch.unique(got)) == 4  # the three components and the background


def test_11_labelling_refuses_a_mask_that_is_not_a_2d_bool_tensor() -> None:
    for bad in (torch.zeros(1, 4, 4, dtype=torch.bool), torch.zeros(4, 4), torch.zeros(4, 4).numpy() > 0):
        with pytest.raises(ValueError, match="mask must be a bool tensor of shape"):
            label_components(bad)


def _sky_over_texture(seed: int = 0, h: int = 100, w: int = 100) -> torch.Tensor:
    """``(3, h, w)`` linear: a brown ground textured over a stop, for a smooth blue sky to be put on."""
    g = torch.Generator().manual_seed(seed)
    return torch.tensor([0.30, 0.25, 0.18])[:, None, None] * torch.exp(torch.rand(1, h, w, generator=g) - 0.5)


SKY_BLUE = torch.tensor([0.40, 0.55, 0.90])[:, None, None]


@pytest.mark.parametrize("columns, kept", [(12, True), (15, True), (8, False), (5, False)])
def test_12_a_sky_of_one_percent_of_the_photo_is_enough(columns: int, kept: bool) -> None:
    """A smooth blue patch at the top of a textured 100 x 100 photo is a sky from 1 % of the photo on
    (:data:`MIN_SKY_FRACTION`): 1.2 % and 1.5 % are kept, 0.8 % and 0.5 % refused with the share in the reason."""
    from physrelight import sky_mask as ss

    mask = torch.zeros(100, 100, dtype=torch.bool)
    mask[:10, 20:20 + columns] = True
    sky, why = ss.plausible_sky(mask, torch.where(mask, SKY_BLUE, _sky_over_texture()))
    assert bool(sky.any()) == kept and (why == "") == kept, why
    if kept:
        assert torch.equal(sky, mask)
    else:
        assert why == f"the sky found covers {columns / 10:.1f} % of the photo"


@pytest.mark.parametrize("brightness, kept", [(0.35, False), (0.45, False), (0.55, True), (0.8, True)])
def test_13_sky_between_towers_is_kept_when_half_as_bright_and_as_blue(brightness: float, kept: bool) -> None:
    """A sky patch that does not touch the top (sky seen between towers) is kept when its median luminance is at
    least half the top sky's (and it is as blue): at 0.55 and 0.8 of it, not at 0.45 or 0.35. The top sky is
    kept either way."""
    from physrelight import sky_mask as ss

    top = torch.zeros(100, 100, dtype=torch.bool)
    top[:20] = True
    inner = torch.zeros_like(top)
    inner[40:60, 40:60] = True
    image = torch.where(inner, brightness * SKY_BLUE, torch.where(top, SKY_BLUE, _sky_over_texture()))
    sky, why = ss.plausible_sky(top | inner, image)
    assert why == "" and torch.equal(sky, top | inner if kept else top)


@pytest.mark.parametrize("r", [17, 40, 129, 400])
def test_14_the_wide_dilation_by_running_maxima_is_the_window_counts(r: int) -> None:
    """A wide dilation and band (``r`` > 16) from scipy's running maximum and minimum give the same bits as the
    window count of summed-area tables they replaced (``box_filter`` of the mask in float64 > 0, and between 0 and
    1 for the band), windows cut at the border, on blobs, a single pixel and an empty mask."""
    from physrelight.guided_filter import box_filter

    g = torch.Generator().manual_seed(r)
    h, w = 150, 230
    blobs = F.interpolate(torch.rand(1, 1, 7, 11, generator=g), size=(h, w), mode="bilinear") > 0.6
    dot = torch.zeros(1, 1, h, w, dtype=torch.bool)
    dot[..., 3, w - 2] = True
    for m in (blobs, dot, torch.zeros_like(dot), ~dot):
        share = box_filter(m.to(torch.float64), min(r, max(h, w)))
        assert torch.equal(_dilate(m, r), share > 0)
        assert torch.equal(_boundary_band(m, r), (share > 0) & (share < 1))


def test_15_monochrome_counts_every_strip_and_stops_only_past_the_share() -> None:
    """:func:`is_monochrome` reads the photo by strips of rows and stops once more than
    ``MONOCHROME_MAX_SHARE`` of the pixels are coloured; coloured pixels in the last strip alone count, and the
    verdict flips exactly where the share of coloured pixels passes the limit."""
    from physrelight import sky_mask

    h, w = 700, 300  # three strips, the last one short
    n = int(sky_mask.MONOCHROME_MAX_SHARE * h * w)  # 1050: the most coloured pixels of a monochrome photo
    for coloured, want in ((n, True), (n + 1, False)):
        img = torch.full((1, 3, h, w), 0.2)
        flat = img[0, 0].view(-1)
        flat[h * w - coloured:] = 0.6  # red, at the bottom of the photo only
        assert sky_mask.is_monochrome(img) is want
