"""Specification of :mod:`physrelight.window_sums`: the compiled running sums give the summed-area path's numbers to
the bit (the sky mask's near-ties depend on them), and a box mean that is the brute-force mean."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from physrelight import guided_filter
from physrelight.guided_filter import _window_count, _window_sums, box_filter
from physrelight.window_sums import box_mean, summed_area_table


def _by_tables(x: torch.Tensor, radius: int) -> torch.Tensor:
    """The summed-area path in torch (the one off the CPU)."""
    h, w = x.shape[-2:]
    return _window_sums(_window_sums(x, radius, -2), radius, -1) / _window_count(h, w, radius, x.dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shape, radius", [((1, 1, 37, 53), 17), ((2, 3, 120, 300), 42), ((1, 7, 90, 61), 200),
                                           ((1, 1, 40, 1000), 33), ((1, 2, 301, 9), 150)])
def test_01_box_mean_is_the_summed_area_tables_numbers_to_the_bit(dtype, shape, radius) -> None:
    """Windows inside the image, windows wider than it (radius >= H or W), several planes, offset values (the running
    sums grow large, so their rounding to float32 matters)."""
    g = torch.Generator().manual_seed(radius)
    x = (torch.rand(*shape, generator=g, dtype=torch.float64) * 3 + 0.5).to(dtype)
    h, w = shape[-2:]
    got = box_mean(x, radius, _window_count(h, w, radius, dtype))
    assert got.dtype == dtype and got.shape == x.shape
    assert torch.equal(got, _by_tables(x, radius))
    assert torch.equal(box_filter(x, radius), got)  # box_filter's CPU path


def test_02_box_mean_is_the_brute_force_window_mean() -> None:
    """float64: every pixel's mean over its window cut at the border, summed directly."""
    g = torch.Generator().manual_seed(2)
    x = torch.rand(1, 2, 41, 57, generator=g, dtype=torch.float64)
    r = 18
    got = box_filter(x, r)
    pad = F.pad(x, (r, r, r, r))
    ones = F.pad(torch.ones_like(x[:, :1]), (r, r, r, r))
    k = 2 * r + 1
    direct = F.avg_pool2d(pad, k, stride=1) / F.avg_pool2d(ones, k, stride=1)
    torch.testing.assert_close(got, direct, rtol=1e-12, atol=1e-12)


def test_03_the_summed_area_table_is_the_running_sums_to_the_bit() -> None:
    g = torch.Generator().manual_seed(4)
    x = torch.rand(123, 77, generator=g, dtype=torch.float64) * 10 - 2
    assert torch.equal(summed_area_table(x), F.pad(x.cumsum(0).cumsum(1), (1, 0, 1, 0)))


def test_04_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="float32 or float64 CPU"):
        box_mean(torch.ones(1, 1, 4, 4, dtype=torch.float16), 2, torch.ones(1, 1, 4, 4, dtype=torch.float16))
    with pytest.raises(ValueError, match="count must be"):
        box_mean(torch.ones(1, 1, 4, 4), 2, torch.ones(1, 1, 4, 5))
    with pytest.raises(ValueError, match=r"\(H, W\) float64"):
        summed_area_table(torch.ones(4, 4))
    assert guided_filter.box_filter(torch.ones(1, 1, 50, 50), 20).eq(1).all()
