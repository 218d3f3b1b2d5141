"""The relit sky rendered over the sky mask's bounding box only (``Relighter._relight_tensors``): a view whose
principal point moves with the crop sees the same rays, so the box is the crop of the whole view."""

import math

import numpy as np
import pytest
import torch

from physrelight import data, panorama
from physrelight.sky_view import rendered_sky


@pytest.mark.parametrize("source, target, sky", [
    ("target", str(data.hdri("forest")), "clear"),  # an env map
    ("target", np.array([0.3, 0.5, -0.8]), "clear"),  # a sun's clear sky and its disc
    ("target", np.array([0.3, 0.5, -0.8]), "overcast"),
    ("fit", str(data.hdri("city")), "clear"),
])
def test_01_the_sky_over_its_box_is_the_crop_of_the_whole_view(source, target, sky) -> None:
    h, w, (r0, r1, c0, c1) = 120, 180, (5, 61, 37, 170)
    K = panorama.view_intrinsics(20.0, w, h)  # magnifies the maps: the B-spline lookup
    a = math.radians(10.0)
    T = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    whole = rendered_sky(source, target, K, T, h, w, sky, 30.0)
    K_box = K.copy()
    K_box[0, 2] -= c0
    K_box[1, 2] -= r0
    box = rendered_sky(source, target, K_box, T, r1 - r0, c1 - c0, sky, 30.0)
    want = whole[r0:r1, c0:c1]
    assert box.shape == want.shape
    torch.testing.assert_close(box, want, rtol=1e-5, atol=1e-6 * float(want.abs().max()))
