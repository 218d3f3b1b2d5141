"""Specification of physrelight.filters: the one separable Gaussian blur of the library (the segmenter's camera
softening, SkyGAN's smoothed sky, SSIM's window), checked against scipy.ndimage."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight.filters import gaussian_blur, gaussian_kernel1d


@pytest.mark.parametrize("sigma, radius", [(0.3, 2), (1.0, None), (1.5, 5), (4.3, None), (12.0, None)])
def test_01_the_blur_is_scipys_gaussian_filter_with_nearest_border(sigma, radius) -> None:
    """Replicate border = scipy's ``mode="nearest"``; scipy's window is ``int(truncate sigma + 0.5)`` taps on each
    side, so ``truncate = radius / sigma`` gives the same window. Float64 agrees to 1e-12 (the sums' order alone),
    also on images narrower than the window."""
    ndimage = pytest.importorskip("scipy.ndimage")
    g = torch.Generator().manual_seed(0)
    r = max(1, int(3 * sigma)) if radius is None else radius
    for shape in ((2, 3, 37, 53), (1, 2, 5, 3)):
        x = torch.rand(*shape, generator=g, dtype=torch.float64)
        want = ndimage.gaussian_filter(x.numpy(), (0, 0, sigma, sigma), mode="nearest", truncate=r / sigma)
        np.testing.assert_allclose(gaussian_blur(x, sigma, radius).numpy(), want, rtol=0, atol=1e-12)


def test_02_the_valid_blur_is_the_interior_of_the_replicate_one() -> None:
    g = torch.Generator().manual_seed(1)
    x = torch.rand(2, 4, 30, 41, generator=g, dtype=torch.float64)
    valid = gaussian_blur(x, 1.5, 5, "valid")
    assert valid.shape == (2, 4, 20, 31)
    torch.testing.assert_close(valid, gaussian_blur(x, 1.5, 5)[..., 5:-5, 5:-5], rtol=0, atol=1e-15)


def test_03_the_kernel_is_a_normalised_symmetric_gaussian_and_a_point_spreads_into_its_outer_product() -> None:
    k = gaussian_kernel1d(1.7, 6)
    t = torch.arange(-6, 7, dtype=torch.float64)
    torch.testing.assert_close(k, torch.exp(-t ** 2 / (2 * 1.7 ** 2)) / torch.exp(-t ** 2 / (2 * 1.7 ** 2)).sum())
    assert math.isclose(float(k.sum()), 1.0, abs_tol=1e-15) and torch.equal(k, k.flip(0))
    assert gaussian_kernel1d(0.5).numel() == 3 and gaussian_kernel1d(2.0).numel() == 13  # max(1, int(3 sigma))
    point = torch.zeros(1, 1, 21, 21, dtype=torch.float64)
    point[..., 10, 10] = 1.0
    torch.testing.assert_close(gaussian_blur(point, 1.7, 6)[0, 0, 4:17, 4:17], k[:, None] * k[None, :],
                               rtol=0, atol=1e-16)
    flat = torch.full((1, 3, 9, 14), 0.37)
    torch.testing.assert_close(gaussian_blur(flat, 3.0), flat, rtol=0, atol=1e-6)  # a constant stays (float32)


@pytest.mark.parametrize("kwargs, word", [(dict(sigma=0.0), "sigma"), (dict(sigma=-1.0), "sigma"),
                                          (dict(sigma=math.nan), "sigma"), (dict(sigma=True), "sigma"),
                                          (dict(sigma=1.0, radius=-1), "radius"),
                                          (dict(sigma=1.0, radius=1.5), "radius"),
                                          (dict(sigma=1.0, border="reflect"), "border"),
                                          (dict(sigma=1.0, radius=8, border="valid"), "valid blur of radius 8")])
def test_04_bad_arguments_are_refused_by_name(kwargs, word) -> None:
    with pytest.raises(ValueError, match=word):
        gaussian_blur(torch.rand(1, 1, 12, 16), **kwargs)
    for bad in (torch.rand(12, 16), torch.ones(1, 1, 4, 4, dtype=torch.int64), np.ones((1, 1, 4, 4))):
        with pytest.raises(ValueError, match="x must be"):
            gaussian_blur(bad, 1.0)
