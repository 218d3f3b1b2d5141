"""SkyGAN and the sky segmenter: inference contracts, tiny training runs, resume, export."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from safetensors.torch import load_file

from learned import checkpoint as ckpt
from learned.sky_gan import SkyGenerator, generate_sky, lighting_scale, load_sky_generator
from learned.sky_segmentation import (SkySegmenter, load_sky_segmenter, photometric_augment, segment_sky,
                                      sky_probability)
from learned.train_sky import (SkyData, SkyTrainConfig, _sky_stats, build_sky_model, evaluate_segmentation,
                               export_sky, mirror_lighting, sky_follows_lighting, train_sky)
from physrelight import sh


def _inputs(b: int = 2, h: int = 24, w: int = 32, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    fg = torch.rand(b, 3, h, w, generator=g) * 0.8 + 0.05
    sky = torch.zeros(b, 1, h, w, dtype=torch.bool)
    sky[:, :, : h // 3] = True
    sky[1:, :, h // 3: h // 2, : w // 4] = True  # an irregular sky in the second image
    light = torch.randn(b, 9, 3, generator=g) * 0.3
    light[:, 0] = torch.tensor([3.0, 3.2, 3.6])
    return fg, sky, light


@pytest.fixture(scope="module")
def generator() -> SkyGenerator:
    torch.manual_seed(0)
    g = SkyGenerator(width=4, hidden=8).eval()
    # Break the near-symmetry of a fresh init so the SH channels visibly matter.
    with torch.no_grad():
        for p in g.parameters():
            p.add_(0.05 * torch.randn(p.shape))
    return g


# ------------------------------------------------------------------ SkyGAN inference


def test_generate_sky_rejects_bad_shapes(generator):
    fg, sky, light = _inputs()
    with pytest.raises(ValueError, match=r"foreground .*\(B, 3, H, W\).*\(2, 4, 24, 32\)"):
        generate_sky(generator, torch.zeros(2, 4, 24, 32), sky, light)
    with pytest.raises(ValueError, match=r"sky .*\(2, 1, 24, 32\).*\(2, 1, 24, 31\)"):
        generate_sky(generator, fg, sky[..., :31], light)
    with pytest.raises(ValueError, match="bool"):
        generate_sky(generator, fg, sky.float(), light)
    with pytest.raises(ValueError, match=r"lighting .*\(2, 9, 3\).*\(2, 27\)"):
        generate_sky(generator, fg, sky, light.reshape(2, 27))
    dark = light.clone()
    dark[0, 0] = -1.0
    with pytest.raises(ValueError, match="DC luminance"):
        generate_sky(generator, fg, sky, dark)


def test_generate_sky_composites_and_is_seeded(generator):
    fg, sky, light = _inputs()
    out = generate_sky(generator, fg, sky, light, seed=3)
    assert out.shape == fg.shape
    assert torch.equal(out[~sky.expand_as(out)], fg[~sky.expand_as(fg)])  # foreground bit for bit
    assert torch.equal(out, generate_sky(generator, fg, sky, light, seed=3))
    other = generate_sky(generator, fg, sky, light, seed=4)
    s = sky.expand_as(out)
    assert (out[s] - other[s]).abs().mean() > 1e-4  # the noise matters
    assert torch.isfinite(out).all() and (out[s] > 0).all()
    # An image's noise does not depend on the batch around it.
    assert torch.allclose(generate_sky(generator, fg[:1], sky[:1], light[:1], seed=3), out[:1], atol=1e-6)


def test_sky_follows_units_and_sh(generator):
    fg, sky, light = _inputs()
    out = generate_sky(generator, fg, sky, light, seed=0)
    # Units: scaling foreground and lighting together scales the sky by the same factor.
    out4 = generate_sky(generator, 4.0 * fg, sky, 4.0 * light, seed=0)
    assert torch.allclose(out4, 4.0 * out, rtol=1e-4, atol=1e-6)
    # The SH shape (same DC) changes the sky.
    tilted = light.clone()
    tilted[:, 1] += 2.0  # more light from above (Y1-1 ~ y)
    s = sky.expand_as(out)
    assert (generate_sky(generator, fg, sky, tilted, seed=0)[s] - out[s]).abs().mean() > 1e-3
    assert torch.allclose(lighting_scale(light).flatten(), 0.282095 * (light[:, 0] @ torch.tensor(
        [0.2126, 0.7152, 0.0722])), rtol=1e-6)


def test_mirror_lighting_is_the_mirrored_sh():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    coeffs = torch.from_numpy(rng.normal(size=(9, 3)))
    f_mirrored = torch.from_numpy(sh.basis(d * np.array([-1.0, 1.0, 1.0]))) @ coeffs  # f(Mx d)
    assert torch.allclose(torch.from_numpy(sh.basis(d)) @ mirror_lighting(coeffs), f_mirrored, atol=1e-12)


def test_sky_stats_measure_a_known_gradient():
    h, w = 16, 20
    ys = torch.linspace(1, -1, h).reshape(h, 1).expand(h, w)
    xs = torch.linspace(-1, 1, w).reshape(1, w).expand(h, w)
    lum = torch.exp(0.7 * ys - 0.3 * xs)
    image = torch.stack([0.5 * lum, lum, 2.0 * lum])[None]
    sky = torch.ones(1, 1, h, w, dtype=torch.bool)
    stats = _sky_stats(image, sky)[0]
    assert stats[1] == pytest.approx(math.log(4.0), abs=1e-6)
    assert stats[2] == pytest.approx(0.7, abs=1e-5) and stats[3] == pytest.approx(-0.3, abs=1e-5)


# ------------------------------------------------------------------ segmentation inference


def test_segment_sky_any_size_and_errors():
    torch.manual_seed(0)
    model = SkySegmenter(width=4, res=16).eval()
    image = torch.rand(2, 3, 37, 50)
    mask = segment_sky(model, image)
    assert mask.shape == (2, 1, 37, 50) and mask.dtype == torch.bool
    p = sky_probability(model, image)
    assert torch.equal(mask, p > 0.5) and float(p.min()) >= 0 and float(p.max()) <= 1
    with pytest.raises(ValueError, match=r"image .*\(B, 3, H, W\).*\(2, 1, 37, 50\)"):
        segment_sky(model, image[:, :1])
    with pytest.raises(ValueError, match="threshold"):
        segment_sky(model, image, threshold=1.5)
    # Exposure invariance of the network's input (up to the log's 1e-3 offset).
    bright = torch.rand(1, 3, 16, 16) + 0.5
    assert torch.allclose(model(bright), model(8.0 * bright), atol=2e-2)


def test_photometric_augment_is_seeded_and_photographic():
    x = torch.rand(3, 3, 16, 16) * 0.6
    a = photometric_augment(x, torch.Generator().manual_seed(5))
    assert torch.equal(a, photometric_augment(x, torch.Generator().manual_seed(5)))
    b = photometric_augment(x, torch.Generator().manual_seed(6))
    assert not torch.equal(a, b) and not torch.allclose(a, x, atol=1e-2)
    assert a.shape == x.shape and float(a.min()) >= 0.0 and float(a.max()) <= 1.0  # a linearised 8-bit photo
    assert torch.allclose(torch.round(_srgb(a) * 255), _srgb(a) * 255, atol=1e-3)  # quantised like a PNG


def test_cloud_sky_puts_clouds_in_the_sky_only_seeded_and_within_its_draws():
    """``cloud_sky``: the foreground is kept bit for bit; a sky that gets clouds has texture (its rows are no
    longer constant) and keeps the clouds within the sky's mean luminance times 2^[-3, 1] times their shading;
    about half of the photos get clouds; the same generator state gives the same clouds; bad shapes are refused."""
    from learned.sky_segmentation import CLOUD_SKY, cloud_sky

    b, h, w = 64, 24, 32
    x = torch.zeros(b, 3, h, w)
    x[:, :, :10] = torch.tensor([0.2, 0.35, 0.7])[:, None, None]  # a flat blue sky on the top ten rows
    x[:, :, 10:] = torch.rand(b, 3, h - 10, w, generator=torch.Generator().manual_seed(0)) * 0.5
    sky = torch.zeros(b, 1, h, w, dtype=torch.bool)
    sky[:, :, :10] = True
    y = cloud_sky(x, sky, torch.Generator().manual_seed(1))
    assert torch.equal(y[:, :, 10:], x[:, :, 10:])
    assert torch.equal(y, cloud_sky(x, sky, torch.Generator().manual_seed(1)))
    clouded = (y != x).flatten(1).any(1)
    n = int(clouded.sum())
    assert abs(n - CLOUD_SKY["probability"] * b) <= 3 * (b * 0.25) ** 0.5  # binomial, 3 sigma
    lum0 = float((x[0, :, 0, 0] * torch.tensor([0.2126, 0.7152, 0.0722])).sum())
    ly = (y[clouded][:, :, :10] * torch.tensor([0.2126, 0.7152, 0.0722])[:, None, None]).sum(1)
    # the sky's mixture of itself and a cloud no darker than 2^-3 x exp(-0.25 x 5 sigma) of its luminance
    assert float(ly.min()) >= lum0 * 2.0 ** -3 * math.exp(-0.25 * 5) - 1e-6
    assert float(ly.std(dim=(1, 2)).min()) > 1e-3  # textured, not a uniform tint
    with pytest.raises(ValueError, match="sky must be a bool tensor"):
        cloud_sky(x, sky.float(), torch.Generator())


def _srgb(x: torch.Tensor) -> torch.Tensor:
    from physrelight import colour

    return colour.to_ldr(x)


# ------------------------------------------------------------------ tiny training runs


def _config(data: Path, out: Path, stage: str, steps: int, **kw) -> SkyTrainConfig:
    base = dict(stage=stage, data=str(data), out=str(out), train_split="all", val_split="all", res=24, batch=4,
                steps=steps, width=4, hidden=8, d_width=4, ckpt_every=3, val_every=1000, val_images=4,
                log_every=1, threads=1, progress=False)
    base.update(kw)
    return SkyTrainConfig(**base)


def _rows(path: Path) -> list[list[str]]:
    return list(csv.reader(path.open()))


def test_segmentation_training_reduces_loss(tiny_dataset, tmp_path):
    cfg = _config(tiny_dataset, tmp_path / "seg", "segmentation", steps=25, lr=3e-3, width=4)
    data = SkyData(tiny_dataset, "all", 24, lighting=False)

    def bce(model: torch.nn.Module) -> float:
        with torch.no_grad():
            return float(F.binary_cross_entropy_with_logits(model["seg"](data.image), data.sky.float()))

    before = bce(build_sky_model(cfg))
    train_sky(cfg)
    model = build_sky_model(cfg)
    ckpt.load_checkpoint(ckpt.latest_checkpoint(cfg.out), model, restore_rng=False)
    assert bce(model) < 0.8 * before
    assert (Path(cfg.out) / "val.csv").is_file() and list((Path(cfg.out) / "panels").glob("*.png"))
    res = evaluate_segmentation(model["seg"], tiny_dataset, "all", 24, fit_split="all", fit_images=12)
    for k in ("network", "baseline_top_rows", "baseline_brightness", "network_augmented_input"):
        assert 0.0 <= res[k]["iou_mean"] <= 1.0 and 0.0 <= res[k]["iou_pooled"] <= 1.0


def test_sky_gan_steps_run_with_finite_losses(tiny_dataset, tmp_path):
    cfg = _config(tiny_dataset, tmp_path / "gan", "sky", steps=3)
    init = build_sky_model(cfg)
    train_sky(cfg)
    model = build_sky_model(cfg)
    ckpt.load_checkpoint(ckpt.latest_checkpoint(cfg.out), model, restore_rng=False)
    rows = _rows(Path(cfg.out) / "train.csv")
    assert rows[0][:6] == ["step", "g", "d", "g_gan", "g_fm", "g_lowres"] and len(rows) == 4
    assert all(math.isfinite(float(v)) for r in rows[1:] for v in r)
    for part in ("g", "d"):  # both players moved
        delta = sum(float((a - b).detach().abs().sum()) for a, b in zip(init[part].parameters(), model[part].parameters()))
        assert delta > 0
    figs = sky_follows_lighting(model["g"], tiny_dataset, "all", res=24)
    assert figs["images"] == 12
    for case in ("same", "relight"):
        for cond in ("conditioned", "shuffled", "shuffled_same_dc"):
            assert set(figs[case][cond]) == {"log_brightness", "log_blue_over_red", "vertical_gradient",
                                             "horizontal_gradient"}
    assert "keep_source_sky" in figs["relight"]


@pytest.mark.parametrize("stage,extra", [("sky", {}), ("segmentation", {}), ("segmentation", {"clouds": True}),
                                         ("segmentation", {"dusk": True})])
def test_resume_is_bit_identical(tiny_dataset, tmp_path, stage, extra):
    straight = _config(tiny_dataset, tmp_path / "a", stage, steps=6, **extra)
    train_sky(straight)
    train_sky(_config(tiny_dataset, tmp_path / "b", stage, steps=3, **extra))  # "killed" after its step-3 checkpoint
    train_sky(_config(tiny_dataset, tmp_path / "b", stage, steps=6, **extra))  # the same command again resumes
    a = load_file(str(tmp_path / "a" / "checkpoints" / "step_0000006.safetensors"))
    b = load_file(str(tmp_path / "b" / "checkpoints" / "step_0000006.safetensors"))
    assert a.keys() == b.keys() and any(k.startswith("optim.") for k in a)
    for k in a:
        assert torch.equal(a[k], b[k]), k
    ra, rb = _rows(tmp_path / "a" / "train.csv"), _rows(tmp_path / "b" / "train.csv")
    assert [r[:-1] for r in ra] == [r[:-1] for r in rb]  # every logged loss, seconds aside
    with pytest.raises(ValueError, match="another configuration"):
        train_sky(_config(tiny_dataset, tmp_path / "b", stage, steps=8, seed=1, **extra))


def test_export_and_load_round_trip(tiny_dataset, tmp_path):
    gan = _config(tiny_dataset, tmp_path / "gan", "sky", steps=1)
    seg = _config(tiny_dataset, tmp_path / "seg", "segmentation", steps=1)
    train_sky(gan)
    train_sky(seg)
    g_path = export_sky(gan.out, tmp_path / "w" / "sky_gan.safetensors")
    s_path = export_sky(seg.out, tmp_path / "w" / "sky_segmentation.safetensors")
    assert all(k.startswith("g.") for k in load_file(str(g_path)))  # generator only, no discriminator
    model = build_sky_model(gan)
    ckpt.load_checkpoint(ckpt.latest_checkpoint(gan.out), model, restore_rng=False)
    fg, sky, light = _inputs(h=24, w=24)
    assert torch.equal(generate_sky(load_sky_generator(g_path), fg, sky, light, seed=2),
                       generate_sky(model["g"].eval(), fg, sky, light, seed=2))
    smodel = build_sky_model(seg)
    ckpt.load_checkpoint(ckpt.latest_checkpoint(seg.out), smodel, restore_rng=False)
    assert torch.equal(sky_probability(load_sky_segmenter(s_path), fg), sky_probability(smodel["seg"].eval(), fg))
    with pytest.raises(ValueError, match="not a sky segmenter"):
        load_sky_segmenter(g_path)
    with pytest.raises(ValueError, match="not a sky_gan"):
        load_sky_generator(s_path)


@pytest.mark.parametrize("size", [(40, 60), (300, 420)])
def test_smooth_sky_keeps_a_constant_sky_and_lets_no_foreground_in(size):
    """Normalised convolution: a constant sky stays that constant on the mask, whatever the foreground
    holds (at full size and on the downsized path above 256 px), and a blotchy sky loses its blotches."""
    from learned.sky_gan import smooth_sky

    h, w = size
    mask = torch.zeros(1, 1, h, w, dtype=torch.bool)
    mask[..., : h // 2, :] = True
    img = torch.full((1, 3, h, w), 100.0)  # a bright foreground must not leak in
    img[:, :, : h // 2] = torch.tensor([0.2, 0.3, 0.6])[:, None, None]
    out = smooth_sky(img, mask)
    sky = out[:, :, : h // 2 - 1]
    assert torch.allclose(sky, torch.tensor([0.2, 0.3, 0.6])[None, :, None, None].expand_as(sky), rtol=1e-5)
    g = torch.Generator().manual_seed(0)
    blotchy = img.clone()
    blotchy[:, :, : h // 2] *= torch.exp(0.5 * torch.randn(1, 1, h // 2, w, generator=g))
    sm = smooth_sky(blotchy, mask)[:, :, : h // 2]
    spread = lambda x: float(x.std(dim=(2, 3)).mean())  # noqa: E731 (per channel, over the pixels)
    assert spread(sm) < 0.2 * spread(blotchy[:, :, : h // 2])
    with pytest.raises(ValueError, match="sky must have shape"):
        smooth_sky(img, mask[..., :-1])
    with pytest.raises(ValueError, match="sigma"):
        smooth_sky(img, mask, sigma=0.0)


@pytest.mark.parametrize("extra", [{"clouds": True}, {"dusk": True}])
def test_sky_augmentation_switches_change_the_run_and_nothing_else_when_off(tiny_dataset, tmp_path, extra):
    """``--clouds`` and ``--dusk`` change what the segmenter trains on (other weights after three steps), and a run
    with the switch off is the plain run bit for bit (the switches draw from their own streams)."""
    plain = _config(tiny_dataset, tmp_path / "plain", "segmentation", steps=3)
    train_sky(plain)
    train_sky(_config(tiny_dataset, tmp_path / "on", "segmentation", steps=3, **extra))
    off = {k: False for k in extra}
    train_sky(_config(tiny_dataset, tmp_path / "off", "segmentation", steps=3, **off))
    a, b, c = (load_file(str(tmp_path / n / "checkpoints" / "step_0000003.safetensors")) for n in ("plain", "on", "off"))
    weights = [k for k in a if not k.startswith("optim.")]
    assert any(not torch.equal(a[k], b[k]) for k in weights)
    assert all(torch.equal(a[k], c[k]) for k in weights)
