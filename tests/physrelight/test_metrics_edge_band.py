"""Specification of the halo metric: physrelight.metrics.depth_edges / edge_band / edge_band_l1."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import metrics as pm

H, W, EDGE = 12, 16, 8  # a depth step between columns EDGE - 1 and EDGE


def _step_scene(near: float = 2.0, far: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """``depth (H, W)``: near on the left, far from column EDGE; ``target (3, H, W)``: 0.2 | 0.8 at the same column."""
    depth = np.full((H, W), near)
    depth[:, EDGE:] = far
    target = np.full((3, H, W), 0.2)
    target[:, :, EDGE:] = 0.8
    return depth, target


def test_01_step_edge_marks_both_pixels_of_the_jump() -> None:
    depth, _ = _step_scene()
    e = pm.depth_edges(depth)
    assert e.dtype == bool and e.shape == (H, W)
    assert e[:, EDGE - 1].all() and e[:, EDGE].all()
    assert e.sum() == 2 * H


def test_02_band_is_2k_plus_2_wide_across_a_straight_edge() -> None:
    depth, _ = _step_scene()
    for k in (0, 1, 2, 3):
        band = pm.edge_band(depth, k)
        cols = np.flatnonzero(band.all(axis=0))
        assert list(cols) == list(range(EDGE - 1 - k, EDGE + 1 + k)), k
        assert band.sum() == (2 * k + 2) * H


def test_03_known_halo_gives_the_known_error() -> None:
    # A halo two pixels wide on the far (bright) side, 0.1 too dark in every channel:
    # in the k = 2 band (6 columns) it is 2 of 6 columns, so 0.1 * 2 / 6.
    depth, target = _step_scene()
    pred = target.copy()
    pred[:, :, EDGE:EDGE + 2] -= 0.1
    got = pm.edge_band_l1(pred, target, depth, k=2)
    assert got == pytest.approx(0.1 * 2 / 6, abs=1e-12)
    # the plain l1 dilutes the same halo over the whole image
    assert pm.l1(pred, target) == pytest.approx(0.1 * 2 / W, abs=1e-12)
    # a halo outside the band is not counted
    far = target.copy()
    far[:, :, -2:] -= 0.1
    assert pm.edge_band_l1(far, target, depth, k=2) == 0.0


def test_04_perfect_prediction_scores_zero() -> None:
    depth, target = _step_scene()
    assert pm.edge_band_l1(target, target, depth, k=2) == 0.0


def test_05_no_edge_gives_nan_and_mean_skips_it() -> None:
    flat = np.full((H, W), 5.0)
    _, target = _step_scene()
    pred = target + 0.05
    assert math.isnan(pm.edge_band_l1(pred, target, flat))
    # batch: one image with a step, one flat -> per image [value, nan]; the mean takes the first only
    depth, _ = _step_scene()
    d = np.stack([depth, flat])
    p, t = np.stack([pred, pred]), np.stack([target, target])
    per = pm.edge_band_l1(p, t, d, reduction="none")
    assert per.shape == (2,) and per[0] == pytest.approx(0.05) and math.isnan(per[1])
    assert pm.edge_band_l1(p, t, d) == pytest.approx(0.05)


def test_06_smooth_slope_below_threshold_is_no_edge() -> None:
    # a plane receding by 5 % a pixel (below the 0.1 threshold) has no edge; at threshold 0.04 it is all edge
    depth = np.tile(1.05 ** np.arange(W), (H, 1))
    assert not pm.depth_edges(depth).any()
    assert pm.depth_edges(depth, threshold=0.04).all()


def test_07_surface_next_to_sky_is_an_edge() -> None:
    depth = np.full((H, W), 3.0)
    depth[:4] = 0.0  # sky in the top four rows
    e = pm.depth_edges(depth)
    assert e[3].all() and e[4].all() and e.sum() == 2 * W


def test_08_mask_restricts_the_band() -> None:
    depth, target = _step_scene()
    pred = target.copy()
    pred[:, :, EDGE - 1] += 0.1  # error on the near side only
    near_side = np.zeros((H, W), bool)
    near_side[:, :EDGE] = True
    far_side = ~near_side
    assert pm.edge_band_l1(pred, target, depth, near_side, k=2) == pytest.approx(0.1 / 3)
    assert pm.edge_band_l1(pred, target, depth, far_side, k=2) == 0.0


def test_09_torch_in_torch_out_with_gradient() -> None:
    depth, target = _step_scene()
    pred = torch.tensor(target + 0.1, requires_grad=True)
    out = pm.edge_band_l1(pred[None], torch.tensor(target)[None], torch.tensor(depth)[None, None])
    assert isinstance(out, torch.Tensor) and out.ndim == 0
    out.backward()
    g = pred.grad
    assert (g[:, :, EDGE - 3:EDGE + 3] > 0).all() and (g[:, :, :EDGE - 3] == 0).all()


@pytest.mark.parametrize("bad, match", [
    (dict(depth=np.ones((H, W + 1))), "depth"),
    (dict(depth=-np.ones((H, W))), ">= 0"),
    (dict(depth=np.full((H, W), np.nan)), "depth"),
    (dict(k=-1), "k must be"),
    (dict(k=1.5), "k must be"),
    (dict(threshold=0.0), "threshold"),
    (dict(mask=np.full((H, W), 0.5)), "mask"),
])
def test_10_bad_inputs_are_refused(bad: dict, match: str) -> None:
    depth, target = _step_scene()
    args = dict(pred=target, target=target, depth=depth, mask=None, k=2, threshold=0.1)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        pm.edge_band_l1(**args)
