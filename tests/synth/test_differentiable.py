"""Specification of synth.differentiable and synth.analysis_by_synthesis: Mitsuba gradients in torch.

Gradient checks compare two independent unbiased estimates of the same derivative of the
expected image: the adjoint (PRB) gradient and a central finite difference with fixed
primal seeds. Their difference is tested against 4 combined standard errors estimated
from several seeds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import image_model, sh
from synth import analysis_by_synthesis as abs_
from synth import lighting
from synth.differentiable import DifferentiableRenderer, gradient_check

from .test_render import sphere_spec, view


@pytest.fixture(scope="module")
def light() -> lighting.Lighting:
    return lighting.sunsky(5, elevation_deg=35.0, azimuth_deg=200.0, turbidity=3.0, resolution=16)


@pytest.fixture(scope="module")
def sphere(light):
    spec = sphere_spec(with_ground=True)
    cam = view([0.4, 1.8, 4.0], [0, 1.5, 0], size=24)
    return spec, cam, DifferentiableRenderer(spec, cam, light, spp=16, max_depth=3)


def test_01_primal_equals_the_path_tracer(sphere, light) -> None:
    from synth import render

    spec, cam, renderer = sphere
    with torch.no_grad():
        ours = np.stack([renderer.render(None, seed=s, spp=64).numpy() for s in range(4)])
    scene = render.build_scene(spec, [cam], light, spp=64, max_depth=3)
    import mitsuba as mi

    ref = np.stack([np.array(mi.render(scene, sensor=0, spp=64, seed=50 + s)) for s in range(4)])
    a, b = ours.mean(axis=(1, 2, 3)), ref.mean(axis=(1, 2, 3))
    se = math.sqrt(a.var(ddof=1) / 4 + b.var(ddof=1) / 4)
    assert abs(a.mean() - b.mean()) < 4 * se + 1e-3 * b.mean()


@pytest.mark.parametrize("name, h", [("texture/sphere", 0.05), ("texture/ground", 0.05), ("sky", 0.02)])
def test_02_gradients_match_finite_differences_within_mc_noise(sphere, name: str, h: float) -> None:
    _, _, renderer = sphere
    if name == "sky":
        sky = renderer.parameters()["sky"]
        h = h * float(sky.abs().mean()) * math.sqrt(sky.numel())
    c = gradient_check(renderer, name, h, seeds=6)
    assert abs(c.ad) > 4 * c.standard_error, "the derivative should be clearly non-zero"
    # Student-t with ~10 dof: |t| > 4.6 has probability 1e-3; plus float32 round-off of the
    # finite difference (1e-4 relative, generous).
    assert abs(c.ad - c.fd) < 4.6 * c.standard_error + 1e-4 * abs(c.fd), c


def test_03_the_image_is_linear_in_the_sun_irradiance(sphere) -> None:
    _, _, renderer = sphere
    e = renderer.parameters()["sun_irradiance"].clone().requires_grad_(True)
    w = torch.rand(renderer.height, renderer.width, 3, generator=torch.Generator().manual_seed(1))
    img = renderer.render({"sun_irradiance": e}, seed=7)
    (img * w).sum().backward()
    with torch.no_grad():
        without = (renderer.render({"sun_irradiance": torch.zeros(3)}, seed=8) * w).sum()
        full = (renderer.render({"sun_irradiance": e.detach()}, seed=8) * w).sum()
    # L = L_sky + sum_c E_c dL/dE_c exactly for a linear function (up to MC noise of two seeds).
    predicted = float(without) + float((e.grad * e.detach()).sum())
    assert predicted == pytest.approx(float(full), rel=0.05)


def test_04_sh_image_model_agrees_with_mitsuba_in_value_and_gradient(light) -> None:
    # Convex sphere alone, direct light only: Mitsuba vs albedo * shading_SH (order 4);
    # they differ by the SH truncation error plus MC noise.
    spec = sphere_spec(with_ground=False)
    cam = view([0.3, 1.6, 4.0], [0, 1.5, 0], size=24)
    renderer = DifferentiableRenderer(spec, cam, light, spp=64, max_depth=2)
    albedo = renderer.parameters()["texture/sphere"].clone().requires_grad_(True)
    img = renderer.render({"texture/sphere": albedo}, seed=3)
    from synth import render

    scene = render.build_scene(spec, [cam], light, spp=4, max_depth=2)
    geo = render.render_geometry(scene, 0, cam, spp=4, seed=0)
    full = torch.from_numpy(geo.coverage == 1)
    T = np.asarray(cam.world_to_camera, dtype=np.float64)
    normals = torch.from_numpy(geo.normal).permute(2, 0, 1)[None].double()
    sh_cam = torch.from_numpy(light.sh(4, T))
    a = albedo.detach().double().mean(dim=(0, 1)).clone().requires_grad_(True)
    model = (a[None, :, None, None] * image_model.shading(normals, sh_cam))[0].permute(1, 2, 0)
    w = full[..., None].double().expand(-1, -1, 3)
    # Value: mean over the sphere within the order-4 truncation bound (0.094 int L / pi
    # per pixel at worst; the mean is far tighter) -- here 3 %.
    ratio = float((img.detach().double() * w).sum() / (model.detach() * w).sum())
    assert abs(ratio - 1) < 0.03, ratio
    # Gradient w.r.t. the albedo (a constant texture): sum over texels vs the model's.
    (img.double() * w).sum().backward()
    (model * w).sum().backward()
    mitsuba_grad = albedo.grad.double().sum(dim=(0, 1))
    np.testing.assert_allclose(mitsuba_grad.numpy(), a.grad.numpy(), rtol=0.03)


def test_05_a_few_steps_of_analysis_by_synthesis_reduce_the_loss_and_approach_the_albedo(sphere, light) -> None:
    spec, cam, renderer = sphere
    truth = renderer.parameters()
    with torch.no_grad():
        photo = renderer.render(None, seed=999, spp=64)
    grey = {k: torch.full_like(v, 0.5) for k, v in truth.items() if k.startswith("texture/")}
    fitted = abs_.fit(renderer, photo, steps=12, lr=0.1, fit_sky=False, fit_sun=False, init=grey, seed=0)
    assert fitted.losses[-1] < 0.5 * fitted.losses[0]
    # The sphere's albedo moves towards the truth. Its UVs are all (0, 0): with bilinear
    # filtering and wrapping it sees the mean of the four corner texels (the ground's
    # texture is mostly unseen, so it is not a fair yardstick).
    colour = lambda t: t["texture/sphere"][[0, 0, -1, -1], [0, -1, 0, -1]].mean(dim=0)  # noqa: E731
    before = float((colour(grey) - colour(truth)).abs().max())
    after = float((colour(fitted.inputs) - colour(truth)).abs().max())
    assert after < 0.6 * before, (before, after)


def test_06_bad_inputs_are_refused_with_a_clear_error(sphere) -> None:
    _, _, renderer = sphere
    p = renderer.parameters()
    with pytest.raises(ValueError, match="sun direction"):
        renderer.render({"sun_direction": p["sun_direction"].clone().requires_grad_(True)})
    with pytest.raises(ValueError, match="shape"):
        renderer.render({"sky": p["sky"][:, :5]})
    with pytest.raises(ValueError, match="unknown input"):
        renderer.render({"albedo": p["sky"]})
    with pytest.raises(ValueError, match="NaN"):
        renderer.render({"sky": p["sky"] * float("nan")})
