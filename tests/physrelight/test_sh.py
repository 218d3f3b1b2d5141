"""Specification of physrelight.sh: real SH, irradiance, rotation, projection, order selection."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import special

from physrelight import envmap, rotations, sh

from .conftest import HDRI_NAMES, band_limited_map, positive_coeffs


def unit(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# ----------------------------------------------------------------- basis


def test_01_order2_basis_matches_the_design_table() -> None:
    d = unit(np.random.default_rng(0), 50)
    x, y, z = d.T
    expected = np.stack([
        np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x,
        1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z,
        0.546274 * (x * x - y * y),
    ], axis=-1)
    np.testing.assert_allclose(sh.basis(d, 2), expected, atol=2e-6)


def test_02_basis_agrees_with_scipy_complex_harmonics_up_to_order_8() -> None:
    # Real SH without Condon-Shortley phase from scipy's complex ones (which carry it):
    # Y_l^m (m>0) = sqrt2 (-1)^m Re Y_l^m, Y_l^-m = sqrt2 (-1)^m Im Y_l^m.
    d = unit(np.random.default_rng(1), 40)
    theta = np.arccos(d[:, 2])
    phi = np.arctan2(d[:, 1], d[:, 0])
    ours = sh.basis(d, 8)
    for l in range(9):
        for m in range(0, l + 1):
            c = special.sph_harm_y(l, m, theta, phi)
            if m == 0:
                np.testing.assert_allclose(ours[:, l * (l + 1)], c.real, atol=1e-12)
            else:
                sign = (-1) ** m * math.sqrt(2)
                np.testing.assert_allclose(ours[:, l * (l + 1) + m], sign * c.real, atol=1e-12)
                np.testing.assert_allclose(ours[:, l * (l + 1) - m], sign * c.imag, atol=1e-12)


def test_03_basis_is_orthonormal_by_exact_quadrature() -> None:
    # Gauss-Legendre in cos(theta) times the trapezoid rule in phi integrates products
    # of SH up to order 8 exactly, so the Gram matrix must be the identity to rounding.
    z, wz = np.polynomial.legendre.leggauss(20)
    phi = 2 * np.pi * np.arange(40) / 40
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz**2)
    d = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    w = (wz[:, None] * np.full(40, 2 * np.pi / 40)[None, :]).reshape(-1, 1)
    y = sh.basis(d, 8)
    assert np.abs((y * w).T @ y - np.eye(81)).max() < 1e-12


def test_04_addition_theorem_holds_for_every_band() -> None:
    rng = np.random.default_rng(2)
    a, b = unit(rng, 30), unit(rng, 30)
    ya, yb = sh.basis(a, 8), sh.basis(b, 8)
    cos = np.sum(a * b, axis=1)
    for l in range(9):
        s = slice(l * l, (l + 1) ** 2)
        lhs = np.sum(ya[:, s] * yb[:, s], axis=1)
        rhs = (2 * l + 1) / (4 * math.pi) * special.eval_legendre(l, cos)
        np.testing.assert_allclose(lhs, rhs, atol=1e-12)


def test_05_clamped_cosine_coefficients_match_numerical_integration() -> None:
    a = sh.clamped_cosine_coeffs(8)
    np.testing.assert_allclose(a[:5], [math.pi, 2 * math.pi / 3, math.pi / 4, 0.0, -math.pi / 24], atol=1e-15)
    # A_l = 2 pi int_0^1 t P_l(t) dt (the clamped cosine's Funk-Hecke eigenvalue).
    t, w = np.polynomial.legendre.leggauss(64)
    t, w = 0.5 * (t + 1), 0.5 * w
    for l in range(9):
        np.testing.assert_allclose(a[l], 2 * math.pi * np.sum(w * t * special.eval_legendre(l, t)), atol=1e-13)


# ----------------------------------------------------------- irradiance


@pytest.mark.parametrize("order", [1, 2, 4])
def test_06_sh_irradiance_equals_brute_force_on_band_limited_maps(order: int) -> None:
    coeffs = positive_coeffs(order, seed=order)
    env = band_limited_map(coeffs, 512)
    normals = sh.fibonacci_sphere(200)
    exact = sh.irradiance(coeffs, normals)
    brute = envmap.irradiance_reference(env, normals)
    rel = np.abs(brute - exact).max() / np.abs(exact).max()
    assert rel < 1e-5, rel
    # The projection recovers the coefficients themselves to the same accuracy.
    np.testing.assert_allclose(sh.project_envmap(env, order), coeffs, atol=1e-5 * np.abs(coeffs).max())


@pytest.mark.parametrize("name", HDRI_NAMES)
def test_07_order2_error_obeys_the_theoretical_bound_on_real_maps(hdris, name: str) -> None:
    env = hdris[name]
    normals = np.concatenate([sh.fibonacci_sphere(400), sh.fibonacci_sphere(7)])
    brute = envmap.irradiance_reference(env, normals)
    est = sh.irradiance(sh.project_envmap(env, 2), normals)
    lum = np.asarray(envmap.LUMINANCE)
    total = envmap.luminance_integral(env)
    max_err = np.abs((est - brute) @ lum).max() / total
    mean_err = np.abs((est - brute) @ lum).mean() / total
    # Ramamoorthi & Hanrahan style bounds for non-negative lighting (DESIGN.md).
    assert max_err <= 0.094, max_err
    assert mean_err <= 0.031, mean_err


def test_08_order3_adds_nothing_to_irradiance() -> None:
    coeffs = positive_coeffs(3, seed=5)
    n = sh.fibonacci_sphere(64)
    np.testing.assert_allclose(sh.irradiance(coeffs, n), sh.irradiance(coeffs[:9], n), atol=1e-12)


def test_09_shading_is_irradiance_over_pi_and_white_furnace_gives_one() -> None:
    # Uniform radiance 1 everywhere: E = pi for every normal, so shading = 1.
    env = np.ones((64, 128, 3))
    c = sh.project_envmap(env, 4)
    n = sh.fibonacci_sphere(50)
    np.testing.assert_allclose(sh.shading(c, n), 1.0, atol=1e-12)
    np.testing.assert_allclose(sh.irradiance(c, n), math.pi, atol=1e-12)


# ----------------------------------------------------------- rotation


@pytest.mark.parametrize("order", [0, 1, 2, 3, 4, 8])
def test_10_basis_of_rotated_direction_is_rotated_basis(order: int) -> None:
    rng = np.random.default_rng(10 + order)
    for seed in range(5):
        R = rotations.random_rotation(100 * order + seed)
        x = unit(rng, 20)
        D = sh.rotation(R, order)
        np.testing.assert_allclose(sh.basis(x @ R.T, order), sh.basis(x, order) @ D.T, atol=1e-12)
        np.testing.assert_allclose(D @ D.T, np.eye(D.shape[0]), atol=1e-12)


def test_11_rotation_is_a_representation() -> None:
    r1, r2 = rotations.random_rotation(1), rotations.random_rotation(2)
    np.testing.assert_allclose(sh.rotation(r1 @ r2, 4), sh.rotation(r1, 4) @ sh.rotation(r2, 4), atol=1e-12)
    np.testing.assert_allclose(sh.rotation(np.eye(3), 4), np.eye(25), atol=1e-15)
    # Batched rotations give the per-matrix results.
    batch = np.stack([r1, r2])
    np.testing.assert_allclose(sh.rotation(batch, 2)[1], sh.rotation(r2, 2), atol=1e-15)


def test_12_rotating_coefficients_equals_projecting_the_rotated_map() -> None:
    # Brute force: sample f(R^T w) analytically on the texels and project it.
    coeffs = positive_coeffs(4, seed=3)
    R = rotations.random_rotation(7)
    d = envmap.directions(512, 1024)
    rotated_map = sh.basis(d @ R, 4) @ coeffs  # rows (R^T d)^T = d^T R
    np.testing.assert_allclose(sh.project_envmap(rotated_map, 4), sh.rotate(coeffs, R),
                               atol=1e-5 * np.abs(coeffs).max())


def test_13_rotation_about_y_by_one_texel_is_an_exact_column_shift(hdris) -> None:
    env = hdris["city"]
    h, w = env.shape[:2]
    shift = 37
    R = rotations.about_y(360.0 * shift / w)
    rotated = envmap.rotate(env, R)
    # env'(w) = env(R^T w): a positive turn about +Y moves u by -shift/W columns. The
    # pole rows are single points: they become the mean of the original pole row.
    np.testing.assert_allclose(rotated[1:-1], np.roll(env, -shift, axis=1)[1:-1], rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(rotated[0], np.broadcast_to(env[0].mean(axis=0), env[0].shape), rtol=1e-5)
    np.testing.assert_allclose(sh.project_envmap(rotated, 4), sh.rotate(sh.project_envmap(env, 4), R),
                               rtol=1e-5, atol=1e-4)


# ----------------------------------------------------------- sun


def test_14_sun_projection_is_the_limit_of_a_small_bright_disk() -> None:
    h = 1024
    d = envmap.directions(h, 2 * h)
    w = envmap.solid_angles(h, 2 * h)
    s = np.array([0.3, 0.8, -0.52])
    s /= np.linalg.norm(s)
    disk = (d @ s) >= math.cos(math.radians(1.5))
    e_sun = np.array([900.0, 800.0, 700.0])
    env = np.zeros((h, 2 * h, 3))
    env[disk] = e_sun / w[disk].sum()
    np.testing.assert_allclose(sh.project_envmap(env, 4), sh.project_sun(s, e_sun, 4), rtol=0, atol=2e-3 * e_sun.max())
    # Irradiance of the delta sun is E_sun max(0, n.s) in the continuum; order 4 is
    # within the truncation bound.
    n = sh.fibonacci_sphere(100)
    brute = np.clip(n @ s, 0, None)[:, None] * e_sun
    est = sh.irradiance(sh.project_sun(s, e_sun, 4), n)
    assert np.abs(est - brute).max() <= 0.094 * e_sun.max()


# ----------------------------------------------------------- order selection


def test_15_select_order_models_no_more_than_the_scene_needs(hdris) -> None:
    # The yardstick (texel quadrature) is itself within O(dtheta^2) of the interpolated
    # map: ~2e-4 at H=64, hence tolerance 1e-3 for the exact cases.
    assert sh.select_order(np.full((64, 128, 3), 0.7), tolerance=1e-3) == 0
    coeffs = np.zeros((4, 3))
    coeffs[0] = 2.0
    coeffs[2] = 0.8  # a pure order-1 gradient sky
    assert sh.select_order(band_limited_map(coeffs, 64), tolerance=1e-3) == 1
    # The same city sky with and without its sun: the sun is what needs order 4.
    city = hdris["city"]
    sky = envmap.split_sun(city).sky
    with_sun, without = sh.order_errors(city, (0, 1, 2, 4)), sh.order_errors(sky, (0, 1, 2, 4))
    for e in (with_sun, without):
        assert e[0]["nmae"] >= e[1]["nmae"] >= e[2]["nmae"] >= e[4]["nmae"]
    assert sh.select_order(sky, tolerance=0.02) == 2
    assert sh.select_order(city, tolerance=0.02) == 4


# ----------------------------------------------------------- types, gradients


def test_16_numpy_in_numpy_out_torch_in_torch_out() -> None:
    d = unit(np.random.default_rng(3), 5)
    assert isinstance(sh.basis(d), np.ndarray)
    assert isinstance(sh.basis(torch.from_numpy(d)), torch.Tensor)
    assert sh.basis(d.astype(np.float32)).dtype == np.float32
    c = positive_coeffs(2, 1)
    out = sh.irradiance(torch.from_numpy(c).float(), torch.from_numpy(d).float())
    assert out.dtype == torch.float32 and out.shape == (5, 3)


def test_17_gradcheck_irradiance_and_shading() -> None:
    rng = np.random.default_rng(4)
    c = torch.tensor(positive_coeffs(2, 2), requires_grad=True)
    n = torch.tensor(unit(rng, 6), requires_grad=True)
    assert torch.autograd.gradcheck(sh.irradiance, (c, n))
    assert torch.autograd.gradcheck(sh.shading, (c, n))
    R = torch.tensor(rotations.random_rotation(3))
    assert torch.autograd.gradcheck(lambda x: sh.rotate(x, R), (c,))


# ----------------------------------------------------------- bad input


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: sh.basis(np.array([[0.0, 0.0, 0.0]])), "zero-length"),
        (lambda: sh.basis(np.array([[np.nan, 0.0, 1.0]])), "non-finite"),
        (lambda: sh.basis(np.ones((4, 2))), r"\(\.\.\., 3\)"),
        (lambda: sh.basis(np.ones((4, 3)), order=9), "order"),
        (lambda: sh.basis(np.ones((4, 3)), order=2.5), "order"),
        (lambda: sh.irradiance(np.ones((8, 3)), np.ones((4, 3))), "K = \\(order\\+1\\)\\^2"),
        (lambda: sh.irradiance(np.ones((9, 4)), np.ones((4, 3))), r"\(\.\.\., K, 3\)"),
        (lambda: sh.irradiance(np.full((9, 3), np.inf), np.ones((4, 3))), "non-finite"),
        (lambda: sh.irradiance(np.ones((2, 9, 3)), np.ones((5, 3))), "broadcast"),
        (lambda: sh.project_envmap(np.ones((32, 32, 3))), "2:1"),
        (lambda: sh.project_envmap(-np.ones((32, 64, 3))), "non-negative"),
        (lambda: sh.project_envmap(np.ones((32, 64, 4))), r"\(H, W, 3\)"),
        (lambda: sh.rotation(np.diag([1.0, 1.0, -1.0])), "reflection"),
        (lambda: sh.rotation(2 * np.eye(3)), "orthonormal"),
        (lambda: sh.project_sun(np.array([0.0, 1.0, 0.0]), np.array([-1.0, 1.0, 1.0])), "non-negative"),
        (lambda: sh.select_order(np.ones((8, 16, 3)), tolerance=0.0), "tolerance"),
    ],
)
def test_18_bad_input_raises_a_clear_value_error(call, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        call()
