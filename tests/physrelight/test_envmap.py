"""Specification of physrelight.envmap: layout, IO, brute-force irradiance, rotation, sun split."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import torch

from physrelight import envmap, rotations, sh

from .conftest import HDRI_DIR, HDRI_NAMES


def test_01_layout_follows_mitsubas_latlong_convention() -> None:
    h, w = 8, 16
    d = envmap.directions(h, w)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-15)
    np.testing.assert_allclose(d[0], np.broadcast_to([0, 1, 0], (w, 3)), atol=1e-15)  # row 0 = zenith
    np.testing.assert_allclose(d[-1], np.broadcast_to([0, -1, 0], (w, 3)), atol=1e-15)
    # Rows align-corners in theta, columns texel-centred in u = atan2(x, -z) / 2 pi.
    np.testing.assert_allclose(np.arccos(d[:, 0, 1]), np.pi * np.arange(h) / (h - 1), atol=1e-12)
    u = np.mod(np.arctan2(d[3, :, 0], -d[3, :, 2]) / (2 * np.pi), 1.0)
    np.testing.assert_allclose(u, (np.arange(w) + 0.5) / w, atol=1e-12)


def test_02_solid_angles_sum_to_4pi_and_integrate_the_interpolant() -> None:
    for h in (2, 3, 16, 513):
        assert abs(envmap.solid_angles(h, 2 * h).sum() - 4 * math.pi) < 1e-12
    # A map that is cos(theta) in the upper half-space: int = pi exactly for the
    # interpolated function up to O(dt^2).
    h = 256
    d = envmap.directions(h, 2 * h)
    env = np.repeat(np.clip(d[..., 1:2], 0, None), 3, axis=-1)
    total = (env[..., 0] * envmap.solid_angles(h, 2 * h)).sum()
    assert abs(total - math.pi) < 1e-4


def test_03_exr_round_trip_is_bit_exact_and_atomic(tmp_path) -> None:
    rng = np.random.default_rng(0)
    img = (rng.random((12, 24, 3)) * 100).astype(np.float32)
    path = tmp_path / "sub" / "map.exr"
    envmap.write(path, img)
    back = envmap.read(path)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, img)
    assert os.listdir(path.parent) == ["map.exr"]  # no temporary file left behind


def test_04_reading_clamps_dwa_noise_and_rejects_broken_files(tmp_path) -> None:
    forest = envmap.read(HDRI_DIR / "forest.exr")  # holds -2e-3 DWA ringing on disk
    assert forest.min() >= 0.0 and forest.shape == (512, 1024, 3)
    with pytest.raises(ValueError, match="does not exist"):
        envmap.read(tmp_path / "missing.exr")
    junk = tmp_path / "junk.exr"
    junk.write_bytes(b"not an exr at all")
    with pytest.raises(ValueError, match="cannot read"):
        envmap.read(junk)
    with pytest.raises(ValueError, match="non-finite"):
        envmap.write(tmp_path / "nan.exr", np.full((4, 8, 3), np.nan, dtype=np.float32))
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        envmap.write(tmp_path / "grey.exr", np.ones((4, 8), dtype=np.float32))


def test_05_sample_returns_texels_at_their_centres_and_is_continuous_across_the_seam() -> None:
    rng = np.random.default_rng(1)
    env = rng.random((16, 32, 3))
    d = envmap.directions(16, 32)
    np.testing.assert_allclose(envmap.sample(env, d[1:-1]), env[1:-1], atol=1e-12)
    # u = 0 lies half-way between the last and the first column.
    theta = np.pi * 7.5 / 15
    on_seam = np.array([0.0, math.cos(theta), -math.sin(theta)])
    expected = 0.25 * (env[7, -1] + env[7, 0] + env[8, -1] + env[8, 0])
    np.testing.assert_allclose(envmap.sample(env, on_seam), expected, atol=1e-12)


def test_06_brute_force_irradiance_of_analytic_skies() -> None:
    h = 512
    const = np.full((h, 2 * h, 3), 2.0)
    d = envmap.directions(h, 2 * h)
    upper = np.where(d[..., 1:2] > 0, 1.0, 0.0) * np.ones(3)
    n = np.array([[0, 1, 0], [0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
    # Uniform L: E = pi L for every normal. Upper hemisphere only: pi, 0, pi/2, pi/2.
    np.testing.assert_allclose(envmap.irradiance_reference(const, n), 2 * math.pi, rtol=2e-5)
    e = envmap.irradiance_reference(upper, n)[:, 0]
    np.testing.assert_allclose(e, [math.pi, 0.0, math.pi / 2, math.pi / 2], atol=2e-2)
    # Chunking does not change the result.
    np.testing.assert_allclose(envmap.irradiance_reference(upper, n, chunk_texels=1000),
                               envmap.irradiance_reference(upper, n), rtol=1e-12)


def test_07_rotated_map_has_rotated_sh() -> None:
    # Smooth map (order-4 band-limited plus a soft lobe): bilinear resampling error only.
    h = 256
    d = envmap.directions(h, 2 * h)
    lobe = np.exp(8 * (d @ np.array([0.6, 0.64, 0.48]) - 1))[..., None] * np.array([3.0, 2.0, 1.0])
    env = 0.2 + lobe
    R = rotations.random_rotation(5)
    got = sh.project_envmap(envmap.rotate(env, R), 4)
    want = sh.rotate(sh.project_envmap(env, 4), R)
    assert np.abs(got - want).max() < 2e-3 * np.abs(want).max()
    # The direction of the lobe's peak moves to R times it.
    peak = np.unravel_index(np.argmax(envmap.rotate(env, R)[..., 0]), (h, 2 * h))
    moved = R @ np.array([0.6, 0.64, 0.48])
    assert math.degrees(math.acos(np.clip(d[peak] @ moved, -1, 1))) < 1.0


def test_08_sun_split_recovers_a_synthetic_sun_and_conserves_energy() -> None:
    h = 512
    d = envmap.directions(h, 2 * h)
    w = envmap.solid_angles(h, 2 * h)
    sky = 0.3 + 0.5 * np.clip(d[..., 1:2], 0, None) * np.array([0.6, 0.8, 1.0])
    s = np.array([-0.5, 0.5, 0.7071])
    s /= np.linalg.norm(s)
    disk = (d @ s) >= math.cos(math.radians(0.8))
    e_sun = np.array([300.0, 280.0, 250.0])
    env = sky.copy()
    env[disk] += e_sun / w[disk].sum()
    split = envmap.split_sun(env)
    assert split.has_sun
    assert math.degrees(math.acos(np.clip(split.direction @ s, -1, 1))) < 0.3
    np.testing.assert_allclose(split.irradiance, e_sun, rtol=0.01)
    # Exact energy bookkeeping: sky + sun integrates to the original.
    total = (env * w[..., None]).sum(axis=(0, 1))
    np.testing.assert_allclose((split.sky * w[..., None]).sum(axis=(0, 1)) + split.irradiance, total, rtol=1e-6)
    np.testing.assert_allclose(split.sky[disk], sky[disk], rtol=0.02)


@pytest.mark.parametrize("name", HDRI_NAMES)
def test_09_sun_split_of_real_maps_keeps_irradiance(hdris, name: str) -> None:
    env = hdris[name]
    split = envmap.split_sun(env)
    assert split.has_sun == (name != "courtyard")  # the courtyard is overcast
    n = sh.fibonacci_sphere(200)
    direct = 0 if not split.has_sun else np.clip(n @ split.direction, 0, None)[:, None] * split.irradiance
    recombined = envmap.irradiance_reference(split.sky, n) + direct
    err = np.abs((recombined - envmap.irradiance_reference(env, n)) @ envmap.LUMINANCE).max()
    # Moving the solar region (radius 3 deg) onto one direction changes E by at most
    # (1 - cos 3deg) of the sun's share plus terminator effects: < 0.5 % of int L.
    assert err / envmap.luminance_integral(env) < 5e-3


def test_10_city_sun_is_where_the_map_is_brightest(hdris) -> None:
    env = hdris["city"]
    split = envmap.split_sun(env)
    y = env @ np.asarray(envmap.LUMINANCE)
    peak = envmap.directions(*y.shape)[np.unravel_index(np.argmax(y), y.shape)]
    assert math.degrees(math.acos(np.clip(split.direction @ peak, -1, 1))) < 0.5
    assert 0.1 < split.fraction < 0.5 and split.direction[1] > 0  # above the horizon


def test_11_torch_in_torch_out() -> None:
    env = torch.rand(8, 16, 3, dtype=torch.float64)
    out = envmap.irradiance_reference(env, torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float32))
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert isinstance(envmap.rotate(env, torch.eye(3, dtype=torch.float64)), torch.Tensor)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: envmap.irradiance_reference(np.ones((8, 8, 3)), np.ones((2, 3))), "2:1"),
        (lambda: envmap.irradiance_reference(np.ones((8, 16, 3)), np.zeros((2, 3))), "zero-length"),
        (lambda: envmap.irradiance_reference(np.ones((8, 16, 3)), np.ones((2, 2))), r"\(N, 3\)"),
        (lambda: envmap.rotate(np.ones((8, 16, 3)), np.ones((3, 3))), "orthonormal"),
        (lambda: envmap.split_sun(np.full((8, 16, 3), np.nan)), "non-finite"),
        (lambda: envmap.directions(8, 15), "W == 2 H"),
    ],
)
def test_12_bad_input_raises_a_clear_value_error(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()


def _rgbe_bytes(img: np.ndarray, rle: bool) -> bytes:
    """A minimal Radiance writer for the test (runs of >= 2 equal bytes, else 1-byte literals)."""
    h, w, _ = img.shape
    v = img.max(-1)
    m, e = np.frexp(v)
    scale = np.where(v > 1e-32, m * 256.0 / np.maximum(v, 1e-32), 0.0)
    rgbe = np.zeros((h, w, 4), np.uint8)
    rgbe[..., :3] = np.floor(img * scale[..., None])
    rgbe[..., 3] = np.where(v > 1e-32, e + 128, 0)
    out = bytearray(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {h} +X {w}\n".encode())
    for y in range(h):
        if not rle:
            out += rgbe[y].tobytes()
            continue
        out += bytes([2, 2, w >> 8, w & 255])
        for c in range(4):
            row, x = rgbe[y, :, c], 0
            while x < w:
                r = 1
                while x + r < w and r < 127 and row[x + r] == row[x]:
                    r += 1
                out += bytes([128 + r, row[x]]) if r >= 2 else bytes([1, row[x]])
                x += r
    return bytes(out)


@pytest.mark.parametrize("rle", [False, True])
def test_13_radiance_hdr_reads_within_rgbe_quantisation(tmp_path, rle: bool) -> None:
    rng = np.random.default_rng(5)
    img = np.exp(rng.normal(0, 3, (6, 16, 3)))
    img[:, :5] = img[:, :1]  # constant stretches: runs in the RLE
    img[0, 0] = 0.0
    path = tmp_path / "map.hdr"
    path.write_bytes(_rgbe_bytes(img, rle))
    got = envmap.read(path)
    assert got.shape == (6, 16, 3) and got.dtype == np.float32
    assert got[0, 0].max() == 0.0
    # RGBE keeps 8 mantissa bits of the brightest channel: error <= 2^-8 of it.
    assert np.all(np.abs(got - img) <= 2.0 ** -8 * img.max(-1, keepdims=True) + 1e-12)
    path.write_bytes(_rgbe_bytes(img, rle)[:-7])
    with pytest.raises(ValueError, match="corrupt or truncated"):
        envmap.read(path)
    path.write_bytes(b"P6 not a radiance file")
    with pytest.raises(ValueError, match="not a Radiance"):
        envmap.read(path)


def test_14_angles_name_the_texels_of_the_maps_layout() -> None:
    """``direction_from_angles`` is the layout's own parametrisation: the texel of row ``i`` (elevation
    ``90 - 180 i / (H - 1)``) and column ``j`` (azimuth ``360 (j + 0.5) / W``) is its direction; azimuth 0 is -Z,
    90 is +X; it broadcasts, and refuses what is not finite."""
    h, w = 9, 18
    i, j = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    got = envmap.direction_from_angles(90.0 - 180.0 * i / (h - 1), 360.0 * (j + 0.5) / w)
    np.testing.assert_allclose(got, envmap.directions(h, w), atol=1e-12)
    np.testing.assert_allclose(envmap.direction_from_angles(0.0, 0.0), [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(envmap.direction_from_angles(0.0, 90.0), [1, 0, 0], atol=1e-15)
    assert envmap.direction_from_angles(np.zeros((2, 1)), np.zeros(3)).shape == (2, 3, 3)
    with pytest.raises(ValueError, match="finite"):
        envmap.direction_from_angles(float("nan"), 0.0)


def _dirs_at(x: torch.Tensor, y: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """World directions whose lookup coordinates (texel-centred column ``x``, align-corners row ``y``) are given."""
    u = (x + 0.5) / w
    theta = y / (h - 1) * math.pi
    phi = u * 2 * math.pi  # u = atan2(dx, -dz) / (2 pi)
    return torch.stack([torch.sin(theta) * torch.sin(phi), torch.cos(theta), -torch.sin(theta) * torch.cos(phi)], -1)


def test_15_the_bspline_lookup_keeps_constants_and_linear_maps_exactly() -> None:
    """The cubic B-spline's weights sum to 1 and reproduce linear functions: a constant map comes back constant and
    a map linear in the texel coordinates comes back as that linear function of the lookup's coordinates (so
    equal to the bilinear lookup), away from the wrap seam and the clamped pole rows."""
    h, w = 16, 32
    g = torch.Generator().manual_seed(0)
    x = torch.empty(500, dtype=torch.float64).uniform_(3.0, w - 5.0, generator=g)
    y = torch.empty(500, dtype=torch.float64).uniform_(2.0, h - 4.0, generator=g)
    d = _dirs_at(x, y, h, w)
    const = torch.full((h, w, 3), 0.37, dtype=torch.float64)
    assert torch.allclose(envmap.sample_bspline(const, d), const[0, 0].expand(500, 3), atol=1e-12)
    rows, cols = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    lin = torch.stack([1.0 + 0.5 * cols, 5.0 - 0.25 * rows, 0.1 * cols + 0.3 * rows], -1)
    expected = torch.stack([1.0 + 0.5 * x, 5.0 - 0.25 * y, 0.1 * x + 0.3 * y], -1)
    assert torch.allclose(envmap.sample_bspline(lin, d), expected, atol=1e-9)
    assert torch.allclose(envmap.sample(lin, d), expected, atol=1e-9)


def test_16_the_bspline_lookup_of_a_bright_texel_is_positive_and_keeps_the_rows_mean() -> None:
    """A lone bright texel: the B-spline lookup is never negative (bicubic interpolation rings below 0 round it) and
    is 4/9 of the texel at its centre ((2/3)^2, the spline's centre weight per axis). Looked up all round a row
    (equally spaced, whole turns), it averages to 1/6, 4/6, 1/6 of the means of the rows above, at and below."""
    h, w = 16, 32
    env = torch.zeros(h, w, 3, dtype=torch.float64)
    env[7, 11] = 90.0
    g = torch.Generator().manual_seed(1)
    x = torch.empty(4000, dtype=torch.float64).uniform_(0.0, w, generator=g)
    y = torch.empty(4000, dtype=torch.float64).uniform_(1.0, h - 2.0, generator=g)
    assert float(envmap.sample_bspline(env, _dirs_at(x, y, h, w)).min()) >= 0.0
    centre = envmap.sample_bspline(env, _dirs_at(torch.tensor([11.0]), torch.tensor([7.0]), h, w))
    assert torch.allclose(centre, torch.full((1, 3), 90.0 * 4 / 9, dtype=torch.float64), atol=1e-9)
    noise = torch.rand(h, w, 3, generator=g, dtype=torch.float64)
    k = 7  # samples per texel
    xs = torch.arange(w * k, dtype=torch.float64) / k
    for r in (3, 8):
        mean = envmap.sample_bspline(noise, _dirs_at(xs, torch.full_like(xs, float(r)), h, w)).mean(0)
        expected = (noise[r - 1].mean(0) + 4 * noise[r].mean(0) + noise[r + 1].mean(0)) / 6
        assert torch.allclose(mean, expected, atol=1e-9)


def test_17_both_lookups_give_a_pole_its_rows_mean() -> None:
    """Exactly at a pole the column is undefined: the bilinear lookup gives the pole row's mean, the B-spline its
    weights' rows (5/6 of the pole row's mean and 1/6 of the next row's), whatever the map's columns hold. Off the
    pole both depend on the column, which is why a real map's pole row is (nearly) one colour."""
    g = torch.Generator().manual_seed(2)
    env = torch.rand(8, 16, 3, generator=g, dtype=torch.float64)
    up, down = torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64), torch.tensor([[0.0, -1.0, 0.0]], dtype=torch.float64)
    assert torch.allclose(envmap.sample(env, up)[0], env[0].mean(0))
    assert torch.allclose(envmap.sample(env, down)[0], env[-1].mean(0))
    assert torch.allclose(envmap.sample_bspline(env, up)[0], (5 * env[0].mean(0) + env[1].mean(0)) / 6)
    assert torch.allclose(envmap.sample_bspline(env, down)[0], (5 * env[-1].mean(0) + env[-2].mean(0)) / 6)


def test_18_an_env_maps_sun_is_its_texels_over_four_times_the_ring_within_three_degrees() -> None:
    """:func:`physrelight.envmap.split_sun`, the one sun finder of the library (targets, synth, bench), pinned at
    its thresholds on a dim sky (0.01) with a peak texel of 100: of the texels within 3 degrees of the peak, those
    at 5 times the surrounding sky (the 3-6 degree ring's median) are the sun's and those at 3 times are not; a
    bright texel 9.5 degrees away is not. The sun carries exactly the excess of its texels over the ring (the sky
    keeps the ring's value there), and a sun under 1 % of the map's energy is no sun."""
    h, w = 256, 512
    env = np.full((h, w, 3), 0.01)
    r, c = 60, 100  # 47.5 degrees up: a texel is 0.70 degrees high, 0.47 wide
    env[r, c] = 100.0
    env[r, c + 1] = env[r + 1, c] = 0.05  # within a degree, 5x the ring: the sun's
    env[r, c - 2] = env[r - 1, c] = 0.03  # within a degree, 3x the ring: not
    env[r, c + 20] = 30.0  # 9.5 degrees away: not
    dw = envmap._solid_angles(h, w)
    got = envmap.split_sun(env)
    sun_texels = ((r, c), (r, c + 1), (r + 1, c))
    want = sum((env[rc] - 0.01) * dw[rc] for rc in sun_texels)
    np.testing.assert_allclose(got.irradiance, want, rtol=1e-9)
    kept = env.copy()
    for rc in sun_texels:
        kept[rc] = 0.01
    np.testing.assert_allclose(got.sky, kept, rtol=1e-6)
    # the energy share: a sun of 1.5 % is a sun, one of 0.5 % is not
    total = float((np.full((h, w), 0.01) * dw).sum())
    for share, is_sun in ((0.015, True), (0.005, False)):
        one = np.full((h, w, 3), 0.01)
        one[r, c] = 0.01 + share / (1 - share) * total / dw[r, c]
        assert (envmap.split_sun(one).direction is not None) == is_sun, share

