"""Specification of physrelight.metrics, checked against scikit-image and colour-science."""

from __future__ import annotations

import colour
import numpy as np
import pytest
import torch
from skimage.metrics import mean_squared_error, peak_signal_noise_ratio, structural_similarity

from physrelight import metrics as pm

SRGB = colour.RGB_COLOURSPACES["sRGB"]


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def _pair(rng: np.random.Generator, shape=(2, 3, 64, 80), noise: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A target in [0, 1] and a noisy, clipped prediction of it (float64, channel-first)."""
    target = rng.random(shape)
    pred = np.clip(target + noise * rng.standard_normal(shape), 0.0, 1.0)
    return pred, target


def _sk_ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0, full: bool = False):
    """scikit-image's Wang et al. SSIM of one channel-first image pair."""
    return structural_similarity(
        np.moveaxis(a, 0, -1),
        np.moveaxis(b, 0, -1),
        channel_axis=-1,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=data_range,
        full=full,
    )


def _colour_de00(a_srgb: np.ndarray, b_srgb: np.ndarray) -> np.ndarray:
    """Per-pixel CIEDE2000 of channel-first sRGB-encoded images with colour-science: (..., H, W)."""

    def lab(x):
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(colour.cctf_decoding(np.moveaxis(x, -3, -1)), SRGB))

    return colour.delta_E(lab(a_srgb), lab(b_srgb), method="CIE 2000")


# Sharma, Wu & Dalal (2005), Table 1: (L1, a1, b1), (L2, a2, b2), published dE00 (4 decimals).
# Pair 14 (hue difference exactly 180 degrees, platform-dependent) is left out, as colour-science does.
SHARMA_2005 = [
    ((50.0000, 2.6772, -79.7751), (50.0000, 0.0000, -82.7485), 2.0425),
    ((50.0000, 3.1571, -77.2803), (50.0000, 0.0000, -82.7485), 2.8615),
    ((50.0000, 2.8361, -74.0200), (50.0000, 0.0000, -82.7485), 3.4412),
    ((50.0000, -1.3802, -84.2814), (50.0000, 0.0000, -82.7485), 1.0000),
    ((50.0000, 0.0000, 0.0000), (50.0000, -1.0000, 2.0000), 2.3669),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0009), 7.1792),
    ((50.0000, 2.4900, -0.0010), (50.0000, -2.4900, 0.0011), 7.2195),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0009, -2.4900), 4.8045),
    ((50.0000, -0.0010, 2.4900), (50.0000, 0.0011, -2.4900), 4.7461),
    ((50.0000, 2.5000, 0.0000), (50.0000, 0.0000, -2.5000), 4.3065),
    ((50.0000, 2.5000, 0.0000), (73.0000, 25.0000, -18.0000), 27.1492),
    ((50.0000, 2.5000, 0.0000), (56.0000, -27.0000, -3.0000), 31.9030),
    ((50.0000, 2.5000, 0.0000), (50.0000, 3.2972, 0.0000), 1.0000),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((63.0109, -31.0961, -5.8663), (62.8187, -29.7946, -4.0864), 1.2630),
    ((22.7233, 20.0904, -46.6940), (23.0331, 14.9730, -42.5619), 2.0373),
    ((36.4612, 47.8580, 18.3852), (36.2715, 50.5065, 21.2231), 1.4146),
    ((90.8027, -2.0831, 1.4410), (91.1528, -1.6435, 0.0447), 1.4441),
    ((6.7747, -0.2908, -2.4247), (5.8714, -0.0985, -2.2286), 0.6377),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
]


# ----------------------------------------------------------------------------- L1, MSE, PSNR


def test_01_l1_and_mse_match_brute_force_and_scikit_image(rng):
    pred, target = _pair(rng)
    assert pm.l1(pred, target) == pytest.approx(np.abs(pred - target).mean(), rel=1e-12)
    per_image = [mean_squared_error(target[i], pred[i]) for i in range(2)]
    np.testing.assert_allclose(pm.mse(pred, target, reduction="none"), per_image, rtol=1e-12)
    assert pm.mse(pred, target) == pytest.approx(np.mean(per_image), rel=1e-12)


def test_02_psnr_matches_scikit_image_per_image_and_averages_decibels(rng):
    pred, target = _pair(rng, (3, 3, 48, 48))
    pred[1] = np.clip(target[1] + 0.01 * rng.standard_normal(target[1].shape), 0, 1)
    ref = [peak_signal_noise_ratio(target[i], pred[i], data_range=1.0) for i in range(3)]
    np.testing.assert_allclose(pm.psnr(pred, target, reduction="none"), ref, rtol=1e-12)
    assert pm.psnr(pred, target) == pytest.approx(np.mean(ref), rel=1e-12)
    ref255 = peak_signal_noise_ratio(255 * target[0], 255 * pred[0], data_range=255)
    assert pm.psnr(255 * pred[0], 255 * target[0], data_range=255.0) == pytest.approx(ref255, rel=1e-12)


def test_03_psnr_of_identical_images_is_infinite(rng):
    _, target = _pair(rng, (1, 3, 16, 16))
    assert pm.psnr(target, target) == float("inf")


# ----------------------------------------------------------------------------- SSIM


@pytest.mark.parametrize("shape", [(2, 3, 64, 80), (1, 3, 48, 48), (1, 1, 37, 52), (2, 4, 11, 23)])
def test_04_ssim_matches_scikit_image_wang_et_al_settings(rng, shape):
    pred, target = _pair(rng, shape)
    ref = [_sk_ssim(pred[i], target[i]) for i in range(shape[0])]
    np.testing.assert_allclose(pm.ssim(pred, target, reduction="none"), ref, rtol=0, atol=1e-12)
    assert pm.ssim(pred, target) == pytest.approx(np.mean(ref), abs=1e-12)


def test_05_ssim_in_float32_torch_matches_scikit_image_to_1e5(rng):
    pred, target = _pair(rng)
    ref = np.mean([_sk_ssim(pred[i], target[i]) for i in range(2)])
    got = pm.ssim(torch.from_numpy(pred).float(), torch.from_numpy(target).float())
    assert abs(float(got) - ref) < 1e-5


def test_06_ssim_honours_data_range(rng):
    pred, target = _pair(rng, (1, 3, 40, 50))
    ref = _sk_ssim(255 * pred[0], 255 * target[0], data_range=255)
    assert pm.ssim(255 * pred, 255 * target, data_range=255.0) == pytest.approx(ref, abs=1e-12)
    dim_p, dim_t = 0.05 * pred, 0.05 * target  # low contrast: C1 and C2 matter
    ref_small = _sk_ssim(dim_p[0], dim_t[0], data_range=0.05)
    assert pm.ssim(dim_p, dim_t, data_range=0.05) == pytest.approx(ref_small, abs=1e-12)
    assert abs(ref_small - pm.ssim(dim_p, dim_t)) > 0.02


def test_07_ssim_map_matches_scikit_image_full_map_and_its_crop_mean_is_ssim(rng):
    pred, target = _pair(rng, (1, 3, 30, 41))
    _, full = _sk_ssim(pred[0], target[0], full=True)  # (H, W, C)
    sym = pm.ssim_map(pred[0], target[0], padding="symmetric")
    assert sym.shape == (3, 30, 41)
    np.testing.assert_allclose(np.moveaxis(sym, 0, -1), full, rtol=0, atol=1e-12)
    valid = pm.ssim_map(pred, target)
    assert valid.shape == (1, 3, 20, 31)
    np.testing.assert_allclose(valid[0], sym[:, 5:-5, 5:-5], rtol=0, atol=1e-12)
    assert valid.mean() == pytest.approx(pm.ssim(pred, target), abs=1e-12)


def test_08_ssim_of_an_image_with_itself_is_one_and_dssim_is_half_one_minus_ssim(rng):
    pred, target = _pair(rng, (2, 3, 32, 32))
    assert pm.ssim(target, target) == pytest.approx(1.0, abs=1e-12)
    assert pm.dssim(target, target) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(
        pm.dssim(pred, target, reduction="none"), (1 - pm.ssim(pred, target, reduction="none")) / 2, atol=1e-15
    )


# ----------------------------------------------------------------------------- types and reductions


def test_09_numpy_gives_floats_and_torch_gives_0_dim_tensors_or_per_image_vectors(rng):
    pred, target = _pair(rng, (2, 3, 16, 16))
    tp, tt = torch.from_numpy(pred).float(), torch.from_numpy(target).float()
    for f in (pm.l1, pm.mse, pm.psnr, pm.ssim, pm.dssim, pm.delta_e2000):
        v = f(pred, target)
        assert type(v) is float
        vt = f(tp, tt)
        assert isinstance(vt, torch.Tensor) and vt.shape == () and vt.dtype == torch.float32
        assert float(vt) == pytest.approx(v, rel=1e-4, abs=1e-4)
        per = f(pred, target, reduction="none")
        assert isinstance(per, np.ndarray) and per.shape == (2,)
        assert np.mean(per) == pytest.approx(v, rel=1e-12)
        assert f(tp, tt, reduction="none").shape == (2,)
        unbatched = f(pred[1], target[1], reduction="none")
        assert unbatched.shape == (1,) and unbatched[0] == pytest.approx(per[1], rel=1e-12)


def test_10_differentiable_metrics_backpropagate_to_pred(rng):
    pred, target = _pair(rng, (1, 3, 16, 16))
    for f in (pm.l1, pm.mse, pm.psnr, pm.ssim, pm.dssim, pm.delta_e2000):
        p = torch.from_numpy(pred).float().requires_grad_()
        (g,) = torch.autograd.grad(f(p, torch.from_numpy(target).float()), p)
        assert torch.isfinite(g).all() and g.abs().sum() > 0


# ----------------------------------------------------------------------------- masks


def _masks(rng: np.random.Generator, b: int, h: int, w: int) -> np.ndarray:
    m = rng.random((b, h, w)) < 0.4
    m[:, 10:20, 12:30] = True  # some pixels inside the SSIM crop for every image
    return m


@pytest.mark.parametrize("layout", ["B1HW_bool", "BHW_float", "HW_bool", "B1HW_torch"])
def test_11_masked_l1_mse_psnr_average_over_mask_pixels_only(rng, layout):
    pred, target = _pair(rng, (2, 3, 40, 44))
    m = _masks(rng, 2, 40, 44)
    if layout == "HW_bool":
        m[1] = m[0]
    arg = {
        "B1HW_bool": m[:, None],
        "BHW_float": m.astype(np.float32),
        "HW_bool": m[0],
        "B1HW_torch": torch.from_numpy(m[:, None]),
    }[layout]
    err = pred - target
    l1_ref = [np.abs(err[i][:, m[i]]).mean() for i in range(2)]
    mse_ref = [(err[i][:, m[i]] ** 2).mean() for i in range(2)]
    np.testing.assert_allclose(pm.l1(pred, target, arg, reduction="none"), l1_ref, rtol=1e-12)
    np.testing.assert_allclose(pm.mse(pred, target, arg, reduction="none"), mse_ref, rtol=1e-12)
    np.testing.assert_allclose(pm.psnr(pred, target, arg, reduction="none"), -10 * np.log10(mse_ref), rtol=1e-12)
    assert pm.l1(pred, target, arg) == pytest.approx(np.mean(l1_ref), rel=1e-12)


def test_12_masked_ssim_is_the_mean_of_the_ssim_map_over_mask_pixels_inside_the_crop(rng):
    pred, target = _pair(rng, (2, 3, 40, 44))
    m = _masks(rng, 2, 40, 44)
    ref = []
    for i in range(2):
        _, full = _sk_ssim(pred[i], target[i], full=True)  # (H, W, C)
        inside = m[i].copy()
        inside[:5], inside[-5:], inside[:, :5], inside[:, -5:] = False, False, False, False
        ref.append(full[inside].mean())
    np.testing.assert_allclose(pm.ssim(pred, target, m[:, None], reduction="none"), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        pm.dssim(torch.from_numpy(pred), torch.from_numpy(target), torch.from_numpy(m), reduction="none").numpy(),
        (1 - np.array(ref)) / 2,
        atol=1e-12,
    )
    # a full mask is the unmasked SSIM
    assert pm.ssim(pred, target, np.ones((40, 44), bool)) == pytest.approx(pm.ssim(pred, target), abs=1e-15)


def test_13_masked_delta_e2000_is_the_mean_over_mask_pixels(rng):
    pred, target = _pair(rng, (2, 3, 24, 30))
    m = _masks(rng, 2, 24, 30)
    de = _colour_de00(pred, target)  # (2, H, W)
    ref = [de[i][m[i]].mean() for i in range(2)]
    np.testing.assert_allclose(pm.delta_e2000(pred, target, m, reduction="none"), ref, rtol=0, atol=1e-10)


# ----------------------------------------------------------------------------- CIEDE2000


def test_14_delta_e2000_matches_colour_science_per_pixel_on_srgb_images(rng):
    pred, target = _pair(rng, (2, 3, 64, 80))
    pred[:, :, :3] = 0.0  # black rows: zero chroma, the special case of the hue terms
    target[:, :, 1:5, :7] = pred[:, :, 1:5, :7]  # identical pixels: dE = 0
    ref = _colour_de00(pred, target)
    got = pm.delta_e2000_map(pred, target)
    assert got.shape == (2, 1, 64, 80)
    np.testing.assert_allclose(got[:, 0], ref, rtol=0, atol=1e-10)
    assert pm.delta_e2000(pred, target) == pytest.approx(ref.mean(), abs=1e-10)
    got32 = pm.delta_e2000_map(torch.from_numpy(pred).float(), torch.from_numpy(target).float())
    assert float((got32[:, 0].double() - torch.from_numpy(ref)).abs().max()) < 1e-3


def test_15_delta_e2000_linear_encoding_skips_the_srgb_decoding(rng):
    pred, target = _pair(rng, (1, 3, 20, 24))
    lab = lambda x: colour.XYZ_to_Lab(colour.RGB_to_XYZ(np.moveaxis(x, -3, -1), SRGB))  # noqa: E731
    ref = colour.delta_E(lab(pred), lab(target), method="CIE 2000")
    np.testing.assert_allclose(pm.delta_e2000_map(pred, target, encoding="linear")[:, 0], ref, atol=1e-10)


def test_16_ciede2000_reproduces_the_sharma_2005_test_pairs():
    lab1 = np.array([p[0] for p in SHARMA_2005])
    lab2 = np.array([p[1] for p in SHARMA_2005])
    published = np.array([p[2] for p in SHARMA_2005])
    got = pm.ciede2000(lab1, lab2)
    np.testing.assert_allclose(got, published, rtol=0, atol=1e-4)  # published to 4 decimals
    np.testing.assert_allclose(got, colour.delta_E(lab1, lab2, method="CIE 2000"), rtol=0, atol=1e-10)
    np.testing.assert_allclose(pm.ciede2000(lab2, lab1), got, rtol=0, atol=1e-10)  # symmetric
    got_t = pm.ciede2000(torch.tensor(lab1), torch.tensor(lab2))
    np.testing.assert_allclose(got_t.numpy(), published, atol=1e-4)


def test_17_ciede2000_matches_colour_science_on_random_lab_including_hue_wraps(rng):
    n = 5000
    lab1 = np.stack([rng.random(n) * 100, rng.random(n) * 200 - 100, rng.random(n) * 200 - 100], -1)
    lab2 = lab1 + rng.standard_normal((n, 3)) * [5, 20, 20]
    lab2[:50, 1:] = 0.0  # achromatic partners
    # hue differences near (not at: that is an ill-posed tie) 180 degrees, both sides
    turn = np.deg2rad(180.0 + rng.choice([-1.0, 1.0], 50) * rng.uniform(0.01, 2.0, 50))
    a, b = lab1[50:100, 1], lab1[50:100, 2]
    lab2[50:100, 1], lab2[50:100, 2] = a * np.cos(turn) - b * np.sin(turn), a * np.sin(turn) + b * np.cos(turn)
    np.testing.assert_allclose(pm.ciede2000(lab1, lab2), colour.delta_E(lab1, lab2, method="CIE 2000"), atol=1e-10)
    # channel-first layout and broadcasting against one reference colour
    img = np.moveaxis(lab1[:4800].reshape(2, 40, 60, 3), -1, 1)
    ref = colour.delta_E(np.moveaxis(img, 1, -1), lab2[0], method="CIE 2000")
    np.testing.assert_allclose(pm.ciede2000(img, lab2[0].reshape(3, 1, 1), dim=-3), ref, atol=1e-10)


# ----------------------------------------------------------------------------- gradients


def test_18_gradcheck_ssim_and_dssim_in_float64(rng):
    pred, target = _pair(rng, (1, 2, 11, 13))
    p = torch.tensor(pred, requires_grad=True)
    t = torch.tensor(target)
    assert torch.autograd.gradcheck(lambda x: pm.ssim(x, t), (p,))
    m = torch.from_numpy(_masks(rng, 1, 11, 13))
    assert torch.autograd.gradcheck(lambda x: pm.dssim(x, t, m), (p,), fast_mode=True)


def test_19_gradcheck_delta_e2000_in_float64(rng):
    pred, target = _pair(rng, (1, 3, 4, 5))
    p = torch.tensor(0.05 + 0.9 * pred, requires_grad=True)
    t = torch.tensor(0.05 + 0.9 * target, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, y: pm.delta_e2000(x, y), (p, t))
    lab1 = torch.tensor([[50.0, 2.6772, -79.7751], [61.29, 3.72, -5.39]], dtype=torch.float64, requires_grad=True)
    lab2 = torch.tensor([[52.0, 0.5, -82.7485], [61.43, 2.25, -4.96]], dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda x: pm.ciede2000(x, lab2), (lab1,))


def test_20_gradients_stay_finite_at_black_grey_and_identical_pixels():
    p = torch.zeros(1, 3, 12, 12, dtype=torch.float64)
    p[:, :, 6:] = 0.5  # grey
    p.requires_grad_()
    t = torch.zeros(1, 3, 12, 12, dtype=torch.float64)
    t[:, :, :, 6:] = 0.5
    for f in (pm.delta_e2000, pm.ssim, pm.l1):
        for target in (t, p.detach().clone()):
            (g,) = torch.autograd.grad(f(p, target), p)
            assert torch.isfinite(g).all()
    lab = torch.zeros(2, 3, dtype=torch.float64, requires_grad=True)
    (g,) = torch.autograd.grad(pm.ciede2000(lab, torch.tensor([[50.0, 0.0, 0.0], [0.0, 0.0, 0.0]])).sum(), lab)
    assert torch.isfinite(g).all()


# ----------------------------------------------------------------------------- bad input


def test_21_mismatched_shapes_are_value_errors_naming_both_shapes(rng):
    a = rng.random((2, 3, 16, 16))
    b = rng.random((2, 3, 16, 15))
    for f in (pm.l1, pm.mse, pm.psnr, pm.ssim, pm.dssim, pm.delta_e2000, pm.ssim_map, pm.delta_e2000_map):
        with pytest.raises(ValueError, match=r"\(2, 3, 16, 16\).*\(2, 3, 16, 15\)"):
            f(a, b)
    with pytest.raises(ValueError, match=r"\(16, 16\)"):
        pm.l1(a[0, 0], a[0, 0])  # not an image


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_22_nan_or_inf_in_either_image_is_a_value_error(rng, bad):
    a = rng.random((1, 3, 16, 16))
    b = a.copy()
    b[0, 2, 3, 4] = bad
    for f in (pm.l1, pm.mse, pm.psnr, pm.ssim, pm.dssim, pm.delta_e2000):
        with pytest.raises(ValueError, match="target holds 1 non-finite"):
            f(torch.from_numpy(a), torch.from_numpy(b))
        with pytest.raises(ValueError, match="pred holds 1 non-finite"):
            f(b, a)


def test_23_empty_or_malformed_masks_are_value_errors(rng):
    a, b = _pair(rng, (2, 3, 20, 20))
    empty = np.ones((2, 1, 20, 20), bool)
    empty[1] = False
    for f in (pm.l1, pm.mse, pm.psnr, pm.ssim, pm.dssim, pm.delta_e2000):
        with pytest.raises(ValueError, match=r"no pixels.*\[1\]"):
            f(a, b, empty)
    border_only = np.zeros((20, 20), bool)
    border_only[:4] = True
    assert np.isfinite(pm.l1(a, b, border_only))
    with pytest.raises(ValueError, match="no pixels at least 5 px from the border"):
        pm.ssim(a, b, border_only)
    with pytest.raises(ValueError, match=r"mask \(3, 1, 20, 20\) does not fit images \(2, 3, 20, 20\)"):
        pm.l1(a, b, np.ones((3, 1, 20, 20)))
    with pytest.raises(ValueError, match=r"mask \(20, 21\)"):
        pm.mse(a, b, np.ones((20, 21)))
    with pytest.raises(ValueError, match="only 0 and 1"):
        pm.l1(a, b, np.full((20, 20), 0.5))


def test_24_other_bad_arguments_are_value_errors(rng):
    a, b = _pair(rng, (1, 3, 10, 20))
    with pytest.raises(ValueError, match="at least 11x11"):
        pm.ssim(a, b)
    with pytest.raises(ValueError, match=r"3 channel\(s\), got shape \(1, 2, 10, 20\)"):
        pm.delta_e2000(a[:, :2], b[:, :2])
    with pytest.raises(ValueError, match="reduction"):
        pm.l1(a, b, reduction="sum")
    with pytest.raises(ValueError, match="encoding"):
        pm.delta_e2000(a, b, encoding="gamma")
    with pytest.raises(ValueError, match="data_range"):
        pm.psnr(a, b, data_range=0.0)
    with pytest.raises(ValueError, match=r"lab1 must have shape \(\.\.\., 3\), got \(4, 2\)"):
        pm.ciede2000(np.zeros((4, 2)), np.zeros((4, 3)))


def test_25_best_gain_is_the_least_squares_gain_and_scales_inversely(rng):
    """``best_gain`` equals brute-force least squares over a fine gain grid (to the grid's step), scales
    as 1/k when the prediction is scaled by k (so gain * pred is scale-free), and honours the mask."""
    pred = rng.uniform(0.1, 1.0, (2, 3, 8, 8))
    target = 1.7 * pred + rng.normal(0.0, 0.05, pred.shape)
    mask = rng.random((2, 1, 8, 8)) > 0.3
    g = pm.best_gain(pred, target, mask)
    grid = np.linspace(1.0, 2.5, 15001)
    for b in range(2):
        m = np.broadcast_to(mask[b], pred[b].shape)
        sse = [((k * pred[b] - target[b])[m] ** 2).sum() for k in grid]
        assert abs(g[b] - grid[int(np.argmin(sse))]) <= 1e-4
    for k in (0.25, 3.7):
        np.testing.assert_allclose(pm.best_gain(k * pred, target, mask), g / k, rtol=1e-12)
    # pixels outside the mask do not move it
    wild = np.where(mask, pred, 100.0)
    np.testing.assert_allclose(pm.best_gain(wild, target, mask), g, rtol=1e-12)
    assert np.array_equal(pm.best_gain(np.zeros_like(pred), target), [1.0, 1.0])
    with pytest.raises(ValueError, match="mask selects no pixels"):
        pm.best_gain(pred, target, np.zeros((2, 1, 8, 8), bool))
