"""Specification of physrelight.image_model: i = s * albedo * shading(n; L) and the lighting solve."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import envmap, image_model, rotations, sh

from .conftest import positive_coeffs


def random_scene(b: int = 2, h: int = 12, w: int = 16, order: int = 2, seed: int = 0, dtype=torch.float64):
    """Random unit normals, albedo in [0.05, 0.85], shadow in [0.1, 1], positive lighting."""
    g = torch.Generator().manual_seed(seed)
    n = torch.randn(b, 3, h, w, generator=g, dtype=dtype)
    n = n / n.norm(dim=1, keepdim=True)
    a = 0.05 + 0.8 * torch.rand(b, 3, h, w, generator=g, dtype=dtype)
    s = 0.1 + 0.9 * torch.rand(b, 1, h, w, generator=g, dtype=dtype)
    light = torch.stack([torch.from_numpy(positive_coeffs(order, seed + i)) for i in range(b)]).to(dtype)
    return n, a, s, light


def test_01_render_is_shadow_times_albedo_times_shading() -> None:
    n, a, s, light = random_scene()
    i = image_model.render(a, n, light, s)
    per_pixel = sh.shading(light[:, None, None], n.permute(0, 2, 3, 1)).permute(0, 3, 1, 2)
    torch.testing.assert_close(i, s * a * per_pixel, rtol=1e-12, atol=1e-12)


def test_02_white_furnace_shading_is_one_and_sky_pixels_are_zero() -> None:
    n, _, _, _ = random_scene(b=1)
    n[:, :, :3] = 0.0  # sky rows: no surface
    furnace = sh.project_envmap(np.ones((32, 64, 3)), 2)
    out = image_model.shading(n, torch.from_numpy(furnace))
    torch.testing.assert_close(out[:, :, 3:], torch.ones_like(out[:, :, 3:]), rtol=1e-12, atol=1e-12)
    assert torch.all(out[:, :, :3] == 0)


def test_03_camera_frame_shading_equals_world_frame_shading() -> None:
    # Lighting moved into a camera frame with D(R_wc), normals with R_wc: same shading.
    n_world, _, _, _ = random_scene(b=1)
    light = torch.from_numpy(positive_coeffs(4, 9))
    r_wc = torch.from_numpy(rotations.random_rotation(4))
    n_cam = torch.einsum("ij,bjhw->bihw", r_wc, n_world)
    world = image_model.shading(n_world, light)
    cam = image_model.shading(n_cam, sh.rotate(light, r_wc))
    torch.testing.assert_close(cam, world, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("order", [1, 2, 4])
def test_04_solve_recovers_the_lighting_of_a_noiseless_image_despite_garbage_in_the_sky(order: int) -> None:
    n, a, s, light = random_scene(order=order, h=16, w=20)
    i = image_model.render(a, n, light, s)
    mask = torch.ones_like(s)
    mask[:, :, :4] = 0
    i[:, :, :2] = float("nan")  # garbage the solve must never read
    i[:, :, 2:4] = 1e6
    n[:, :, 3] = 0.0
    got = image_model.solve_lighting(i, a, n, mask, s, order=order)
    # Odd bands above 1 have A_l = 0: invisible in the image, returned as 0.
    seen = torch.from_numpy(np.repeat(sh.clamped_cosine_coeffs(order) != 0, [2 * l + 1 for l in range(order + 1)]))
    torch.testing.assert_close(got[:, seen], light[:, seen], rtol=1e-6, atol=1e-6 * float(light.abs().max()))
    assert torch.all(got[:, ~seen].abs() < 1e-9)


def test_05_soft_mask_weights_and_unbatched_input_still_solve_exactly() -> None:
    n, a, s, light = random_scene(b=1)
    i = image_model.render(a, n, light, s)
    soft = torch.rand(1, 1, 12, 16, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    got = image_model.solve_lighting(i[0], a[0], n[0], soft[0], s[0])
    assert got.shape == (9, 3)
    torch.testing.assert_close(got, light[0], rtol=1e-6, atol=1e-6)


def test_06_a_single_wall_is_solved_without_blowing_up() -> None:
    # All normals equal: L is not identifiable, but the ridge keeps the solve finite
    # and the solution still re-renders the image.
    n, a, s, light = random_scene(b=1)
    n[:] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)[None, :, None, None]
    i = image_model.render(a, n, light, s)
    got = image_model.solve_lighting(i, a, n, torch.ones_like(s), s)
    assert torch.isfinite(got).all()
    torch.testing.assert_close(image_model.render(a, n, got, s), i, rtol=1e-5, atol=1e-6)


def test_07_deep_shadow_pixels_do_not_enter_the_solve() -> None:
    n, a, s, light = random_scene()
    s[:, :, :5] = 0.0
    i = image_model.render(a, n, light, s)
    i[:, :, :5] += 0.3  # would bias L if i / s were read there
    got = image_model.solve_lighting(i, a, n, torch.ones_like(s), s)
    torch.testing.assert_close(got, light, rtol=1e-6, atol=1e-6)


def test_08_residual_is_the_detail_the_model_does_not_explain() -> None:
    n, a, s, light = random_scene()
    i = image_model.render(a, n, light, s)
    torch.testing.assert_close(image_model.residual(i, a, n, light, s), torch.zeros_like(i), atol=1e-14, rtol=0)
    detail = 0.01 * torch.randn(i.shape, generator=torch.Generator().manual_seed(1), dtype=i.dtype)
    torch.testing.assert_close(image_model.residual(i + detail, a, n, light, s), detail, atol=1e-14, rtol=0)


def test_09_gradcheck_shading_render_and_solve() -> None:
    n, a, s, light = random_scene(b=1, h=4, w=5)
    n.requires_grad_(True)
    a.requires_grad_(True)
    light.requires_grad_(True)
    s.requires_grad_(True)
    assert torch.autograd.gradcheck(image_model.shading, (n, light))
    assert torch.autograd.gradcheck(image_model.render, (a, n, light, s))
    i = image_model.render(a, n, light, s).detach().requires_grad_(True)
    mask = torch.ones_like(s).detach()
    assert torch.autograd.gradcheck(lambda i_, a_, s_: image_model.solve_lighting(i_, a_, n.detach(), mask, s_),
                                    (i, a, s))


def test_10_numpy_in_numpy_out() -> None:
    n, a, s, light = random_scene(b=1)
    out = image_model.render(a.numpy(), n.numpy(), light.numpy(), s.numpy())
    assert isinstance(out, np.ndarray) and out.shape == (1, 3, 12, 16)
    solved = image_model.solve_lighting(out, a.numpy(), n.numpy(), np.ones((1, 1, 12, 16)), s.numpy())
    np.testing.assert_allclose(solved, light.numpy(), atol=1e-6)


def test_11_lambertian_sphere_matches_brute_force_irradiance_to_the_order4_bound(hdris) -> None:
    # Normals of a sphere seen from the camera (camera = world here): shading from the
    # order-4 SH vs brute-force irradiance / pi, within the truncation error.
    env = hdris["forest"]
    h = w = 24
    v, u = np.meshgrid((np.arange(h) + 0.5) / h * 2 - 1, (np.arange(w) + 0.5) / w * 2 - 1, indexing="ij")
    r2 = u**2 + v**2
    inside = r2 < 1
    n = np.zeros((h, w, 3))
    n[inside] = np.stack([u[inside], -v[inside], np.sqrt(1 - r2[inside])], axis=-1)
    shade = image_model.shading(torch.from_numpy(n).permute(2, 0, 1)[None], torch.from_numpy(sh.project_envmap(env, 4)))
    shade = shade[0].permute(1, 2, 0).numpy()
    exact = envmap.irradiance_reference(env, n[inside]) / math.pi
    err = np.abs(shade[inside] - exact).max()
    assert err <= 0.094 * envmap.luminance_integral(env) / math.pi
    assert np.all(shade[~inside] == 0)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda n, a, s, L: image_model.solve_lighting(a, a, n, torch.zeros_like(s), s), "usable pixel"),
        (lambda n, a, s, L: image_model.solve_lighting(a[:, :, :2, :4], a[:, :, :2, :4], n[:, :, :2, :4],
                                                       torch.ones_like(s)[:, :, :2, :4], None, order=2), "at least 9"),
        (lambda n, a, s, L: image_model.solve_lighting(a, a[:, :, :5], n, torch.ones_like(s), s), "albedo"),
        (lambda n, a, s, L: image_model.solve_lighting(a, a, n[:, :2], torch.ones_like(s), s), "3 channel"),
        (lambda n, a, s, L: image_model.solve_lighting(a.masked_fill(torch.ones_like(a, dtype=torch.bool), float("nan")),
                                                       a, n, torch.ones_like(s), s), "NaN"),
        (lambda n, a, s, L: image_model.render(a, n, L, s * 2), r"\[0, 1\]"),
        (lambda n, a, s, L: image_model.render(a, n, L[:, :8], s), "K = "),
        (lambda n, a, s, L: image_model.shading(n[0], L), r"\(B, C, H, W\)"),
    ],
)
def test_12_bad_input_raises_a_clear_value_error(make, match: str) -> None:
    n, a, s, light = random_scene()
    with pytest.raises(ValueError, match=match):
        make(n, a, s, light)


def _subspace_prior(k: int = 8, seed: int = 0):
    from physrelight.lighting_prior import fit_lighting_prior

    lights = np.stack([positive_coeffs(2, seed + i) for i in range(60)])
    return fit_lighting_prior(lights, k=k)


def test_13_map_solve_recovers_a_lighting_of_the_subspace_and_falls_back_to_the_prior_mean() -> None:
    prior = _subspace_prior()
    n, a, s, _ = random_scene(b=2, seed=3)
    truth = torch.stack([prior.decode(torch.tensor([0.5, -1.0, 0.3, 0, 0, 0, 0, 0.2], dtype=torch.float64)),
                         prior.decode(torch.zeros(8, dtype=torch.float64))])
    i = image_model.render(a, n, truth, s)
    mask = torch.ones_like(s)
    # Almost no noise: the least-squares fit inside the subspace, which the noiseless image pins down.
    tight = image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=1e-7)
    torch.testing.assert_close(tight, truth, atol=1e-8, rtol=0)
    # Overwhelming noise: the data says nothing, the prior's mean comes back.
    loose = image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=1e6)
    torch.testing.assert_close(loose, prior.mean.reshape(9, 3).expand(2, 9, 3).to(loose), atol=1e-6, rtol=0)


def test_14_map_solve_is_the_stationary_point_of_its_objective_and_differentiable() -> None:
    prior = _subspace_prior(k=6, seed=10)
    n, a, s, light = random_scene(b=1, h=6, w=7, seed=5)
    noise = torch.randn(1, 3, 6, 7, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    i = image_model.render(a, n, light, s) * (1 + 0.1 * noise)  # not explained exactly by any lighting
    mask = torch.ones_like(s)
    out = image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=0.3)
    # The objective written out pixel by pixel; its gradient in z vanishes at the solution.
    basis = prior.components * prior.scale[:, None]
    z = ((out.reshape(1, 27) - prior.mean) @ basis.T @ torch.linalg.inv(basis @ basis.T)).detach().requires_grad_(True)
    lit = (prior.mean + z @ basis).reshape(1, 9, 3)
    target = i / s
    sigma2 = 0.3**2 * (target**2).mean()
    objective = ((target - a * image_model.shading(n, lit)) ** 2).sum() + sigma2 * (z**2).sum()
    (grad,) = torch.autograd.grad(objective, z)
    assert float(grad.abs().max()) < 1e-8 * float(objective.detach())
    torch.testing.assert_close(lit.detach(), out)  # out lies in the subspace
    a_ = a.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(lambda al: image_model.solve_lighting_map(i.detach(), al, n, mask, prior, s, 0.3),
                                    (a_,))
    with pytest.raises(ValueError, match="noise"):
        image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=0.0)


def test_15_relative_map_solve_is_scale_equivariant_and_fits_the_prior_shape_at_any_exposure() -> None:
    prior = _subspace_prior(k=6, seed=20)
    n, a, s, light = random_scene(b=2, h=6, w=7, seed=8)
    noise = torch.randn(2, 3, 6, 7, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    i = image_model.render(a, n, light, s) * (1 + 0.1 * noise)
    mask = torch.ones_like(s)
    base = image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=0.3, relative=True)
    for c in (1 / 8, 5.0):  # an exposure change scales the lighting and nothing else
        scaled = image_model.solve_lighting_map(c * i, a, n, mask, prior, shadow=s, noise=0.3, relative=True)
        torch.testing.assert_close(scaled, c * base, atol=1e-12, rtol=1e-9)
    absolute = image_model.solve_lighting_map(i / 8, a, n, mask, prior, shadow=s, noise=0.3)
    assert not torch.allclose(absolute * 8, image_model.solve_lighting_map(i, a, n, mask, prior, shadow=s, noise=0.3))
    # The prior's mean lighting photographed at any exposure comes back exactly (the level is
    # the least-squares fit of the mean, the shape then needs no correction) ...
    mean = prior.mean.reshape(1, 9, 3).expand(2, 9, 3)
    for c in (0.125, 3.0):
        photo = image_model.render(a, n, c * mean, s)
        got = image_model.solve_lighting_map(photo, a, n, mask, prior, shadow=s, noise=0.3, relative=True)
        torch.testing.assert_close(got, c * mean, atol=1e-10, rtol=1e-8)
    # ... and the solution is the stationary point of the objective at that level.
    target = i / s
    basis = prior.components * prior.scale[:, None]
    mean_img = a * image_model.shading(n, mean)
    t = (target * mean_img).sum((1, 2, 3)) / (mean_img**2).sum((1, 2, 3))
    z = ((base.reshape(2, 27) / t[:, None] - prior.mean) @ basis.T @ torch.linalg.inv(basis @ basis.T))
    z = z.detach().requires_grad_(True)
    lit = (t[:, None] * (prior.mean + z @ basis)).reshape(2, 9, 3)
    sigma2 = 0.3**2 * (target**2).mean((1, 2, 3))
    objective = (((target - a * image_model.shading(n, lit)) ** 2).sum((1, 2, 3)) + sigma2 * (z**2).sum(1)).sum()
    (grad,) = torch.autograd.grad(objective, z)
    assert float(grad.abs().max()) < 1e-8 * float(objective.detach())
    torch.testing.assert_close(lit.detach(), base)
    a_ = a[:1].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda al: image_model.solve_lighting_map(i[:1].detach(), al, n[:1], mask[:1], prior, s[:1], 0.3, relative=True),
        (a_,))
