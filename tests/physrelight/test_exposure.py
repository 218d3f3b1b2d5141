"""Specification of the lighting's level (:mod:`physrelight.exposure`): a target is brought into a decomposition's
units by the ratio of DC luminances. (Moved from tests/learned/test_renderer.py with the functions, issue 41.)"""

from __future__ import annotations

import pytest
import torch

from physrelight.exposure import dc_luminance, exposure_scale, match_exposure


def test_01_exposure_matching_follows_the_protocol() -> None:
    target = torch.zeros(1, 9, 3)
    target[0, 0] = torch.tensor([2.0, 2.0, 2.0])
    est = torch.zeros(1, 9, 3)
    est[0, 0] = torch.tensor([0.5, 0.5, 0.5])
    given = torch.zeros(1, 9, 3)
    given[0, 0] = torch.tensor([1.0, 1.0, 1.0])
    torch.testing.assert_close(match_exposure(target, est, given), target * 0.5)  # est / given
    torch.testing.assert_close(match_exposure(target, est, None), target * 0.25)  # DC equal to est
    with pytest.raises(ValueError, match="DC luminance"):
        match_exposure(target, est, -given)


def test_02_the_scale_falls_back_on_the_prior_where_the_estimate_has_no_level() -> None:
    """An estimate without a positive DC luminance (below 1e-6 of the fallback's) takes the fallback's level; a
    positive one keeps its own; the DC luminance is the Rec. 709 weighting of the DC term."""
    target = torch.zeros(2, 9, 3)
    target[:, 0] = torch.tensor([1.0, 2.0, 3.0])
    est = torch.zeros(2, 9, 3)
    est[0, 0] = torch.tensor([0.5, 0.5, 0.5])  # photo 1's estimate is black
    prior = torch.zeros(1, 9, 3)
    prior[0, 0] = torch.tensor([0.8, 0.8, 0.8])
    lum = torch.tensor([0.2126, 0.7152, 0.0722])
    torch.testing.assert_close(dc_luminance(target), (target[:, 0] * lum).sum(-1))
    scale = exposure_scale(target, est, None, fallback=prior)
    torch.testing.assert_close(scale, torch.tensor([0.5, 0.8]) / dc_luminance(target))
    assert float(exposure_scale(target, est)[1]) == 0.0  # without a fallback the black estimate gives 0
    with pytest.raises(ValueError, match="DC luminance"):
        exposure_scale(-target, est)
