"""Specification of a level camera's pitch read from a photo (:mod:`physrelight.horizon`): from where the sky comes
down to (its lowest reach, the horizon), and from the world's vertical edges converging to the up direction's
vanishing point. (Moved from tests/learned/test_relight_real.py with the functions, issue 41.)"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physrelight import panorama
from physrelight.horizon import estimate_camera_pitch, estimate_pitch, pitch_from_verticals


def test_01_the_pitch_comes_from_where_the_sky_comes_down_to() -> None:
    H, W, fov = 120, 160, 60.0
    K = panorama.view_intrinsics(fov, W, H)
    for pitch in (-4.0, 0.0, 9.0):
        rays = panorama.camera_rays(K, panorama.level_camera(0.0, pitch), H, W, 1)[..., 0, :]
        sky = rays[..., 1] > 0  # an open horizon
        sky[:, 40:60] &= torch.arange(H)[:, None] < 30  # a building
        assert abs(estimate_pitch(sky, K) - pitch) < 0.6
    assert estimate_pitch(torch.zeros(H, W, dtype=torch.bool), K) == 0.0


def test_02_the_horizon_is_the_skys_lowest_reach() -> None:
    """A treeline hides the horizon in 95 % of the columns; the open 5 % give the pitch (study 32), where the
    old 90th percentile read the treeline."""
    H, W, fov, pitch = 120, 160, 60.0, 6.0
    K = panorama.view_intrinsics(fov, W, H)
    rays = panorama.camera_rays(K, panorama.level_camera(0.0, pitch), H, W, 1)[..., 0, :]
    sky = rays[..., 1] > 0
    sky[:, 8:] &= torch.arange(H)[:, None] < 50  # trees above the horizon, but for 8 open columns
    assert abs(estimate_pitch(sky, K) - pitch) < 0.6
    assert estimate_pitch(sky, K, quantile=0.9) < pitch - 2.0
    with pytest.raises(ValueError, match="quantile"):
        estimate_pitch(sky, K, quantile=1.5)


def test_03_vertical_edges_converge_to_the_pitch_they_are_seen_at() -> None:
    """World-vertical stripes (meridians of a panorama) seen through a level camera pitched by p converge to
    the up direction's vanishing point: ``pitch_from_verticals`` finds p within its 0.25 deg step and a half;
    a featureless photo has no verticals. ``estimate_camera_pitch`` keeps the sky's pitch when the
    vanishing point falls below it."""
    u = (np.arange(256) + 0.5) / 256
    env = np.repeat(np.where((np.floor(u * 24) % 2) == 0, 1.0, 0.2)[None, :, None], 128, 0)
    env = np.repeat(env, 3, -1).astype(np.float32)
    H, W, fov = 96, 128, 60.0
    K = panorama.view_intrinsics(fov, W, H)
    for pitch in (-8.0, 0.0, 12.0, 25.0):
        img = torch.as_tensor(panorama.view(torch.from_numpy(env), K, panorama.level_camera(10.0, pitch), H, W, 2))
        got = pitch_from_verticals(img.permute(2, 0, 1).float(), K)
        assert got is not None and abs(got - pitch) < 0.75, (pitch, got)
    assert pitch_from_verticals(torch.full((3, H, W), 0.3), K) is None
    sky = torch.zeros(H, W, dtype=torch.bool)
    sky[:60] = True  # a sky down to row 60: pitch about +6 deg, above the stripes' 0
    img = torch.as_tensor(panorama.view(torch.from_numpy(env), K, panorama.level_camera(10.0, 0.0), H, W, 2))
    assert estimate_camera_pitch(img.permute(2, 0, 1).float(), sky, K) == estimate_pitch(sky, K)
