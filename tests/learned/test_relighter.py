"""The relighting path of ``learned.Relighter`` on the shipped weights.

Identities that hold whatever the networks learned: the Lambertian methods are the image
model applied to the decomposition, linear in the target; the source-lighting ratio maps the
target into the decomposition's units; sky pixels are never touched. (The full-resolution transfer itself is
specified in tests/physrelight/test_full_resolution.py.)
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physrelight import image_model


@pytest.fixture(scope="module")
def relighter():
    from learned import Relighter

    return Relighter.load()


@pytest.fixture(scope="module")
def photo() -> tuple[torch.Tensor, torch.Tensor]:
    """A smooth-ish linear photo with a sky band on top, ``(2, 3, 48, 48)`` and its sky mask."""
    g = torch.Generator().manual_seed(0)
    base = torch.rand(2, 3, 6, 6, generator=g) * 0.5 + 0.1
    image = torch.nn.functional.interpolate(base, size=(48, 48), mode="bilinear", align_corners=False)
    sky = torch.zeros(2, 1, 48, 48, dtype=torch.bool)
    sky[:, :, :10] = True
    image = torch.where(sky, torch.tensor([0.4, 0.6, 0.9])[None, :, None, None], image)
    return image, sky


def _target(seed: int) -> torch.Tensor:
    t = torch.zeros(9, 3)
    t[0] = 2.0
    t[1:4] = torch.from_numpy(np.random.default_rng(seed).normal(0, 0.4, (3, 3))).float()
    return t


def test_01_lambertian_sh_is_the_image_model_on_the_decomposition(relighter, photo) -> None:
    image, sky = photo
    out = relighter.relight_linear(image, sky, _target(1), method="lambertian_sh")
    expect = image_model.render(out["albedo"], out["normals"], out["target"]).clamp_min(0)
    fg = ~sky.expand_as(image)
    torch.testing.assert_close(out["relit"][fg], expect[fg])
    assert torch.equal(out["relit"][~fg], image[~fg])  # sky untouched, bit for bit
    assert torch.equal(out["target_shadow"], torch.ones_like(out["target_shadow"]))


def test_02_shadownet_method_multiplies_by_the_target_shadow(relighter, photo) -> None:
    image, sky = photo
    plain = relighter.relight_linear(image, sky, _target(2), method="lambertian_sh")
    shadowed = relighter.relight_linear(image, sky, _target(2), method="shadownet_lambertian")
    s = shadowed["target_shadow"]
    assert float(s.min()) >= 0 and float(s.max()) <= 1
    fg = ~sky.expand_as(image)
    torch.testing.assert_close(shadowed["relit"][fg], (plain["relit"] * s)[fg])


def test_03_source_lighting_sets_the_scale_and_the_default_keeps_exposure(relighter, photo) -> None:
    image, sky = photo
    t = _target(3)
    same = relighter.relight_linear(image, sky, t, source_lighting=t, method="lambertian_sh")
    darker = relighter.relight_linear(image, sky, t, source_lighting=2 * t, method="lambertian_sh")
    fg = ~sky.expand_as(image)
    # Twice the source level for the same target: the relit image is half as bright.
    torch.testing.assert_close(darker["relit"][fg], 0.5 * same["relit"][fg], rtol=1e-5, atol=1e-7)
    # Without a source lighting the target's DC luminance equals the estimated source's.
    default = relighter.relight_linear(image, sky, 10 * t, method="lambertian_sh")
    lum = torch.tensor([0.2126, 0.7152, 0.0722])
    torch.testing.assert_close((default["target"][:, 0] * lum).sum(-1), (default["lighting"][:, 0] * lum).sum(-1))


def test_04_relight_to_the_estimated_lighting_reproduces_the_lambertian_reconstruction(relighter, photo) -> None:
    image, sky = photo
    dec = relighter.decompose_linear(image, sky)
    out = relighter.relight_linear(image, sky, dec["lighting"], method="lambertian_sh")
    torch.testing.assert_close(out["target"], dec["lighting"])
    expect = image_model.render(dec["albedo"], dec["normals"], dec["lighting"]).clamp_min(0)
    fg = ~sky.expand_as(image)
    torch.testing.assert_close(out["relit"][fg], expect[fg])


def test_06_relight_any_size_photo_and_bad_input(relighter) -> None:
    rng = np.random.default_rng(4)
    photo = (rng.uniform(0.1, 0.9, (50, 70, 3)) * 255).astype(np.uint8)
    out = relighter.relight(photo, _target(5).numpy(), method="lambertian_sh")
    assert out.shape == (50, 70, 3) and np.isfinite(out).all() and 0 <= out.min() and out.max() <= 1
    with pytest.raises(ValueError, match="method"):
        relighter.relight(photo, _target(5).numpy(), method="vgg")
    img = torch.rand(1, 3, 16, 16)
    sky = torch.zeros(1, 1, 16, 16, dtype=torch.bool)
    with pytest.raises(ValueError, match=r"target must have shape"):
        relighter.relight_linear(img, sky, torch.zeros(4, 3))
    with pytest.raises(ValueError, match="sky must have shape"):
        relighter.relight_linear(img, sky[:, :, :8], _target(6))
    with pytest.raises(ValueError, match="DC"):
        relighter.relight_linear(img, sky, -_target(6))
    with pytest.raises(ValueError, match="NaN"):
        relighter.relight_linear(img, sky, _target(6) * float("nan"))


def test_07_a_source_estimate_without_positive_level_falls_back_on_the_prior_level(relighter, monkeypatch) -> None:
    # A photo with almost no foreground can solve to a lighting whose DC luminance is <= 0
    # (scikit-image's rocket.jpg under the shipped segmenter did): the prior's mean level is used.
    img = torch.rand(1, 3, 16, 16, generator=torch.Generator().manual_seed(7))
    sky = torch.zeros(1, 1, 16, 16, dtype=torch.bool)
    real = relighter.decompose_linear

    def degenerate(image, sky_):
        out = dict(real(image, sky_))
        out["lighting"] = -out["lighting"].abs()
        return out

    monkeypatch.setattr(relighter, "decompose_linear", degenerate)
    out = relighter.relight_linear(img, sky, _target(7), method="lambertian_sh")
    lum = torch.tensor([0.2126, 0.7152, 0.0722])
    prior_dc = (relighter.prior.mean.reshape(9, 3)[0].float() * lum).sum()
    torch.testing.assert_close((out["target"][0, 0] * lum).sum(), prior_dc)
    assert torch.isfinite(out["relit"]).all()


def test_08_a_sequence_decomposes_once_and_gives_the_frames_of_separate_relights(relighter, monkeypatch) -> None:
    rng = np.random.default_rng(8)
    photo = (rng.uniform(0.1, 0.9, (40, 60, 3)) * 255).astype(np.uint8)
    sun = np.array([0.5, 0.6, 0.2])  # a sun direction (world frame), turned about the vertical
    azimuths = [0.0, 90.0, 200.0]
    separate = [relighter.relight(photo, sun, azimuth_deg=a, seed=3) for a in azimuths]
    calls, denoised = [], []
    original, original_denoised = type(relighter).decompose_linear, type(relighter).denoised
    monkeypatch.setattr(type(relighter), "decompose_linear",
                        lambda self, *a, **k: calls.append(1) or original(self, *a, **k))
    monkeypatch.setattr(type(relighter), "denoised",
                        lambda self, *a, **k: denoised.append(1) or original_denoised(self, *a, **k))
    frames = relighter.relight_sequence(photo, sun, azimuths, seed=3)
    assert len(calls) == 1 and len(denoised) == 1  # one decomposition and one denoise for the whole sequence
    assert len(frames) == 3
    for a, b in zip(frames, separate):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(frames[0], frames[1])  # the light did turn


def test_09_the_quotient_ratio_is_smoothed_at_the_relighters_radius(relighter, photo) -> None:
    """``RelightOptions.ratio_radius`` (study 27): the quotient's relit photo is the raw quotient with its ratio
    passed through ``physrelight.quotient.smooth_ratio`` at that radius; radius 0 is the raw quotient, and a
    negative or fractional radius is refused by name."""
    from learned.relight_options import RelightOptions
    from physrelight import quotient

    image, sky = photo
    target, source = _target(3), _target(4)
    out = relighter.relight_linear(image, sky, target, source_lighting=source, method="quotient", known_source=True)
    raw = quotient.quotient_ratio(out["normals"], source[None].expand(2, -1, -1), target[None].expand(2, -1, -1),
                                  mask=~sky)
    # The ratio is scale-invariant, so the decomposition-unit scale of relight_linear does not enter.
    want = torch.where(sky, image, image * quotient.smooth_ratio(image, raw, relighter.options.ratio_radius))
    torch.testing.assert_close(out["relit"], want.clamp_min(0), rtol=1e-5, atol=1e-6)
    assert relighter.options.ratio_radius == quotient.SMOOTH_RADIUS == 3
    unsmoothed = relighter.with_options(ratio_radius=0)
    got = unsmoothed.relight_linear(image, sky, target, source_lighting=source, method="quotient", known_source=True)
    torch.testing.assert_close(got["relit"], torch.where(sky, image, image * raw).clamp_min(0), rtol=1e-5, atol=1e-6)
    assert not torch.allclose(got["relit"], out["relit"])
    for bad in (-1, 1.5):
        with pytest.raises(ValueError, match="ratio_radius"):
            RelightOptions(ratio_radius=bad)


def test_10_with_denoise_the_foreground_is_relit_from_the_denoised_photo_and_the_sky_stays_the_photos(relighter,
                                                                                                      photo) -> None:
    """``RelightOptions.denoise`` (study 37; off by default): a noisy photo relit to its own lighting on the known track
    comes back as the photo denoised by :func:`physrelight.denoise.denoise` at :data:`learned.relighter.DENOISE`,
    bit for bit on the foreground, nearer the clean photo than the noisy one was; its sky pixels stay the noisy
    photo's own. Off (the default), the photo itself comes back, bit for bit."""
    from learned.relight_options import DENOISE
    from physrelight.denoise import denoise

    image, sky = photo
    g = torch.Generator().manual_seed(5)
    noisy = (image + 0.02 * torch.randn(image.shape, generator=g)).clamp_min(0.0)
    source = _target(4)
    assert relighter.options.denoise is None and DENOISE == (2, 3.0)
    off = relighter.relight_full_resolution(noisy, sky, source, source_lighting=source, method="quotient",
                                            known_source=True)["relit"]
    assert torch.equal(off, noisy) and relighter.denoised(noisy) is noisy
    denoising = relighter.with_options(denoise=DENOISE)
    out = denoising.relight_full_resolution(noisy, sky, source, source_lighting=source, method="quotient",
                                            known_source=True)["relit"]
    clean = denoise(noisy, *DENOISE)
    fg = ~sky.expand_as(noisy)
    assert torch.equal(out[fg], clean[fg]) and torch.equal(out[~fg], noisy[~fg])
    assert float((out - image)[fg].abs().mean()) < float((noisy - image)[fg].abs().mean())
    assert torch.equal(denoising.denoised(noisy), clean)


def test_11_the_level_prior_blends_the_shapes_level_with_the_grey_world(photo) -> None:
    """``RelightOptions.level_prior`` (study 39; 0 by default): on the estimated track with a given source level, the
    target's scale is divided by ``g ** beta``, ``g`` the foreground's median implied albedo over 0.18 under the
    estimated shape at the given level (computed here by hand from its definition). beta = 1 is the target
    divided by ``g`` at beta = 0; beta = 1/2 the same with ``sqrt(g)``; photo, source and target scaled together
    scale the output alike (the blend is exposure-equivariant); the known track ignores it; a weight outside
    [0, 1] is refused by name."""
    from learned.relight_options import RelightOptions
    from learned.relighter import Relighter
    from physrelight import colour

    r = Relighter.load(options=RelightOptions(ratio_radius=0))
    assert r.options.level_prior == 0.0
    image, sky = photo
    source, target = _target(4), _target(3)
    dec = r.decompose_linear(image, sky)
    fg = ~sky.expand_as(image)

    def relit(beta: float, k: float = 1.0, tgt: torch.Tensor = target, **kw) -> torch.Tensor:
        return r.with_options(level_prior=beta).relight_linear(k * image, sky, k * tgt, source_lighting=k * source,
                                                               method="quotient", decomposition=dec, **kw)["relit"]

    # g by hand: the estimate put at the given source's DC luminance, the median of lum(photo) / lum(shading)
    lum = torch.tensor(colour.LUMINANCE, dtype=torch.float64)
    at_given = dec["lighting"].double() * ((source[0].double() @ lum) / (dec["lighting"][:, 0].double() @ lum))[:, None,
                                                                                                               None]
    shade = torch.einsum("bchw,c->bhw", image_model.shading(dec["normals"].double(), at_given), lum)
    y = torch.einsum("bchw,c->bhw", image.double(), lum)
    g = torch.stack([torch.median(y[i][~sky[i, 0]] / shade[i][~sky[i, 0]]) / 0.18 for i in range(2)])
    assert float((g - 1).abs().min()) > 0.2  # the blend moves the level here
    for i in range(2):
        one = {k: v[i:i + 1] for k, v in dec.items()}
        for beta in (0.5, 1.0):
            got = r.with_options(level_prior=beta).relight_linear(image[i:i + 1], sky[i:i + 1], target,
                                                                  source_lighting=source, method="quotient",
                                                                  decomposition=one)["relit"]
            want = r.relight_linear(image[i:i + 1], sky[i:i + 1], target / float(g[i]) ** beta, source_lighting=source,
                                    method="quotient", decomposition=one)["relit"]
            torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-8)
    rh = relit(0.5)
    assert torch.equal(rh[~fg], image[~fg])
    torch.testing.assert_close(relit(0.5, k=4.0), 4.0 * rh, rtol=1e-5, atol=1e-7)
    assert torch.equal(relit(1.0, known_source=True), relit(0.0, known_source=True))
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="level_prior"):
            r.with_options(level_prior=bad)


def test_12_the_stage_hook_hears_each_stage_in_order(relighter, photo) -> None:
    """``Relighter.on_stage`` is told ``RELIGHT_STAGES`` in order: all four for ``relight_layers``, the first three
    for ``relight``, and for a sequence the sky mask once, then relighting and sky per frame."""
    from learned.relighter import RELIGHT_STAGES

    image, sky = photo
    heard: list[str] = []
    relighter.on_stage = heard.append
    try:
        relighter.relight_layers(image[:1], _target(3), sky_mask=sky[:1, 0])
        assert tuple(heard) == RELIGHT_STAGES
        heard.clear()
        relighter.relight(image[:1], _target(3), sky_mask=sky[:1, 0])
        assert tuple(heard) == RELIGHT_STAGES[:3]
        heard.clear()
        relighter.relight_sequence(image[:1], _target(3), [0.0, 90.0, 180.0], sky_mask=sky[:1, 0])
        assert heard == ["sky mask"] + ["relighting", "sky"] * 3
    finally:
        relighter.on_stage = None


def test_13_the_tuning_is_one_frozen_set_of_options_given_at_construction(relighter, photo) -> None:
    """``RelightOptions`` holds the tuning (issue 41): each option out of its range is refused by name when the
    options are made; setting an option on a relighter is refused by name (it would do nothing); ``with_options``
    gives a relighter with the same networks and the changed options, the original untouched. The keyword
    arguments of ``relight``/``relight_layers``/``relight_sequence`` are ``RelightRequest``'s: an unknown one is a
    ``TypeError``, and a sequence takes its azimuths, not ``azimuth_deg``."""
    from learned.relight_options import DENOISE, RelightOptions, RelightRequest

    for bad in (dict(sky_level="moon"), dict(sky_grow=-0.1), dict(sky_grow=2.0), dict(sky_smooth=-1.0),
                dict(denoise=(2,)), dict(renderer_gain_ratio=1), dict(level_prior=float("nan")),
                dict(ratio_radius=True), dict(lighting_estimator="magic")):
        with pytest.raises(ValueError, match=next(iter(bad))):
            RelightOptions(**bad)
    with pytest.raises(AttributeError, match="denoise is a relighting option"):
        relighter.denoise = DENOISE
    other = relighter.with_options(denoise=DENOISE, sky_grow=0.0)
    assert other.inverse is relighter.inverse and other.renderer is relighter.renderer
    assert other.options == RelightOptions(denoise=DENOISE, sky_grow=0.0) and relighter.options == RelightOptions()
    with pytest.raises(AttributeError):
        other.options.denoise = None  # frozen
    assert RelightRequest().method == "proposed" and RelightRequest().exposure == "auto"  # the command line's
    image, sky = photo
    with pytest.raises(TypeError, match="azimuth"):
        relighter.relight(image[:1], _target(3), sky_mask=sky[:1, 0], azimuth=30.0)
    with pytest.raises(TypeError, match="azimuths_deg"):
        relighter.relight_sequence(image[:1], _target(3), [0.0], sky_mask=sky[:1, 0], azimuth_deg=30.0)


def test_14_a_sun_by_its_angles_is_relight_suns_target_wherever_a_target_goes(relighter) -> None:
    """``Sun(elevation_deg, azimuth_deg)`` (issue 41) relights as its direction does, as the target, under a turn,
    in a sequence and as the known source; two bare numbers are refused as ambiguous, before any work."""
    from learned.relight_cli import sun_direction
    from physrelight.target_lighting import Sun

    rng = np.random.default_rng(14)
    photo = (rng.uniform(0.1, 0.9, (40, 60, 3)) * 255).astype(np.uint8)
    photo[:10] = (110, 160, 230)
    kw = dict(seed=2, pitch_deg=5.0)
    by_angles = relighter.relight(photo, Sun(20, 120), azimuth_deg=30.0, **kw)
    np.testing.assert_array_equal(by_angles, relighter.relight(photo, sun_direction(20, 120), azimuth_deg=30.0, **kw))
    np.testing.assert_allclose(by_angles, relighter.relight(photo, Sun(20, 150), **kw), atol=1e-5)  # 120 + 30
    frames = relighter.relight_sequence(photo, Sun(20, 120), [0.0, 30.0], **kw)
    np.testing.assert_allclose(frames[1], by_angles, atol=1e-6)
    known = relighter.relight(photo, Sun(40, -20), source=Sun(60, 10), method="quotient", **kw)
    np.testing.assert_array_equal(known, relighter.relight(photo, sun_direction(40, -20), source=sun_direction(60, 10),
                                                           method="quotient", **kw))
    for bad in ((20, 120), [20.0, 120.0], np.array([20.0, 120.0])):
        with pytest.raises(ValueError, match="ambiguous"):
            relighter.relight(photo, bad)
    with pytest.raises(ValueError, match="ambiguous"):
        relighter.relight(photo, Sun(20, 120), source=(60, 10), method="quotient")
