"""Specification of the full-resolution transfer (:mod:`physrelight.full_resolution`): a relighting computed at a
working resolution comes back at the photo's own by the ratio ``relit / photo``, so detail finer than the working
resolution survives; black working pixels have no ratio and do not bleed into their lit neighbours.
(Moved from tests/learned/test_relighter.py with the functions, issue 41.)"""

from __future__ import annotations

import pytest
import torch

from physrelight.full_resolution import resize_short_side, transfer_to_full_resolution, working_resolution


def test_01_the_transfer_keeps_detail_through_a_smooth_relighting() -> None:
    g = torch.Generator().manual_seed(1)
    full = torch.rand(1, 3, 96, 128, generator=g) * 0.8 + 0.1  # per-pixel detail
    sky = torch.zeros(1, 1, 96, 128, dtype=torch.bool)
    small, small_sky = working_resolution(full, sky, 32)
    assert small.shape[-2:] == (32, 43) and small_sky.shape[-2:] == (32, 43)
    gain = torch.linspace(0.5, 2.0, 43)[None, None, None, :].expand(1, 3, 32, 43)  # a smooth relighting
    back = transfer_to_full_resolution(full, small, small * gain, guided=False)
    up_gain = torch.nn.functional.interpolate(gain, size=(96, 128), mode="bilinear", align_corners=False)
    torch.testing.assert_close(back, full * up_gain)
    # The edge-aware (default) transfer follows the photo's edges, not the grid: on a smooth gain over
    # random texture it stays within 1 % of the bilinear ratio, and a constant gain is kept exactly.
    guided = transfer_to_full_resolution(full, small, small * gain)
    assert float((guided - full * up_gain).abs().mean()) < 0.01 * float((full * up_gain).mean())
    torch.testing.assert_close(transfer_to_full_resolution(full, small, small * 1.7), full * 1.7)
    # A plain upsampling would have lost the detail: its error is far larger.
    naive = torch.nn.functional.interpolate(small * gain, size=(96, 128), mode="bilinear", align_corners=False)
    assert float((naive - full * up_gain).abs().mean()) > 20 * float((back - full * up_gain).abs().mean()) + 1e-3


@pytest.mark.parametrize("guided", [True, False])
def test_02_black_working_pixels_do_not_bleed_into_lit_neighbours(guided: bool) -> None:
    """A constant ratio next to a black corner stays that ratio on every lit pixel (1e-5): the black
    pixels' meaningless ratio is not upsampled into their neighbours (issue 25's study found lit pixels
    down to a ratio of 0.21 with the guided transfer and 1.06 with the bilinear one)."""
    g = torch.Generator().manual_seed(2)
    full = torch.rand(1, 3, 128, 128, generator=g) * 0.8 + 0.1
    full[..., :32, :32] = 0.0  # 8x8 black working pixels
    small, _ = working_resolution(full, torch.zeros(1, 1, 128, 128, dtype=torch.bool), 32)
    back = transfer_to_full_resolution(full, small, small * 1.7, guided=guided)
    lit = (torch.nn.functional.interpolate(small, size=(128, 128), mode="bilinear", align_corners=False) > 1e-3)
    torch.testing.assert_close(back[lit], (full * 1.7)[lit], rtol=1e-5, atol=1e-6)


def test_03_the_working_size_keeps_the_aspect_and_the_sky_goes_by_majority() -> None:
    """The short side becomes ``res`` and the long one is rounded (96 x 128 -> 32 x 43); shrinking averages the
    area (a 3 x 3 block's mean), enlarging is bilinear; a sky mask takes the majority of each working pixel's area;
    an image already at the size is returned itself."""
    x = torch.arange(2 * 1 * 6 * 9, dtype=torch.float64).reshape(2, 1, 6, 9)
    small = resize_short_side(x, 2)
    assert small.shape == (2, 1, 2, 3)
    torch.testing.assert_close(small[0, 0, 0, 0], x[0, 0, :3, :3].mean())
    assert resize_short_side(x, 6) is x
    big = resize_short_side(x, 12)
    torch.testing.assert_close(big, torch.nn.functional.interpolate(x, size=(12, 18), mode="bilinear",
                                                                    align_corners=False))
    image = torch.rand(1, 3, 6, 9, generator=torch.Generator().manual_seed(0))
    sky = torch.zeros(1, 1, 6, 9, dtype=torch.bool)
    sky[..., :2, :] = True  # 2 of each top block's 3 rows: a majority
    sky[..., 2:4, :3] = True  # the bottom-left block (rows 3-5) gets 1 sky row of 3: a minority
    small_image, small_sky = working_resolution(image, sky, 2)
    assert small_image.shape == (1, 3, 2, 3) and small_sky.dtype == torch.bool
    assert small_sky[0, 0].tolist() == [[True, True, True], [False, False, False]]
    same_image, same_sky = working_resolution(image, sky, 6)
    assert same_image is image and same_sky is sky
