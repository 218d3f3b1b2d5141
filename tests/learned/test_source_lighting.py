"""learned.source_lighting: the source-lighting estimate (MAP in the prior's subspace, the sky's
pixels, robust weights), against synthetic Lambertian images with a known lighting.

Each test renders the image model exactly (``albedo * shading(n; L)``, radiance SH ``L`` in the
camera frame) so what is asserted is the estimator's physics, not the network's."""

from __future__ import annotations

import math

import pytest
import torch

from learned.lighting import load_prior
from learned.source_lighting import (SourceLightingConfig, camera_directions, cauchy_weights, sky_observations,
                                     solve_source_lighting)
from physrelight import image_model, panorama, sh

torch.set_num_threads(1)
RES = 48


@pytest.fixture(scope="module")
def prior():
    return load_prior()


def sphere_normals(res: int = RES) -> tuple[torch.Tensor, torch.Tensor]:
    """``(1, 3, res, res)`` camera-frame normals of a sphere filling the frame (orthographic view) and
    ``(1, 1, res, res)`` bool mask of its disc."""
    v, u = torch.meshgrid(torch.arange(res) + 0.5, torch.arange(res) + 0.5, indexing="ij")
    x, y = u / res * 2 - 1, -(v / res * 2 - 1)
    inside = x**2 + y**2 < 0.95
    z = torch.sqrt((1 - x**2 - y**2).clamp_min(0))
    return (torch.stack([x, y, z]) * inside)[None].double(), inside[None, None]


def shading_error(est: torch.Tensor, truth: torch.Tensor, normals: torch.Tensor, mask: torch.Tensor) -> float:
    """Scale-invariant relative error of the shading (learned.evaluate's definition), ``(9, 3)`` each."""
    from learned.evaluate import shading_error as se

    return se(est.double(), truth.double(), normals[0], mask[0])


def lambertian_scene(prior, seed: int, z_scale: float = 1.0):
    """A sphere of random grey-ish albedo under a lighting drawn from the prior: image, albedo,
    normals, mask, truth ``(9, 3)``."""
    g = torch.Generator().manual_seed(seed)
    z = z_scale * torch.randn(prior.dim, generator=g, dtype=torch.float64)
    truth = prior.decode(z)
    n, inside = sphere_normals()
    albedo = (0.2 + 0.6 * torch.rand(1, 3, 1, 1, generator=g, dtype=torch.float64)).expand(1, 3, RES, RES) * inside
    image = image_model.render(albedo, n, truth)
    return image, albedo, n, inside, truth


def ones(c: int = 1) -> torch.Tensor:
    return torch.ones(1, c, RES, RES, dtype=torch.float64)


def test_01_camera_directions_match_the_panorama_rays():
    K = torch.tensor([[40.0, 0, 25.0], [0, 44.0, 23.0], [0, 0, 1]], dtype=torch.float64)
    ours = camera_directions(K, 46, 50)
    ref = panorama.camera_rays(K, torch.eye(3, dtype=torch.float64), 46, 50, 1)[..., 0, :]
    assert torch.allclose(ours, ref, atol=1e-12)
    # the principal point looks straight ahead (-z), the top row up (+y)
    assert float(ours[0, 25, 1]) > 0 and float(ours[23, 25, 2]) < -0.99


def test_02_with_every_switch_off_it_is_the_relative_map_solve(prior):
    image, albedo, n, inside, _ = lambertian_scene(prior, seed=0)
    g = torch.Generator().manual_seed(1)
    noisy = image * (1 + 0.05 * torch.randn(image.shape, generator=g, dtype=torch.float64))
    shadow = 0.5 + 0.5 * torch.rand(1, 1, RES, RES, generator=g, dtype=torch.float64)
    ours = solve_source_lighting(noisy, albedo, n, shadow, inside, prior,
                                 config=SourceLightingConfig(noise=0.7, robust=False, use_shadow=True))
    ref = image_model.solve_lighting_map(noisy, albedo, n, inside.double(), prior, shadow=shadow, noise=0.7,
                                         relative=True)
    assert torch.allclose(ours.double(), ref.double(), rtol=1e-5, atol=1e-6 * float(ref.abs().max()))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_03_map_recovers_a_lighting_drawn_from_the_prior(prior, seed):
    """Noise-free Lambertian sphere: the shading of the estimate on the visible normals matches
    within 0.5 % (scale-invariant) at a small noise constant; a larger constant trusts the prior's
    mean more and the fit less, so its error is larger."""
    image, albedo, n, inside, truth = lambertian_scene(prior, seed)
    est = solve_source_lighting(image, albedo, n, ones(), inside, prior, config=SourceLightingConfig(noise=0.05, robust=False))
    assert shading_error(est[0], truth, n, inside) < 0.005
    loose = solve_source_lighting(image, albedo, n, ones(), inside, prior, config=SourceLightingConfig(noise=1.0, robust=False))
    assert shading_error(loose[0], truth, n, inside) > shading_error(est[0], truth, n, inside)


def test_04_the_estimate_follows_the_exposure(prior):
    """Exposure-equivariant, with the sky term on too: 4 x the photo gives 4 x the lighting."""
    image, albedo, n, inside, _ = lambertian_scene(prior, seed=4, z_scale=0.3)  # positive shading
    K = torch.tensor([[RES, 0, RES / 2], [0, RES, RES / 2], [0, 0, 1]], dtype=torch.float64)
    sky = ~inside
    rad = (torch.as_tensor(sh.basis(camera_directions(K, RES, RES), 2)) @ prior.mean.reshape(9, 3).double())
    photo = torch.where(sky, rad.clamp_min(0.01).permute(2, 0, 1)[None] * 0.3, image)
    cfg = SourceLightingConfig(sky=True, robust=True, clip_level=1e9)
    a = solve_source_lighting(photo, albedo, n, ones(), inside, prior, sky=sky, K=K, config=cfg)
    b = solve_source_lighting(4.0 * photo, albedo, n, ones(), inside, prior, sky=sky, K=K, config=cfg)
    assert torch.allclose(b, 4.0 * a, rtol=1e-4, atol=1e-6 * float(a.abs().max()))


def zenith_sky(prior, seed: int):
    """A camera looking at the zenith (90 deg field of view: world up is the camera's -z) whose
    whole frame is a smooth sky: the order-2 radiance of a lighting drawn near the prior's mean."""
    f = RES / 2 / math.tan(math.radians(45))
    K = torch.tensor([[f, 0, RES / 2], [0, f, RES / 2], [0, 0, 1]], dtype=torch.float64)
    g = torch.Generator().manual_seed(seed)
    truth = prior.decode(0.3 * torch.randn(prior.dim, generator=g, dtype=torch.float64))
    rad = torch.as_tensor(sh.basis(camera_directions(K, RES, RES), 2)) @ truth
    return rad.permute(2, 0, 1)[None], K, truth


def upper_hemisphere_error(est: torch.Tensor, truth: torch.Tensor) -> float:
    """Relative rms error of the order-2 radiance over 256 directions of the upper hemisphere (camera -z)."""
    dirs = torch.as_tensor(sh.fibonacci_sphere(512))
    dirs = dirs[dirs[:, 2] < 0]
    y = torch.as_tensor(sh.basis(dirs, 2))
    return float((y @ est.double() - y @ truth.double()).norm() / (y @ truth.double()).norm())


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_05_the_sky_term_alone_recovers_the_upper_hemisphere(prior, seed):
    """No foreground at all: the sky pixels alone give the upper hemisphere's radiance within 2 % (rms)
    when the prior says the sky is smooth (higher bands at 0.1 of the panoramas' spread) and the pixels
    are trusted (noise 0.5 %); at the panoramas' spread the higher bands take a share of the visible
    variation and the error grows (below 25 %), which is why band_scale is a setting."""
    image, K, truth = zenith_sky(prior, seed)
    sky = torch.ones(1, 1, RES, RES, dtype=torch.bool)
    zeros = torch.zeros(1, 3, RES, RES, dtype=torch.float64)
    no_fg = torch.zeros(1, 1, RES, RES, dtype=torch.bool)
    cfg = SourceLightingConfig(sky=True, sky_noise=0.005, band_scale=0.1, clip_level=1e9, robust=False)
    est = solve_source_lighting(image, zeros, zeros, ones(), no_fg, prior, sky=sky, K=K, config=cfg)
    assert upper_hemisphere_error(est[0], truth) < 0.02
    wide = solve_source_lighting(image, zeros, zeros, ones(), no_fg, prior, sky=sky, K=K,
                                 config=cfg.but(band_scale=1.0))
    assert 0.02 < upper_hemisphere_error(wide[0], truth) < 0.25


def test_06_clipped_sky_pixels_are_dropped(prior):
    """A clipped sun (pixels at the clip level) in the sky changes nothing: those pixels and their
    neighbours are left out, exactly."""
    image, K, _ = zenith_sky(prior, seed=0)
    image = image / float(image.max()) * 0.8  # nothing clipped
    sky = torch.ones(1, 1, RES, RES, dtype=torch.bool)
    d0, r0 = sky_observations(image[0], sky[0], K, clip_level=0.95, max_pixels=RES * RES)
    sunny = image.clone()
    sunny[..., 10:13, 30:33] = 1.0
    d1, r1 = sky_observations(sunny[0], sky[0], K, clip_level=0.95, max_pixels=RES * RES)
    assert d0.shape[0] == RES * RES and d1.shape[0] == RES * RES - 25  # 3 x 3 clipped + their ring
    keep = torch.ones(RES, RES, dtype=torch.bool)
    keep[9:14, 29:34] = False
    assert torch.equal(d1, d0[keep.flatten()]) and torch.equal(r1, r0[keep.flatten()])


def test_07_robust_weights_reject_an_injected_cast_shadow(prior):
    """A pole's cast shadow (a thin band at 0.2 of the light) that the decomposition missed biases
    the plain solve by > 5 % of shading; Cauchy IRLS brings it back below 1 % (the same solve without
    the shadow: 0.1 %; what stays is the band's pixels still weighted a little)."""
    for seed in range(3):
        image, albedo, n, inside, truth = lambertian_scene(prior, seed)
        i, j = torch.meshgrid(torch.arange(RES), torch.arange(RES), indexing="ij")
        band = (j - 0.5 * i - 8).abs() < 3
        shadowed = torch.where(band, 0.2 * image, image)
        cfg = SourceLightingConfig(noise=0.05, robust=False)
        plain = solve_source_lighting(shadowed, albedo, n, ones(), inside, prior, config=cfg)
        robust = solve_source_lighting(shadowed, albedo, n, ones(), inside, prior, config=cfg.but(robust=True))
        assert shading_error(plain[0], truth, n, inside) > 0.05
        assert shading_error(robust[0], truth, n, inside) < 0.01


def test_08_cauchy_weights_by_hand():
    """|r| = 1 for all but one residual: sigma = 1.4826, so w(1) = 1 / (1 + (1 / (2.385 sigma))^2) = 0.9261
    and w(50) = 1 / (1 + (50 / 3.5360)^2) = 0.00498."""
    r = torch.tensor([1.0, -1.0] * 20 + [50.0], dtype=torch.float64)
    w = cauchy_weights(r)
    assert abs(float(w[0]) - 1 / (1 + (1 / (2.385 * 1.4826)) ** 2)) < 1e-9
    assert abs(float(w[-1]) - 1 / (1 + (50 / (2.385 * 1.4826)) ** 2)) < 1e-9
    assert float(w[-1]) < 0.005 < 0.92 < float(w[0])


def test_09_bad_inputs_are_refused(prior):
    image, albedo, n, inside, _ = lambertian_scene(prior, seed=0)
    with pytest.raises(ValueError, match="image must have shape"):
        solve_source_lighting(image[0], albedo, n, ones(), inside, prior)
    with pytest.raises(ValueError, match="albedo must have shape"):
        solve_source_lighting(image, albedo[:, :2], n, ones(), inside, prior)
    with pytest.raises(ValueError, match="shadow must have shape"):
        solve_source_lighting(image, albedo, n, ones(3), inside, prior)
    with pytest.raises(ValueError, match="K must have shape"):
        solve_source_lighting(image, albedo, n, ones(), inside, prior, sky=~inside, K=torch.eye(4))
    with pytest.raises(ValueError, match="sky must have shape"):
        solve_source_lighting(image, albedo, n, ones(), inside, prior, sky=~inside[0], K=torch.eye(3))
    with pytest.raises(ValueError, match="usable foreground"):
        solve_source_lighting(image, albedo, n, ones(), torch.zeros_like(inside), prior)
    with pytest.raises(ValueError, match="noise must be a positive number"):
        SourceLightingConfig(noise=0.0)
    with pytest.raises(ValueError, match="iterations"):
        SourceLightingConfig(iterations=0)
    with pytest.raises(ValueError, match="positive focal"):
        camera_directions(torch.diag(torch.tensor([-1.0, 1.0, 1.0])), 8, 8)


def test_10_relighter_estimator_switch():
    """The Relighter's two estimators: "source_map" is the default, "network" the solve exported with the
    network; an unknown name is refused; "source_map" with its switches off (noise 1, the shadow divided)
    gives the same lighting as "network"."""
    from learned import Relighter
    from learned.relight_options import LIGHTING_ESTIMATORS, RelightOptions

    old = Relighter.load()
    assert old.options.lighting_estimator == "source_map"
    assert Relighter.load(options=RelightOptions(lighting_estimator="network")).options.lighting_estimator == "network"
    with pytest.raises(ValueError, match="lighting_estimator must be one of"):
        RelightOptions(lighting_estimator="magic")
    off = SourceLightingConfig(noise=1.0, use_shadow=True, robust=False, sky=False)
    new = Relighter(old.inverse, old.shadow_net, old.prior, old.res,
                    options=RelightOptions(lighting_estimator="source_map", source_config=off))
    assert set(LIGHTING_ESTIMATORS) == {"network", "source_map"}
    g = torch.Generator().manual_seed(0)
    image = torch.rand(2, 3, 64, 64, generator=g) * 0.6 + 0.05
    sky = torch.zeros(2, 1, 64, 64, dtype=torch.bool)
    sky[:, :, :16] = True
    a = old.with_options(lighting_estimator="network")
    la = a.decompose_linear(image, sky)["lighting"]
    lb = new.decompose_linear(image, sky)["lighting"]
    assert torch.allclose(la, lb, rtol=1e-4, atol=1e-6 * float(la.abs().max()))


def test_11_the_grey_world_level_is_what_a_light_meter_reads():
    """``grey_world_level`` gives the factor under which the foreground's median implied albedo is 0.18:
    1 for a scene of median albedo 0.18 lit by exactly ``L``, 2 for albedo 0.36 (or the same photo twice as
    bright: exposure-equivariant), the assumed albedo's inverse; pixels outside the foreground do not count;
    too few pixels give 1; bad shapes and albedos are refused."""
    from learned.source_lighting import GREY_WORLD_ALBEDO, grey_world_level

    g = torch.Generator().manual_seed(0)
    n = torch.nn.functional.normalize(torch.randn(1, 3, 12, 16, generator=g) + torch.tensor([0.0, 1.0, 1.0])[:, None, None], dim=1)
    L = torch.zeros(1, 9, 3, dtype=torch.float64)
    L[0, 0] = 1.0
    L[0, 2] = 0.6  # brighter from above (+Y)
    albedo = torch.full((1, 3, 12, 16), GREY_WORLD_ALBEDO, dtype=torch.float64)
    albedo[..., :, :5] *= torch.rand(1, 3, 12, 5, generator=g, dtype=torch.float64) * 0.5 + 0.5  # below the median
    albedo[..., :, 11:] *= 1.0 + torch.rand(1, 3, 12, 5, generator=g, dtype=torch.float64)  # above it
    photo = albedo * image_model.shading(n.double(), L)
    fg = torch.ones(1, 1, 12, 16, dtype=torch.bool)
    assert float(grey_world_level(photo, n, L, fg)[0]) == pytest.approx(1.0, rel=1e-9)
    assert float(grey_world_level(2 * photo, n, L, fg)[0]) == pytest.approx(2.0, rel=1e-9)
    assert float(grey_world_level(photo, n, L, fg, albedo=0.09)[0]) == pytest.approx(2.0, rel=1e-9)
    bright_sky = photo.clone()
    bright_sky[..., :3, :] = 50.0
    fg[..., :3, :] = False
    assert float(grey_world_level(bright_sky, n, L, fg)[0]) == pytest.approx(
        float(grey_world_level(photo, n, L, fg)[0]), rel=1e-12)
    few = torch.zeros_like(fg)
    few[..., 0, :10] = True
    assert float(grey_world_level(photo, n, L, few)[0]) == 1.0
    with pytest.raises(ValueError, match="albedo"):
        grey_world_level(photo, n, L, fg, albedo=0.0)
    with pytest.raises(ValueError, match="must be"):
        grey_world_level(photo, n[..., :-1], L, fg)


def test_12_one_reweighting_already_pulls_the_solve_towards_the_truth(prior):
    """IRLS counts its solves: ``iterations=1`` is the plain solve (bit for bit the ``robust=False`` one) and
    ``iterations=2`` is one reweighting by the plain solve's residuals. On test 07's missed pole shadow that one
    reweighting already removes at least a quarter of the plain solve's shading error (measured 33-53 %), and
    each further solve removes more (8 solves: below 1 %)."""
    for seed in range(3):
        image, albedo, n, inside, truth = lambertian_scene(prior, seed)
        i, j = torch.meshgrid(torch.arange(RES), torch.arange(RES), indexing="ij")
        shadowed = torch.where((j - 0.5 * i - 8).abs() < 3, 0.2 * image, image)
        cfg = SourceLightingConfig(noise=0.05, robust=True)
        plain = solve_source_lighting(shadowed, albedo, n, ones(), inside, prior, config=cfg.but(robust=False))
        err = [shading_error(solve_source_lighting(shadowed, albedo, n, ones(), inside, prior,
                                                   config=cfg.but(iterations=k))[0], truth, n, inside)
               for k in (1, 2, 3)]
        assert torch.equal(solve_source_lighting(shadowed, albedo, n, ones(), inside, prior,
                                                 config=cfg.but(iterations=1)), plain)
        assert err[1] < 0.75 * err[0] and err[2] < err[1], (seed, err)
