"""Specification of the neural renderer (inputs, inference composition, training, resume, export).

Runs on the tiny rendered dataset of ``conftest.py`` (3 scenes x 2 views x 2 lightings, 24 px)
with tiny networks; the frozen inverse network and ShadowNet are tiny random ones exported
here, so the tests do not depend on the shipped weights.
"""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file

from learned import checkpoint as ckpt
from learned.data import PairSampler
from learned.lighting import load_prior
from learned.networks import InverseNet, ShadowNet
from learned.neural_renderer import NeuralRenderer, load_renderer, positive, render_relit, renderer_inputs
from learned.objectives import decompose_and_solve
from learned.relight_eval import evaluate_relight
from learned.relighter import Relighter
from learned.renderer_objectives import PHASE2_TERMS, downsample_masked
from learned.train_renderer import RendererConfig, export_renderer, train_renderer
from physrelight import image_model

from .conftest import save_weights


@pytest.fixture(scope="module")
def frozen(tmp_path_factory, tiny_prior: Path) -> Path:
    """A weights folder with a tiny inverse network, ShadowNet and the tiny prior."""
    d = tmp_path_factory.mktemp("frozen")
    torch.manual_seed(11)
    save_weights(InverseNet(4, 2), d / "inverse.safetensors", "inverse")
    save_weights(ShadowNet(4, 2), d / "shadow.safetensors", "shadow")
    shutil.copy(tiny_prior, d / "lighting_prior.npz")
    return d


def config(data: Path, out: Path, weights: Path, **kw) -> RendererConfig:
    base = dict(data=str(data), out=str(out), inverse=str(weights / "inverse.safetensors"),
                shadow=str(weights / "shadow.safetensors"), prior=str(weights / "lighting_prior.npz"),
                train_split="all", val_split="all", width=4, depth=2, d_width=4, res=24, batch=2, steps=6,
                phase1_steps=3, val_every=1000, val_images=4, ckpt_every=3, log_every=1, threads=1, seed=3,
                progress=False, lr=3e-3)
    base.update(kw)
    return RendererConfig(**base)


def rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def _decomposition(b: int = 2, h: int = 12, w: int = 16, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    n = torch.randn(b, 3, h, w, generator=g)
    n[:, 2] = n[:, 2].abs() + 0.5
    lighting = torch.zeros(b, 9, 3)
    lighting[:, 0] = 2.0
    lighting[:, 2] = 1.0  # light from the camera side: positive shading
    return {"albedo": torch.rand(b, 3, h, w, generator=g), "normals": n / n.norm(dim=1, keepdim=True),
            "shadow": torch.rand(b, 1, h, w, generator=g), "lighting": lighting}


def test_01_the_14_channels_are_assembled_in_the_documented_order() -> None:
    dec = _decomposition()
    image = torch.rand(2, 3, 12, 16)
    sky = torch.zeros(2, 1, 12, 16, dtype=torch.bool)
    sky[:, :, :3] = True
    target = dec["lighting"] * 0.5
    ts = torch.rand(2, 1, 12, 16)
    x = renderer_inputs(image, sky, dec["albedo"], dec["normals"], dec["shadow"], dec["lighting"], target, ts)
    assert x.shape == (2, 14, 12, 16)
    fg = ~sky[:, 0]
    torch.testing.assert_close(x[:, 0:3].permute(0, 2, 3, 1)[fg], dec["albedo"].permute(0, 2, 3, 1)[fg])
    torch.testing.assert_close(x[:, 3:6].permute(0, 2, 3, 1)[fg], dec["normals"].permute(0, 2, 3, 1)[fg])
    shading = image_model.shading(dec["normals"], target)
    torch.testing.assert_close(x[:, 6:9].permute(0, 2, 3, 1)[fg], shading.permute(0, 2, 3, 1)[fg])
    torch.testing.assert_close(x[:, 9][fg], ts[:, 0][fg])
    assert torch.equal(x[:, 10], sky[:, 0].float())
    # residual: the photo minus its Lambertian re-rendering with the SOURCE lighting and shadow
    res = image - dec["albedo"] * image_model.shading(dec["normals"], dec["lighting"]) * dec["shadow"]
    torch.testing.assert_close(x[:, 11:14].permute(0, 2, 3, 1)[fg], res.permute(0, 2, 3, 1)[fg])
    assert float(x[:, [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13]].permute(0, 2, 3, 1)[sky[:, 0]].abs().max()) == 0.0


def test_02_bad_shapes_raise_value_errors_naming_them() -> None:
    dec = _decomposition()
    image = torch.rand(2, 3, 12, 16)
    sky = torch.zeros(2, 1, 12, 16, dtype=torch.bool)
    ts = torch.rand(2, 1, 12, 16)
    args = [image, sky, dec["albedo"], dec["normals"], dec["shadow"], dec["lighting"], dec["lighting"], ts]
    bad = {2: (torch.rand(2, 3, 12, 15), r"albedo has shape \(2, 3, 12, 15\)"),
           0: (torch.rand(3, 12, 16), r"image must be .*\(B, 3, H, W\), got \(3, 12, 16\)"),
           7: (torch.rand(2, 3, 12, 16), r"target_shadow must be .*\(B, 1, H, W\), got \(2, 3, 12, 16\)"),
           6: (torch.rand(2, 4, 3), r"target_lighting must have shape \(2, 9, 3\), got \(2, 4, 3\)"),
           1: (torch.zeros(2, 1, 12, 16), "sky must be a bool")}
    for i, (value, message) in bad.items():
        with pytest.raises(ValueError, match=message):
            renderer_inputs(*[value if j == i else a for j, a in enumerate(args)])
    with pytest.raises(ValueError, match=r"\(B, 14, H, W\)"):
        NeuralRenderer(4, 2)(torch.rand(1, 11, 8, 8))
    with pytest.raises(ValueError, match="lacks 'lighting'"):
        render_relit(NeuralRenderer(4, 2), image, sky, {k: dec[k] for k in ("albedo", "normals", "shadow")},
                     dec["lighting"], ts)


def test_03_render_relit_keeps_the_sky_and_starts_at_the_shadowed_lambertian_render() -> None:
    torch.manual_seed(0)
    dec = _decomposition(seed=1)
    image = torch.rand(2, 3, 12, 16) * 5.0  # a bright sky the network never sees
    sky = torch.zeros(2, 1, 12, 16, dtype=torch.bool)
    sky[0, :, :4] = True
    sky[1, :, :, 10:] = True
    ts = torch.rand(2, 1, 12, 16)
    target = dec["lighting"] * torch.tensor([1.0, 0.7, 0.4])
    net = NeuralRenderer(4, 2).eval()
    with torch.no_grad():
        relit = render_relit(net, image, sky, dec, target, ts)
        # the head starts at gain 1 + small: close to the ShadowNet + Lambertian render
        base = image_model.render(dec["albedo"], dec["normals"], target, ts)
        torch.nn.init.zeros_(net.unet.head.weight)
        exact = render_relit(net, image, sky, dec, target, ts)
    assert torch.equal(relit[sky.expand_as(relit)], image[sky.expand_as(image)])  # bit for bit
    assert float(relit.min()) > 0
    fg = (~sky).expand_as(relit)
    torch.testing.assert_close(exact[fg], positive(base)[fg])
    assert float((relit - exact)[fg].abs().max()) < 0.05
    gain_only = NeuralRenderer(4, 2, additive=False).eval()
    torch.nn.init.zeros_(gain_only.unet.head.weight)
    with torch.no_grad():
        torch.testing.assert_close(render_relit(gain_only, image, sky, dec, target, ts)[fg], positive(base)[fg])
    # the output unit is >= 0, monotone and the identity above tau
    x = torch.linspace(-1, 1, 2001)
    y = positive(x)
    assert float(y.min()) >= 0 and torch.equal(y[x >= 1e-3], x[x >= 1e-3])
    assert float((y[1:] - y[:-1]).min()) >= 0


def test_05_masked_downsampling_averages_only_masked_pixels() -> None:
    x = torch.arange(16.0).reshape(1, 1, 4, 4)
    m = torch.zeros(1, 1, 4, 4)
    m[..., :2, :2] = 1.0
    m[..., 0, 2] = 1.0
    y, valid = downsample_masked(x, m, 2)
    assert float(y[0, 0, 0, 0]) == pytest.approx((0 + 1 + 4 + 5) / 4)
    assert float(valid[0, 0, 0, 0]) == 1.0 and float(valid[0, 0, 0, 1]) == 0.0  # 1/4 covered < 1/2


def test_06_a_tiny_run_lowers_the_self_reconstruction_loss(tiny_dataset: Path, frozen: Path, tmp_path: Path) -> None:
    cfg = config(tiny_dataset, tmp_path / "run", frozen, steps=40, phase1_steps=34, ckpt_every=40, val_every=40,
                 batch=2, lr=5e-3)
    result = train_renderer(cfg)
    log = rows(tmp_path / "run" / "train.csv")
    self_lab = np.array([float(r["self_lab"]) for r in log])
    assert len(self_lab) == 40 and np.all(np.isfinite(self_lab))
    assert self_lab[24:34].mean() < 0.7 * self_lab[:10].mean()
    phase2 = [r for r in log if r["phase"] == "2"]
    assert len(phase2) == 6 and all(np.isfinite(float(r[k])) for r in phase2 for k in (*PHASE2_TERMS, "d_loss"))
    assert all(r[k] == "nan" for r in log[:34] for k in PHASE2_TERMS)  # phase 1: self + cross only
    for key in ("proposed_l1", "proposed_ssim", "lambertian_sh_psnr", "shadownet_lambertian_l1"):
        assert np.isfinite(result["val"][key]), key
    val = rows(tmp_path / "run" / "val.csv")[-1]  # the validation says how many cases it left out
    assert float(val["saturated_cases"]) == 0.0 and float(val["cases"]) == result["val"]["cases"] >= 1
    assert (tmp_path / "run" / "panels" / "step_0000040.png").is_file()
    assert list((tmp_path / "run" / "tb").iterdir())


def test_07_resume_after_a_kill_is_bit_identical_through_both_phases(tiny_dataset: Path, frozen: Path,
                                                                     tmp_path: Path) -> None:
    train_renderer(config(tiny_dataset, tmp_path / "straight", frozen))
    train_renderer(config(tiny_dataset, tmp_path / "killed", frozen, steps=5))  # dies after step 5...
    for ext in ("safetensors", "json"):
        (tmp_path / "killed" / "checkpoints" / f"step_0000005.{ext}").unlink()  # ...before saving it
    torch.manual_seed(999)  # another global RNG state must not matter
    train_renderer(config(tiny_dataset, tmp_path / "killed", frozen))
    ta = load_file(str(tmp_path / "straight" / "checkpoints" / "step_0000006.safetensors"))
    tb = load_file(str(tmp_path / "killed" / "checkpoints" / "step_0000006.safetensors"))
    assert ta.keys() == tb.keys()
    assert any(k.startswith("model.g.") for k in ta) and any(k.startswith("model.d.") for k in ta)
    assert any(k.startswith("optim.g.") for k in ta) and any(k.startswith("optim.d.") for k in ta)  # D trained
    for k in ta:
        assert torch.equal(ta[k], tb[k]), k
    la, lb = rows(tmp_path / "straight" / "train.csv"), rows(tmp_path / "killed" / "train.csv")
    assert [r["step"] for r in lb] == [str(i) for i in range(1, 7)]
    for key in ("total", "d_loss"):
        assert [r[key] for r in la] == [r[key] for r in lb], key
    with pytest.raises(ValueError, match="another configuration"):
        train_renderer(config(tiny_dataset, tmp_path / "killed", frozen, steps=8, phase1_steps=2))


def test_08_exported_weights_round_trip_and_plug_into_the_pipeline(tiny_dataset: Path, frozen: Path,
                                                                   tmp_path: Path) -> None:
    run = tmp_path / "run"
    train_renderer(config(tiny_dataset, run, frozen, steps=3, ckpt_every=3))
    dest = export_renderer(ckpt.latest_checkpoint(run), tmp_path / "w" / "renderer.safetensors")
    # The command line writes the same tensors, and names a missing step in one line.
    from physrelight.cli import main

    cli = ["train", "export-renderer", "--run", str(run), "--step"]
    assert main(cli + ["3", "--dest", str(tmp_path / "c.safetensors")]) == 0
    assert all(torch.equal(load_file(str(tmp_path / "c.safetensors"))[k], v) for k, v in load_file(str(dest)).items())
    assert main(cli + ["7", "--dest", str(tmp_path / "d.safetensors")]) == 2
    net = load_renderer(dest)
    meta = ckpt.load_weights(dest)[1]
    assert meta["kind"] == "renderer" and (meta["width"], meta["depth"], meta["additive"]) == ("4", "2", "1")
    models = {k[len("model.g."):]: v for k, v in load_file(str(ckpt.latest_checkpoint(run).with_suffix(
        ".safetensors"))).items() if k.startswith("model.g.")}
    state = net.state_dict()
    assert state.keys() == models.keys() and all(torch.equal(state[k], models[k]) for k in state)
    with pytest.raises(ValueError, match="not a neural renderer"):
        load_renderer(frozen / "shadow.safetensors")
    # the pipeline uses it: "proposed" now differs from the ShadowNet + Lambertian fallback
    for f in ("inverse.safetensors", "shadow.safetensors", "lighting_prior.npz"):
        shutil.copy(frozen / f, tmp_path / "w" / f)
    pipe = Relighter.load(tmp_path / "w")
    assert pipe.renderer is not None
    batch = PairSampler(tiny_dataset, split="all", res=24).batch(1, 0)
    image, sky = batch.image[:1], batch.sky[:1]
    target = decompose_and_solve(pipe.inverse, image, sky, load_prior(frozen / "lighting_prior.npz"))["lighting"]
    prop = pipe.relight_linear(image, sky, target.flip(1).abs(), None, "proposed")
    fall = pipe.relight_linear(image, sky, target.flip(1).abs(), None, "shadownet_lambertian")
    assert torch.equal(prop["relit"][sky.expand_as(image)], image[sky.expand_as(image)])
    assert not torch.equal(prop["relit"], fall["relit"])
    result = evaluate_relight(pipe.relight_linear, tiny_dataset, "all", 24, max_cases=4)
    assert result["cases"] >= 1 and result["identity"]["l1"] > 0
    for m in ("proposed", "lambertian_sh", "shadownet_lambertian", "identity"):
        assert 0 <= result[m]["l1"] <= 1 and -1 <= result[m]["ssim"] <= 1, m
    # The paired comparison: proposed minus each method, its mean equal to the difference of means.
    for m in ("lambertian_sh", "shadownet_lambertian", "identity"):
        for k in ("l1", "ssim", "psnr", "ciede2000"):
            p = result["paired"][m][k]
            assert p["diff"] == pytest.approx(result["proposed"][k] - result[m][k], abs=1e-4), (m, k)  # float32 scores
            assert p["lo"] <= p["diff"] <= p["hi"]


def test_09_a_reference_pipeline_is_scored_on_the_same_cases_and_paired(tiny_dataset: Path, frozen: Path,
                                                                        tmp_path: Path) -> None:
    pipe = Relighter.load(frozen)

    def as_lambertian(image, sky, target, source, method):  # a "second pipeline" whose proposed is lambertian_sh
        return pipe.relight_linear(image, sky, target, source, "lambertian_sh")

    result = evaluate_relight(pipe.relight_linear, tiny_dataset, "all", 24, max_cases=4, reference=as_lambertian)
    assert result["reference"] == result["lambertian_sh"]
    assert result["paired"]["reference"] == result["paired"]["lambertian_sh"]
    same = evaluate_relight(pipe.relight_linear, tiny_dataset, "all", 24, max_cases=4, reference=pipe.relight_linear)
    for k in ("l1", "ssim", "psnr", "ciede2000"):
        assert same["paired"]["reference"][k]["diff"] == 0.0
        assert same["paired"]["reference"][k]["lo"] == same["paired"]["reference"][k]["hi"] == 0.0
    from physrelight.cli import main

    out = tmp_path / "r.json"
    assert main(["train", "evaluate-relight", "--data", str(tiny_dataset), "--weights", str(frozen), "--max-cases",
                 "4", "--res", "24", "--quiet", "--reference-weights", str(frozen), "--json", str(out)]) == 0
    assert "reference" in json.loads(out.read_text())
    assert main(["train", "evaluate-relight", "--data", str(tiny_dataset), "--weights", str(frozen), "--quiet",
                 "--reference-weights", str(tmp_path / "missing")]) != 0


def test_10_a_target_clipped_on_the_whole_foreground_is_left_out_and_counted(tiny_dataset: Path, frozen: Path,
                                                                              monkeypatch) -> None:
    # An over-exposed target (1 on every foreground pixel) is matched exactly by any prediction at least
    # as bright: its PSNR is inf and it cannot rank methods. It is left out of every method alike.
    import learned.relight_eval as rev

    pipe = Relighter.load(frozen)

    def bright(image, sky, target, source, method):  # saturates everywhere: PSNR inf on a clipped target
        return {"relit": torch.full_like(image, 50.0)}

    base = evaluate_relight(bright, tiny_dataset, "all", 24, max_cases=4, reference=pipe.relight_linear)
    assert base["saturated_cases"] == 0.0 and base["cases"] == 4.0
    real = rev.load_case
    ds = rev.SynthDataset(tiny_dataset, split="all", mode="full")
    first = rev.relight_cases(ds)[0]

    def clipped_first(ds, scene, view, a, b, res):
        case = real(ds, scene, view, a, b, res)
        if (scene, view, a, b) == first:
            case["target_ldr"] = torch.where(case["fg"], torch.ones_like(case["target_ldr"]), case["target_ldr"])
        return case

    case, clipped = real(ds, *first, 24), clipped_first(ds, *first, 24)
    assert rev.informative_target(case["target_ldr"], case["fg"])
    assert not rev.informative_target(clipped["target_ldr"], clipped["fg"])
    monkeypatch.setattr(rev, "load_case", clipped_first)
    out = evaluate_relight(bright, tiny_dataset, "all", 24, max_cases=4, reference=pipe.relight_linear)
    assert out["saturated_cases"] == 1.0 and out["cases"] == 3.0
    assert np.isfinite(out["proposed"]["psnr"])  # without the rule: inf, and the paired bootstrap refuses
    assert all(np.isfinite(v["diff"]) for v in out["paired"]["reference"].values())
    assert "1 left out" in rev.format_table(out)


def _quotient_pipeline(tiny_dataset: Path, frozen: Path, tmp_path: Path):
    """A tiny quotient-based renderer trained 3 steps and exported into a weights folder with the frozen
    networks: ``(weights file, Relighter, image (1, 3, 24, W), sky, its decomposition)``."""
    run = tmp_path / "run"
    train_renderer(config(tiny_dataset, run, frozen, steps=3, ckpt_every=3, phase1_steps=3, base="quotient",
                          additive=False))
    dest = export_renderer(ckpt.latest_checkpoint(run), tmp_path / "w" / "renderer.safetensors")
    for f in ("inverse.safetensors", "shadow.safetensors", "lighting_prior.npz"):
        shutil.copy(frozen / f, tmp_path / "w" / f)
    pipe = Relighter.load(tmp_path / "w")
    batch = PairSampler(tiny_dataset, split="all", res=24).batch(1, 0)
    image, sky = batch.image[:1], batch.sky[:1]
    return dest, pipe, image, sky, pipe.decompose_linear(image, sky)


def test_11_a_quotient_based_renderer_starts_at_the_quotient_method_and_round_trips(tiny_dataset: Path,
                                                                                   frozen: Path,
                                                                                   tmp_path: Path) -> None:
    """``base="quotient"`` (issue 26): with its head at zero the renderer *is* the quotient method
    (through the Relighter, ``proposed`` equals ``quotient``), so relighting a photo to its own
    lighting gives the photo; the 17th-channel input is required and checked; a tiny run trains,
    exports with its base in the metadata, and loads back as a quotient-based renderer."""
    dest, pipe, image, sky, dec = _quotient_pipeline(tiny_dataset, frozen, tmp_path)
    assert ckpt.load_weights(dest)[1]["base"] == "quotient"
    net = load_renderer(dest)
    assert net.base == "quotient" and net.in_channels == 17
    target = dec["lighting"].flip(1).abs()
    trained = pipe.relight_linear(image, sky, target, None, "proposed")["relit"]
    quotient = pipe.relight_linear(image, sky, target, None, "quotient")["relit"]
    assert not torch.equal(trained, quotient)  # the trained gain acts
    torch.nn.init.zeros_(pipe.renderer.unet.head.weight)
    torch.nn.init.zeros_(pipe.renderer.unet.head.bias)
    fg = (~sky).expand_as(image)
    torch.testing.assert_close(pipe.relight_linear(image, sky, target, None, "proposed")["relit"][fg],
                               positive(quotient)[fg])
    own = pipe.relight_linear(image, sky, dec["lighting"], None, "proposed")["relit"]
    torch.testing.assert_close(own[fg], positive(image)[fg])
    # the known track: the quotient divides by the given source, so relit to it the photo comes back
    given = dec["lighting"] * 3.0
    known = pipe.relight_linear(image, sky, given, given, "proposed", known_source=True)["relit"]
    torch.testing.assert_close(known[fg], positive(image)[fg])
    # the quotient image is required by a quotient-based renderer and refused by a Lambertian one
    with pytest.raises(ValueError, match="needs quotient"):
        render_relit(pipe.renderer, image, sky, dec, target, torch.ones_like(sky, dtype=image.dtype))
    pipe.renderer = NeuralRenderer(4, 2)  # a Lambertian-based renderer has no known track
    with pytest.raises(ValueError, match="known_source"):
        pipe.relight_linear(image, sky, given, given, "proposed", known_source=True)
    with pytest.raises(ValueError, match="takes no quotient"):
        render_relit(NeuralRenderer(4, 2), image, sky, dec, target, torch.ones_like(sky, dtype=image.dtype),
                     quotient=image)
    with pytest.raises(ValueError, match="base"):
        NeuralRenderer(4, 2, base="phong")


def test_12_the_gain_ratio_variant_gives_the_quotient_when_relit_to_the_source(tiny_dataset: Path, frozen: Path,
                                                                               tmp_path: Path) -> None:
    """``RelightOptions.renderer_gain_ratio`` (study 29, off by default): the renderer's gain for the target over
    its gain for the source, so relit to its own lighting the photo gets the quotient's ratio alone, whatever
    the renderer learned; to another lighting it differs from the quotient."""
    _, pipe, image, sky, dec = _quotient_pipeline(tiny_dataset, frozen, tmp_path)
    fg = (~sky).expand_as(image)
    plain_self = pipe.relight_linear(image, sky, dec["lighting"], None, "proposed")["relit"]
    pipe = pipe.with_options(renderer_gain_ratio=True)
    own = pipe.relight_linear(image, sky, dec["lighting"], None, "proposed")["relit"]
    quotient = pipe.relight_linear(image, sky, dec["lighting"], None, "quotient")["relit"]
    torch.testing.assert_close(own[fg], positive(quotient)[fg])
    assert not torch.allclose(plain_self[fg], own[fg])  # the plain gain changes a self-relighting
    target = dec["lighting"].flip(1).abs()
    other = pipe.relight_linear(image, sky, target, None, "proposed")["relit"]
    assert not torch.allclose(other, pipe.relight_linear(image, sky, target, None, "quotient")["relit"])
