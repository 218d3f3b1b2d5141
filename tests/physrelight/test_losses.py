"""Specification of physrelight.losses: the paper's shadow-free loss, cross-rendering, LAB L2."""

from __future__ import annotations

import colour as colour_science
import numpy as np
import pytest
import torch

from physrelight import image_model, losses, rotations, sh

from .test_image_model import random_scene


def ldr_scene(seed: int = 0):
    """A scene whose shadow-free radiance stays below 1, as the paper's LDR loss assumes."""
    n, a, s, light = random_scene(seed=seed)
    scale = 0.9 / float(image_model.render(a, n, light).max())
    return n, a, s, light * scale


def test_01_loss_vanishes_for_the_model_own_image() -> None:
    n, a, s, light = ldr_scene()
    i = image_model.render(a, n, light, s)
    assert float(losses.shadow_free_loss(i, s, a, n, light)) < 1e-28


def test_02_ignoring_the_shadow_costs_exactly_the_shadowed_energy() -> None:
    n, a, s, light = ldr_scene(1)
    i = image_model.render(a, n, light, s)
    unshadowed = image_model.render(a, n, light)
    expected = ((i - unshadowed) ** 2).sum(dim=1).mean()
    torch.testing.assert_close(losses.shadow_free_loss(i, None, a, n, light), expected, rtol=1e-12, atol=0)


def test_03_min_one_caps_deep_shadow_and_division_is_safe() -> None:
    n, a, s, light = ldr_scene(2)
    i = image_model.render(a, n, light, s) + 0.05  # a little ambient the model lacks
    s[:, :, :3] = 0.0  # i / s would be inf here
    s.requires_grad_(True)
    loss = losses.shadow_free_loss(i, s, a, n, light)
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(s.grad).all()
    # Where s = 0 the target is capped at 1.
    target = losses.shadow_free_target(i, s.detach())
    assert torch.all(target[:, :, :3] == 1.0)


def test_04_mask_excludes_sky_even_when_it_holds_inf() -> None:
    n, a, s, light = ldr_scene(3)
    i = image_model.render(a, n, light, s)
    mask = torch.ones_like(s)
    mask[:, :, :4] = 0
    i[:, :, :4] = float("inf")
    assert float(losses.shadow_free_loss(i, s, a, n, light, mask)) < 1e-28


def test_05_cross_rendering_with_the_true_relative_rotation_is_zero() -> None:
    # The same surface points seen from two camera frames (identity warp): normals and
    # lighting in frame B are R_ab^T times those in A.
    n_a, a, s, light_a = ldr_scene(4)
    r_ab = torch.from_numpy(rotations.random_rotation(8))  # B -> A
    n_b = torch.einsum("ji,bjhw->bihw", r_ab, n_a)  # R^T n_a
    light_b = sh.rotate(light_a, r_ab.T)
    image_b = image_model.render(a, n_b, light_b, s)
    ok = losses.cross_rendering_loss(image_b, s, a, n_a, light_b, r_ab)
    wrong = losses.cross_rendering_loss(image_b, s, a, n_a, light_b, r_ab.T)
    assert float(ok) < 1e-26
    assert float(wrong) > 1e-4


def test_06_lab_l2_matches_colour_science() -> None:
    rng = np.random.default_rng(5)
    p, t = rng.random((1, 3, 6, 7)), rng.random((1, 3, 6, 7))
    lab = lambda x: colour_science.XYZ_to_Lab(colour_science.RGB_to_XYZ(
        np.moveaxis(x[0], 0, -1), colour_science.RGB_COLOURSPACES["sRGB"], apply_cctf_decoding=False))
    expected = (((lab(p) - lab(t)) / 100.0) ** 2).sum(axis=-1).mean()
    assert float(losses.lab_l2(p, t)) == pytest.approx(expected, rel=1e-6)
    assert float(losses.lab_l2(p, p)) == 0.0


def test_07_gradcheck_losses() -> None:
    n, a, s, light = ldr_scene(6)
    n, a, s, light = (x[:1, :, :4, :5].clone() if x.ndim == 4 else x[:1].clone() for x in (n, a, s, light))
    i = image_model.render(a, n, light, s).detach() * 0.9
    a.requires_grad_(True)
    light.requires_grad_(True)
    s.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda a_, l_, s_: losses.shadow_free_loss(i, s_, a_, n, l_), (a, light, s))
    p = torch.rand(1, 3, 4, 5, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x: losses.lab_l2(x, i), (p,))


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda n, a, s, L: losses.shadow_free_loss(a, s, a, n, L, torch.zeros_like(s)), "empty"),
        (lambda n, a, s, L: losses.shadow_free_loss(a, s[:, :, :5], a, n, L), "shadow"),
        (lambda n, a, s, L: losses.lab_l2(a, a[:, :, :5]), "same shape"),
        (lambda n, a, s, L: losses.lab_l2(a, a, encoding="log"), "encoding"),
    ],
)
def test_08_bad_input_raises_a_clear_value_error(make, match: str) -> None:
    n, a, s, light = ldr_scene()
    with pytest.raises(ValueError, match=match):
        make(n, a, s, light)
