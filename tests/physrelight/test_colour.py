"""Specification of physrelight.colour, checked against colour-science."""

from __future__ import annotations

import colour
import numpy as np
import pytest
import torch

from physrelight import colour as pc

SRGB = colour.RGB_COLOURSPACES["sRGB"]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240611)


def _values(rng: np.random.Generator, n: int = 4000) -> np.ndarray:
    """Random values covering both branches of every curve, plus the special points."""
    special = [0.0, 1.0, 0.0031308, 0.04045, 0.040449936, 1e-9, 0.5]
    return np.concatenate([special, rng.random(n), rng.random(n) * 0.05, 1.0 + rng.random(n)])


# ----------------------------------------------------------------------------- sRGB curve


def test_01_srgb_decode_matches_colour_science(rng):
    v = np.concatenate([_values(rng), -rng.random(100) * 0.1])
    np.testing.assert_allclose(pc.srgb_to_linear(v), colour.models.eotf_sRGB(v), rtol=0, atol=1e-12)


def test_02_srgb_encode_matches_colour_science(rng):
    x = np.concatenate([_values(rng), -rng.random(100) * 0.1, [5.0, 100.0]])
    np.testing.assert_allclose(pc.linear_to_srgb(x), colour.models.eotf_inverse_sRGB(x), rtol=0, atol=1e-12)
    np.testing.assert_allclose(pc.linear_to_srgb(x), colour.cctf_encoding(x, function="sRGB"), rtol=0, atol=1e-12)


def test_03_srgb_roundtrip_is_identity(rng):
    x = np.concatenate([_values(rng), -rng.random(100)])
    np.testing.assert_allclose(pc.srgb_to_linear(pc.linear_to_srgb(x)), x, rtol=1e-12, atol=1e-15)
    t = torch.from_numpy(rng.random((2, 3, 16, 20))).float()
    torch.testing.assert_close(pc.linear_to_srgb(pc.srgb_to_linear(t)), t, rtol=1e-5, atol=1e-6)


def test_04_srgb_curve_is_continuous_at_its_breakpoints():
    for f, brk in ((pc.linear_to_srgb, 0.0031308), (pc.srgb_to_linear, 12.92 * 0.0031308)):
        below, above = f(np.array([brk - 1e-12, brk + 1e-12]))
        assert abs(above - below) < 1e-7


def test_05_srgb_gradients_are_finite_at_zero_and_match_the_slopes():
    x = torch.tensor([0.0, -0.2, 1e-9, 0.0031308, 0.04045, 0.5, 2.0], dtype=torch.float64, requires_grad=True)
    for f in (pc.linear_to_srgb, pc.srgb_to_linear):
        (g,) = torch.autograd.grad(f(x).sum(), x)
        assert torch.isfinite(g).all()
    (g_enc,) = torch.autograd.grad(pc.linear_to_srgb(x[:1]).sum(), x)
    (g_dec,) = torch.autograd.grad(pc.srgb_to_linear(x[:1]).sum(), x)
    assert float(g_enc[0]) == pytest.approx(12.92) and float(g_dec[0]) == pytest.approx(1 / 12.92)
    xs = torch.tensor([0.002, 0.01, 0.3, 0.9, 1.4], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(pc.linear_to_srgb, (xs,))
    assert torch.autograd.gradcheck(pc.srgb_to_linear, (xs,))


def test_06_numpy_in_numpy_out_and_torch_in_torch_out_keep_dtype_and_graph(rng):
    a32 = rng.random((3, 4, 5)).astype(np.float32)
    out = pc.srgb_to_linear(a32)
    assert isinstance(out, np.ndarray) and out.dtype == np.float32 and out.shape == a32.shape
    lab = pc.rgb_to_lab(a32)
    assert isinstance(lab, np.ndarray) and lab.dtype == np.float32
    t = torch.from_numpy(a32).requires_grad_()
    for f in (pc.srgb_to_linear, pc.linear_to_srgb, pc.gamma_encode, pc.rgb_to_lab, pc.to_ldr):
        y = f(t)
        assert isinstance(y, torch.Tensor) and y.dtype == torch.float32 and y.requires_grad


# ----------------------------------------------------------------------------- gamma, exposure


def test_07_gamma_encode_decode_are_exact_inverse_power_laws(rng):
    x = rng.random(1000) * 3.0
    np.testing.assert_allclose(pc.gamma_encode(x, 2.2), colour.gamma_function(x, 1 / 2.2), rtol=1e-13)
    np.testing.assert_allclose(pc.gamma_decode(x, 2.4), x**2.4, rtol=1e-13)
    np.testing.assert_allclose(pc.gamma_decode(pc.gamma_encode(x, 1.8), 1.8), x, rtol=1e-12, atol=1e-15)
    # negatives are odd-symmetric, so the round trip holds on all reals
    np.testing.assert_allclose(pc.gamma_encode(-x, 2.2), -pc.gamma_encode(x, 2.2), rtol=0, atol=0)
    assert pc.gamma_encode(np.array([0.0]))[0] == 0.0
    with pytest.raises(ValueError, match="gamma"):
        pc.gamma_encode(x, 0.0)


def test_08_gamma_gradient_is_finite_at_zero_and_exact_elsewhere():
    x = torch.tensor([0.0, 1e-12, 0.3, -0.3, 2.0], dtype=torch.float64, requires_grad=True)
    (g,) = torch.autograd.grad(pc.gamma_encode(x, 2.2).sum(), x)
    assert torch.isfinite(g).all()
    assert float(g[0]) == pytest.approx(1e-6 ** (1 / 2.2 - 1) / 2.2)
    assert float(g[2]) == pytest.approx(0.3 ** (1 / 2.2 - 1) / 2.2, rel=1e-12)
    assert float(g[3]) == pytest.approx(float(g[2]), rel=1e-12)  # odd function: even derivative
    xs = torch.tensor([0.05, 0.4, 1.7, -0.6], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: pc.gamma_encode(t, 2.2), (xs,))
    assert torch.autograd.gradgradcheck(lambda t: pc.gamma_encode(t, 2.2), (xs,))
    assert torch.autograd.gradcheck(lambda t: pc.gamma_decode(t, 2.2), (xs,))


def test_09_expose_multiplies_by_two_to_the_ev(rng):
    x = rng.random((2, 3, 4, 5))
    np.testing.assert_allclose(pc.expose(x, 1.5), x * 2**1.5, rtol=1e-15)
    ev = torch.tensor([-1.0, 2.0], dtype=torch.float64).view(2, 1, 1, 1)
    y = pc.expose(torch.from_numpy(x), ev)
    torch.testing.assert_close(y, torch.from_numpy(x) * torch.tensor([0.5, 4.0], dtype=torch.float64).view(2, 1, 1, 1))
    with pytest.raises(ValueError, match="ev"):
        pc.expose(x, float("nan"))


# ----------------------------------------------------------------------------- response curves


@pytest.mark.parametrize("curve", pc.RESPONSE_CURVES)
def test_10_invert_response_undoes_apply_response(rng, curve):
    x = np.concatenate([[0.0, 1e-6, 0.18, 1.0], rng.random(2000) * 7.0, rng.random(500) * 0.01])
    np.testing.assert_allclose(pc.invert_response(pc.apply_response(x, curve), curve), x, rtol=1e-10, atol=1e-12)
    t = torch.from_numpy(x).float()
    torch.testing.assert_close(pc.invert_response(pc.apply_response(t, curve), curve), t, rtol=2e-5, atol=1e-6)


@pytest.mark.parametrize("curve", pc.RESPONSE_CURVES)
def test_11_response_curves_are_strictly_increasing_and_fix_zero(curve):
    x = np.linspace(0.0, 50.0, 200001)
    y = pc.apply_response(x, curve)
    assert y[0] == 0.0
    assert np.all(np.diff(y) > 0)


def test_12_named_curves_are_the_documented_formulas():
    x = np.linspace(0.0, 4.0, 101)
    np.testing.assert_allclose(pc.apply_response(x, "srgb"), colour.cctf_encoding(x), atol=1e-12)
    np.testing.assert_allclose(pc.apply_response(x, "gamma2.2"), x ** (1 / 2.2), atol=1e-12)
    np.testing.assert_array_equal(pc.apply_response(x, "linear"), x)
    aces = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    np.testing.assert_allclose(pc.apply_response(x, "filmic"), colour.cctf_encoding(aces), atol=1e-12)
    mid, sat, sup = pc.apply_response(np.array([0.18, 7.2423, 1e9]), "filmic")
    assert mid == pytest.approx(0.553, abs=1e-3)
    assert sat == pytest.approx(1.0, abs=1e-4)
    assert sup == pytest.approx(1.0143, abs=1e-4)


def test_13_unknown_curve_is_a_value_error_listing_the_valid_names():
    for f in (pc.apply_response, pc.invert_response, pc.to_ldr, pc.from_ldr):
        with pytest.raises(ValueError, match="linear, srgb, gamma2.2, filmic"):
            f(np.zeros(3), curve="aces")


def test_14_filmic_rejects_negative_radiance_and_values_outside_its_range():
    with pytest.raises(ValueError, match="non-negative"):
        pc.apply_response(np.array([0.1, -0.01]), "filmic")
    with pytest.raises(ValueError, match="invertible"):
        pc.invert_response(np.array([0.5, 1.02]), "filmic")
    with pytest.raises(ValueError, match="invertible"):
        pc.invert_response(np.array([-0.01]), "filmic")


@pytest.mark.parametrize("curve", pc.RESPONSE_CURVES)
def test_15_to_ldr_clamps_and_from_ldr_inverts_below_saturation(rng, curve):
    x = rng.random((2, 3, 8, 9)) * 0.4
    ldr = pc.to_ldr(x, ev=1.0, curve=curve)
    assert ldr.min() >= 0.0 and ldr.max() <= 1.0
    np.testing.assert_allclose(pc.from_ldr(ldr, curve=curve, ev=1.0), x, rtol=1e-10, atol=1e-12)
    bright = pc.to_ldr(np.array([100.0, -1.0 if curve != "filmic" else 0.0]), curve=curve)
    np.testing.assert_array_equal(bright, [1.0, 0.0])


def test_16_from_ldr_scales_integer_photos_and_rejects_out_of_range_values():
    u8 = np.array([0, 10, 128, 255], dtype=np.uint8)
    out = pc.from_ldr(u8)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, colour.cctf_decoding(u8 / 255.0), atol=1e-12)
    u16 = torch.tensor([0, 30000, 65535], dtype=torch.uint16)
    torch.testing.assert_close(pc.from_ldr(u16, curve="linear"), torch.tensor([0.0, 30000 / 65535, 1.0]))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        pc.from_ldr(np.array([0.2, 1.2]))
    with pytest.raises(ValueError, match="uint8 or uint16"):
        pc.from_ldr(np.array([1, 2], dtype=np.int32))


# ----------------------------------------------------------------------------- XYZ and Lab


def test_17_rgb_to_xyz_uses_colour_sciences_srgb_matrix(rng):
    rgb = rng.random((500, 3)) * 2.0 - 0.2
    ref = colour.RGB_to_XYZ(rgb, SRGB)
    np.testing.assert_allclose(pc.rgb_to_xyz(rgb, dim=-1), ref, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(pc.M_RGB_TO_XYZ, SRGB.matrix_RGB_to_XYZ)


def test_18_xyz_to_lab_matches_colour_science_including_the_linear_segment(rng):
    xyz = np.concatenate([rng.random((1000, 3)) * 1.1, rng.random((500, 3)) * 0.01, -rng.random((50, 3)) * 0.01])
    np.testing.assert_allclose(pc.xyz_to_lab(xyz, dim=-1), colour.XYZ_to_Lab(xyz), rtol=0, atol=1e-10)


def test_19_rgb_to_lab_matches_colour_science_on_a_channel_first_batch(rng):
    rgb = rng.random((2, 3, 64, 80))
    ref = colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.moveaxis(rgb, 1, -1), SRGB))
    np.testing.assert_allclose(np.moveaxis(pc.rgb_to_lab(rgb), 1, -1), ref, rtol=0, atol=1e-10)
    lab32 = pc.rgb_to_lab(torch.from_numpy(rgb).float())
    assert float((lab32.double() - torch.from_numpy(np.moveaxis(ref, -1, 1))).abs().max()) < 1e-4


def test_20_white_and_black_land_where_colour_science_puts_them():
    lab = pc.rgb_to_lab(np.array([[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]), dim=-1)
    np.testing.assert_allclose(lab[0], colour.XYZ_to_Lab(SRGB.matrix_RGB_to_XYZ.sum(1)), atol=1e-12)
    assert lab[0, 0] == pytest.approx(100.0) and np.abs(lab[0, 1:]).max() < 0.01
    np.testing.assert_array_equal(lab[1], [0.0, 0.0, 0.0])


def test_21_inverse_conversions_round_trip_and_agree_with_colour_science(rng):
    rgb = rng.random((3, 20, 30))
    np.testing.assert_allclose(pc.lab_to_rgb(pc.rgb_to_lab(rgb)), rgb, rtol=0, atol=1e-12)
    xyz = pc.rgb_to_xyz(rgb)
    np.testing.assert_allclose(pc.xyz_to_rgb(xyz), rgb, rtol=0, atol=1e-14)
    np.testing.assert_allclose(pc.lab_to_xyz(pc.xyz_to_lab(xyz)), xyz, rtol=0, atol=1e-14)
    lab = rng.random((200, 3)) * [100, 160, 160] - [0, 80, 80]
    np.testing.assert_allclose(pc.lab_to_xyz(lab, dim=-1), colour.Lab_to_XYZ(lab), rtol=0, atol=1e-12)
    # colour-science stores the 4-digit IEC inverse matrix, not the exact inverse
    ref = np.moveaxis(colour.XYZ_to_RGB(np.moveaxis(xyz, 0, -1), SRGB), -1, 0)
    np.testing.assert_allclose(pc.xyz_to_rgb(xyz, dim=0), ref, atol=2e-4)


def test_22_channel_axis_is_configurable(rng):
    img = rng.random((2, 3, 5, 7))
    ref = pc.rgb_to_lab(img)
    np.testing.assert_allclose(np.moveaxis(pc.rgb_to_lab(np.moveaxis(img, 1, -1), dim=-1), -1, 1), ref, atol=1e-12)
    np.testing.assert_allclose(pc.rgb_to_lab(img, dim=1), ref, atol=1e-12)
    np.testing.assert_allclose(pc.rgb_to_lab(img[0]), ref[0], atol=1e-12)


def test_23_rgb_to_lab_is_differentiable_with_finite_gradients_at_black(rng):
    rgb = torch.tensor(rng.random((1, 3, 3, 4)) * 0.9 + 0.02, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(pc.rgb_to_lab, (rgb,))
    dark = torch.tensor([[1e-4, 2e-4, 5e-4], [0.3, 0.1, 0.6]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda t: pc.rgb_to_lab(t, dim=-1), (dark,))  # linear segment
    black = torch.zeros(1, 3, 2, 2, dtype=torch.float64, requires_grad=True)
    (g,) = torch.autograd.grad(pc.rgb_to_lab(pc.srgb_to_linear(black)).sum(), black)
    assert torch.isfinite(g).all()


def test_24_wrong_channel_count_is_a_value_error_naming_the_shape():
    for f in (pc.rgb_to_xyz, pc.xyz_to_rgb, pc.xyz_to_lab, pc.lab_to_xyz, pc.rgb_to_lab, pc.lab_to_rgb):
        with pytest.raises(ValueError, match=r"\(2, 4, 5, 6\)"):
            f(np.zeros((2, 4, 5, 6)))
        with pytest.raises(ValueError, match=r"\(\.\.\., 3\).*\(5, 2\)"):
            f(np.zeros((5, 2)), dim=-1)
    with pytest.raises(ValueError, match=r"\(3,\)"):
        pc.rgb_to_lab(torch.zeros(3))  # dim=-3 does not exist


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
def test_25_nan_and_inf_are_value_errors(bad):
    x = np.full((1, 3, 2, 2), 0.5)
    x[0, 1, 1, 0] = bad
    funcs = (
        pc.srgb_to_linear, pc.linear_to_srgb, pc.gamma_encode, pc.gamma_decode, lambda t: pc.expose(t, 1.0),
        pc.to_ldr, pc.from_ldr, pc.apply_response, pc.invert_response,
        pc.rgb_to_xyz, pc.xyz_to_rgb, pc.xyz_to_lab, pc.lab_to_xyz, pc.rgb_to_lab, pc.lab_to_rgb,
    )
    for f in funcs:
        with pytest.raises(ValueError, match="non-finite"):
            f(x)
    with pytest.raises(ValueError, match="non-finite"):
        pc.rgb_to_lab(torch.from_numpy(x))
