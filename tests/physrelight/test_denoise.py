"""physrelight.denoise: the noise level read off the photo, and the denoise it sets (study 37)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight.denoise import denoise, noise_sigma


def _scene(h: int = 128, w: int = 128) -> torch.Tensor:
    """``(1, 3, h, w)`` a clean linear image: flat patches with step edges and linear ramps."""
    y, x = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    img = torch.full((3, h, w), 0.2, dtype=torch.float64)
    img[0] += 0.002 * x  # a ramp
    img[1] += 0.3 * (x >= w // 2 + 1)  # a vertical step off the 2 x 2 grid
    img[2] += 0.25 * (y >= h // 3)  # a horizontal step
    return img[None]


def test_01_an_affine_image_has_no_noise() -> None:
    """The finest diagonal Haar coefficient of an affine function is exactly zero."""
    y, x = torch.meshgrid(torch.arange(33, dtype=torch.float64), torch.arange(48, dtype=torch.float64), indexing="ij")
    img = torch.stack([0.1 + 0.01 * x, 0.3 - 0.004 * y, 0.2 + 0.003 * x + 0.002 * y])[None]
    assert torch.allclose(noise_sigma(img), torch.zeros(1, 3, dtype=torch.float64), atol=1e-15)


@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.05])
def test_02_the_estimate_recovers_gaussian_noise_through_edges(sigma: float) -> None:
    """White Gaussian noise on an image with step edges: the estimate is within 4 standard errors.

    The median of N |coefficients| has a standard error of about 1.166 sigma / sqrt(N) (the asymptotic
    variance of a sample median, pi / 2 sigma^2 / N for the half-normal scaled by 1 / 0.6745); N = 64^2
    here, so about 1.8 %. The edges touch under 2 % of the coefficients, a bias well inside the bound."""
    g = torch.Generator().manual_seed(7)
    clean = _scene()
    noisy = clean + sigma * torch.randn(clean.shape, generator=g, dtype=torch.float64)
    est = noise_sigma(noisy, block=None)
    se = 1.166 * sigma / math.sqrt(64 * 64)
    assert torch.all((est - sigma).abs() < 4 * se + 0.02 * sigma), (est, sigma)


@pytest.mark.parametrize("sigma", [0.002, 0.01, 0.05])
def test_02b_the_noise_floor_recovers_gaussian_noise_within_its_standard_error(sigma: float) -> None:
    """The noise floor (16-px tiles, their 10th percentile, divided by its shortfall under pure noise) on the
    same image: 64 tiles, each estimate with sd 1.166 sigma / 8; the sample quantile's sd is about
    ``sqrt(q (1 - q) / T) / phi(z_q)`` times that (3 % of sigma here). Within 4 of those, plus 2 % for the edges."""
    g = torch.Generator().manual_seed(7)
    clean = _scene()
    noisy = clean + sigma * torch.randn(clean.shape, generator=g, dtype=torch.float64)
    est = noise_sigma(noisy)
    q, tiles = 0.1, 64
    phi = math.exp(-0.5 * 1.2816 ** 2) / math.sqrt(2 * math.pi)
    sd = math.sqrt(q * (1 - q) / tiles) / phi * 1.166 / 8 * sigma
    assert torch.all((est - sigma).abs() < 4 * sd + 0.02 * sigma), (est, sigma)


def test_02c_texture_does_not_raise_the_noise_floor() -> None:
    """Half the tiles carry pixel-scale texture 5 times the noise (as foliage does): Donoho's estimate over the
    whole image reads it as noise, the noise floor still finds the noise in the flat tiles (within 15 %)."""
    g = torch.Generator().manual_seed(2)
    img = torch.full((1, 3, 128, 128), 0.3, dtype=torch.float64)
    img[..., :, 64:] += 0.05 * torch.randn(1, 3, 128, 64, generator=g, dtype=torch.float64)  # texture
    img += 0.01 * torch.randn(img.shape, generator=g, dtype=torch.float64)  # the noise
    whole, floor = noise_sigma(img, block=None), noise_sigma(img)
    assert torch.all(whole > 1.5 * 0.01), whole  # the texture read as noise: half again or more
    assert torch.all((floor - 0.01).abs() < 0.0015), floor


def test_02d_clipped_tiles_do_not_count() -> None:
    """A clipped sky (1.0 exactly, no noise left) over half the photo: the floor comes from the other tiles."""
    g = torch.Generator().manual_seed(4)
    img = (0.3 + 0.01 * torch.randn(1, 3, 128, 128, generator=g, dtype=torch.float64))
    img[..., :64, :] = 1.0
    assert torch.all((noise_sigma(img) - 0.01).abs() < 0.0015)
    assert torch.all(noise_sigma(img, block=None) < 0.005)  # the whole-image median sees the clipped half


def test_03_a_clean_image_comes_back_unchanged() -> None:
    """No noise (sigma 0 in every channel): the denoise is the identity, bit for bit."""
    clean = _scene().float()
    assert torch.equal(denoise(clean, 2, 3.0), clean)


def test_04_the_noise_goes_the_edges_stay() -> None:
    """On the noisy scene the error to the clean image falls 3x or more in the flat interiors, and each
    step keeps its contrast (the mean across the edge, 3 px either side) within the ridge's attenuation: a
    window centred on a step of height d has variance d^2 / 4 and slope ``a = (d^2/4) / (d^2/4 + eps)``, so it
    loses at most ``1 - a < 4 eps / d^2`` of the step (eps = (3 sigma)^2: 4 % for d = 0.3, 5.8 % for 0.25)."""
    g = torch.Generator().manual_seed(3)
    clean = _scene()
    noisy = clean + 0.01 * torch.randn(clean.shape, generator=g, dtype=torch.float64)
    out = denoise(noisy, 2, 3.0)
    h, w = clean.shape[-2:]
    interior = torch.ones(h, w, dtype=torch.bool)
    interior[:, w // 2 - 4: w // 2 + 6] = False
    interior[h // 3 - 5: h // 3 + 5, :] = False
    err_before = (noisy - clean).abs()[..., interior].mean()
    err_after = (out - clean).abs()[..., interior].mean()
    assert err_after < err_before / 3, (float(err_before), float(err_after))
    c = w // 2 + 1
    step_g = out[0, 1, :, c: c + 3].mean() - out[0, 1, :, c - 3: c].mean()
    r = h // 3
    step_b = out[0, 2, r: r + 3, :].mean() - out[0, 2, r - 3: r, :].mean()
    eps = (3.0 * 0.01) ** 2
    for step, d in ((step_g, 0.3), (step_b, 0.25)):
        assert 0.0 <= d - float(step) < 4 * eps / d**2 * d, (float(step), d)


def test_05_a_given_sigma_is_used_and_zero_means_untouched() -> None:
    g = torch.Generator().manual_seed(1)
    noisy = _scene().float() + 0.01 * torch.randn(1, 3, 128, 128, generator=g)
    out = denoise(noisy, 1, 2.0, sigma=torch.tensor([[0.0, 0.01, 0.0]]))
    assert torch.equal(out[:, 0], noisy[:, 0]) and torch.equal(out[:, 2], noisy[:, 2])
    assert not torch.equal(out[:, 1], noisy[:, 1])
    assert torch.equal(denoise(noisy, 1, 2.0, sigma=noise_sigma(noisy)), denoise(noisy, 1, 2.0))


@pytest.mark.parametrize("call, match", [
    (lambda: noise_sigma(torch.zeros(3, 8, 8)), "shape"),
    (lambda: noise_sigma(torch.zeros(1, 3, 1, 8)), "2 x 2"),
    (lambda: noise_sigma(torch.full((1, 3, 4, 4), float("nan"))), "NaN"),
    (lambda: noise_sigma(torch.zeros(1, 3, 8, 8), block=5), "block"),
    (lambda: noise_sigma(torch.zeros(1, 3, 8, 8), quantile=1.0), "quantile"),
    (lambda: denoise(torch.zeros(1, 3, 8, 8), 0), "radius"),
    (lambda: denoise(torch.zeros(1, 3, 8, 8), 1, 0.0), "strength"),
    (lambda: denoise(torch.zeros(1, 3, 8, 8), 1, 1.0, sigma=torch.zeros(3)), "sigma"),
    (lambda: denoise(torch.zeros(1, 3, 8, 8), 1, 1.0, sigma=-torch.ones(1, 3)), "sigma"),
])
def test_06_bad_input_is_refused_by_name(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()


def test_07_seeded_photo_noise_is_read_in_linear_units() -> None:
    """synth's photo model adds its noise in linear exposed units before the sRGB curve; the photo
    linearised again carries it at about that sigma where the curve is near linear's slope (mid-tones),
    so the estimate lands within 25 % of the noise drawn (8-bit quantisation and the curve's slope move it)."""
    from physrelight import colour
    from synth.photo import PhotoParams, make_photo

    radiance = np.full((96, 96, 3), 0.2, dtype=np.float64)
    radiance[:, 48:] = 0.35
    p = PhotoParams(ev=0.0, wb_gains=(1.0, 1.0, 1.0), curve="srgb", noise_sigma=0.01, jpeg_quality=None)
    u8 = make_photo(radiance, p, np.random.default_rng(0))
    lin = colour.from_ldr(torch.from_numpy(u8.astype(np.float32) / 255.0).permute(2, 0, 1)[None])
    est = noise_sigma(lin)
    assert torch.all((est - 0.01).abs() < 0.0025), est
