"""Specification of :mod:`physrelight.panorama`: pinhole views of a lat-long panorama against
analytic cases (constant map, one bright texel, a full turn, the camera-frame SH by brute
force, antialiasing convergence, the native width)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import camera, envmap, panorama, sh

from .conftest import HDRI_DIR


def _cam(fov: float, yaw: float, pitch: float, width: int = 64) -> tuple[np.ndarray, np.ndarray, int, int]:
    h = round(0.75 * width)
    return panorama.view_intrinsics(fov, width, h), panorama.level_camera(yaw, pitch), h, width


def test_01_a_view_of_a_constant_map_is_constant() -> None:
    env = np.ones((64, 128, 3)) * np.array([0.2, 1.5, 7.0])
    K, T, h, w = _cam(70.0, 123.0, 17.0)
    img = panorama.view(env, K, T, h, w, samples=3)
    assert img.shape == (h, w, 3)
    np.testing.assert_allclose(img, np.broadcast_to(env[0, 0], img.shape), rtol=1e-12)


@pytest.mark.parametrize("yaw,pitch,texel", [(0.0, 0.0, (64, 0)), (90.0, 10.0, (60, 32)), (217.0, -4.0, (70, 78)),
                                             (300.0, 19.0, (55, 107))])
def test_02_one_bright_texel_lights_the_pixel_its_direction_projects_to(yaw, pitch, texel) -> None:
    env = np.full((128, 256, 3), 1e-3)
    i, j = texel[0], 2 * texel[1]
    env[i, j] = 1e4
    K, T, h, w = _cam(60.0, yaw, pitch, width=96)
    d = envmap.directions(128, 256)[i, j]
    cam = T[:3, :3] @ d
    assert cam[2] < 0, "the test texel must lie in front of the camera"
    uv, _ = camera.project(cam.reshape(1, 3, 1), K)
    u, v = uv[0, :, 0]
    img = panorama.view(env, K, T, h, w, samples=4)
    r, c = np.unravel_index(np.argmax(img[..., 0]), img.shape[:2])
    assert abs((c + 0.5) - u) <= 1.0 and abs((r + 0.5) - v) <= 1.0, ((r, c), (v, u))
    assert img[r, c, 0] > 100 * np.median(img[..., 0])


def test_03_turning_the_yaw_by_360_degrees_changes_nothing() -> None:
    env = envmap.read(HDRI_DIR / "forest.exr")
    K, T, h, w = _cam(55.0, 41.0, 8.0)
    a = panorama.view(env, K, T, h, w, samples=2)
    b = panorama.view(env, K, panorama.level_camera(41.0 + 360.0, 8.0), h, w, samples=2)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("order", [2, 4])
def test_04_camera_frame_sh_is_the_panoramas_sh_rotated_by_the_views_camera(order) -> None:
    """Brute force: integrate the map against the camera-frame basis ``Y(R d)`` over its texels (a
    smooth map at 512 x 1024, where the texel quadrature is within 6e-6) and compare with the
    world SH turned by ``sh.rotation`` of the view's camera (what a crop records), to 1e-5 of the
    DC term. The transposed camera is off by 15 %."""
    H = 512
    d = envmap.directions(H, 2 * H)
    s = np.array([0.3, 0.5, -0.81]) / np.linalg.norm([0.3, 0.5, -0.81])
    f = 1 + 0.5 * d[..., 1] + 0.3 * d[..., 0] * d[..., 2] + 0.8 * np.maximum(0.0, d @ s) ** 8
    env = np.stack([f, 0.8 * f + 0.1 * d[..., 0], 1.2 * f], axis=-1)
    R = panorama.level_camera(37.0, 12.0)[:3, :3]
    brute = np.einsum("hwk,hwc,hw->kc", sh.basis(d @ R.T, order), env, envmap.solid_angles(H, 2 * H))
    got = np.asarray(sh.rotation(R, order)) @ sh.project_envmap(env, order)
    assert np.abs(got - brute).max() < 1e-5 * np.abs(brute[0]).max()
    wrong = np.asarray(sh.rotation(R.T, order)) @ sh.project_envmap(env, order)
    assert np.abs(wrong - brute).max() > 1e-2 * np.abs(brute[0]).max()


@pytest.mark.parametrize("name", ["city", "sunrise"])
def test_05_antialiasing_converges_4x_and_8x_supersampling_agree_within_1_percent(name) -> None:
    path = HDRI_DIR / f"{name}.exr" if name != "sunrise" else HDRI_DIR.parent / "hdri_heldout" / "sunrise.exr"
    env = torch.from_numpy(envmap.read(path))
    for fov, yaw, pitch in ((45.0, 190.0, 12.0), (75.0, 20.0, -3.0)):
        w = panorama.native_width(fov, 0.75, env.shape[1])
        K, T, h, _ = _cam(fov, yaw, pitch, width=w)
        a = panorama.view(env, K, T, h, w, samples=4)
        b = panorama.view(env, K, T, h, w, samples=8)
        assert float((a - b).abs().sum() / b.abs().sum()) < 0.01


@pytest.mark.parametrize("fov", [45.0, 60.0, 75.0, 120.0])
def test_06_native_width_never_upsamples_the_panorama(fov) -> None:
    """Every pixel (the corner's is the smallest) subtends at least one equatorial texel's solid
    angle at the native width, and one pixel more would break that."""
    W = 1024
    texel = (2 * math.pi / W) ** 2

    def corner_solid_angle(width: int) -> float:
        h = round(0.75 * width)
        f = (width / 2) / math.tan(math.radians(fov) / 2)
        x, y = width / 2 - 0.5, h / 2 - 0.5
        r = math.sqrt(x * x + y * y + f * f)
        return f / r**3  # solid angle of a unit pixel at (x, y): cos^3 / f^2

    w = panorama.native_width(fov, 0.75, W)
    assert corner_solid_angle(w) >= texel * 0.999
    assert corner_solid_angle(w + 2) < texel


def test_07_views_reject_bad_cameras_and_maps() -> None:
    env = np.ones((8, 16, 3))
    with pytest.raises(ValueError, match=r"179"):
        panorama.view_intrinsics(179.5, 64, 48)
    with pytest.raises(ValueError, match=r"pitch"):
        panorama.level_camera(0.0, 90.0)
    with pytest.raises(ValueError, match=r"2:1"):
        panorama.view(np.ones((8, 8, 3)), *_cam(60.0, 0.0, 0.0)[:2], 4, 4)
    bad = env.copy()
    bad[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match=r"NaN|finite"):
        panorama.view(bad, *_cam(60.0, 0.0, 0.0)[:2], 4, 4)
    with pytest.raises(ValueError, match=r"world_to_camera"):
        panorama.view(env, panorama.view_intrinsics(60.0, 4, 3), 2 * np.eye(3), 3, 4)
    with pytest.raises(ValueError, match=r"interpolation must be one of"):
        panorama.view(env, *_cam(60.0, 0.0, 0.0)[:2], 4, 4, interpolation="bicubic")


@pytest.mark.parametrize("fov, yaw, pitch", [(60.0, -20.0, 5.0), (90.0, 100.0, 60.0), (120.0, 33.0, 89.9),
                                             (90.0, 0.0, -89.99)])
def test_08_the_compiled_bspline_view_is_the_float64_lookup_to_float32_rounding(fov, yaw, pitch) -> None:
    """A float32 map seen one ray per pixel by the B-spline goes through one compiled loop (``_bspline_view``) instead
    of :func:`camera_rays` and :func:`physrelight.look_up`: against the same lookup made in float64 (map and rays)
    it is within float32 rounding everywhere, the pole and the texels beside it included (the float32 torch path
    rounds the rays first: near a pole ``acos`` magnifies that last bit, 0.3 relative at pitch -89.99 here)."""
    g = torch.Generator().manual_seed(8)
    env = torch.rand(32, 64, 3, generator=g, dtype=torch.float64) ** 4 * 50 + 0.01  # an HDR-like map
    K, R, h, w = _cam(fov, yaw, pitch, width=96)
    fast = panorama.view(env.float(), K, R, h, w, 1, interpolation="bspline")
    rays = panorama.camera_rays(K, R, h, w, 1)
    exact = panorama.look_up(env.float().double(), rays, "bspline")
    assert fast.dtype == torch.float32 and fast.shape == (h, w, 3)
    rel = ((fast.double() - exact).abs() / exact.abs()).max().item()
    assert rel < 2e-7  # float32's half ulp is 6e-8: the sum's rounding and the output's


def test_09_pixel_rays_are_camera_rays_to_the_last_bit_and_take_strips_of_rows() -> None:
    """One ray per pixel centre by a compiled loop: :func:`camera_rays` with ``samples=1`` within an ulp (their
    matrix products round differently), unit length, and a strip of rows is those rows of the whole image."""
    K, R, h, w = _cam(75.0, 130.0, 35.0, width=120)
    fast = panorama.pixel_rays(K, R, h, w)
    slow = panorama.camera_rays(K, R, h, w, 1)[..., 0, :]
    assert fast.shape == (h, w, 3) and fast.dtype == torch.float64
    assert (fast - slow).abs().max().item() <= 4.5e-16
    torch.testing.assert_close(fast.norm(dim=-1), torch.ones(h, w, dtype=torch.float64), rtol=0, atol=1e-15)
    assert torch.equal(panorama.pixel_rays(K, R, h, w, slice(20, 47)), fast[20:47])
    with pytest.raises(ValueError, match="K must"):
        panorama.pixel_rays(np.eye(2), R, h, w)
