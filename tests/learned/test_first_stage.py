"""Specification of the first stage: self-supervised training of the inverse network and ShadowNet.

Runs on a tiny dataset rendered in a fixture (3 scenes x 2 views x 2 lightings, 24 px) with
tiny networks; the whole file takes about a minute on 2 cores.
"""

from __future__ import annotations

import csv
import math
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from learned import checkpoint as ckpt
from learned.data import PairSampler
from learned.networks import InverseNet, ShadowNet
from learned.objectives import inverse_losses
from learned.train import TrainConfig, train
from physrelight.lighting_prior import LightingPrior
from synth.dataset import GroundTruthAccessError

from .conftest import TINY, TINY_NET, save_weights, tiny_train_config

config = tiny_train_config


def rows(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


def test_01_the_training_loader_refuses_ground_truth(tiny_dataset: Path) -> None:
    sampler = PairSampler(tiny_dataset, split="all", res=24)
    for key in ("albedo", "normal", "depth", "shadow", "sh", "lighting", "radiance", "photo_params"):
        with pytest.raises(GroundTruthAccessError):
            sampler.ds.load("scene_0000", 0, 0, keys=(key,))
    batch = sampler.batch(2, step=0)
    assert batch.image.shape == (4, 3, 24, 24) and batch.depth.shape == (4, 1, 24, 24)
    # Only what MVS and the cameras give; the optional normals are the MVS depth's own (None unless pooled).
    assert set(vars(batch)) == {"image", "depth", "sky", "K", "world_to_camera", "keys", "mvs_normal", "mvs_valid",
                                "network_image"}
    assert batch.mvs_normal is None and batch.mvs_valid is None and batch.network_image is None


def test_02_batches_are_a_function_of_seed_step_and_rank(tiny_dataset: Path) -> None:
    a = PairSampler(tiny_dataset, split="all", res=24, seed=1)
    b = PairSampler(tiny_dataset, split="all", res=24, seed=1, cache=False)
    assert a.pair_keys(3, 7, 0) == b.pair_keys(3, 7, 0)
    assert torch.equal(a.batch(3, 7).image, b.batch(3, 7).image)
    assert a.pair_keys(3, 7, 0) != a.pair_keys(3, 7, 1) or a.pair_keys(3, 8, 0) != a.pair_keys(3, 7, 0)
    for (sa, va, la), (sb, vb, lb) in a.pair_keys(20, 3):
        assert sa == sb and (va, la) != (vb, lb)  # two different photos of one scene


def test_03_networks_output_valid_layers_in_any_mode_and_batch() -> None:
    torch.manual_seed(0)
    net = InverseNet(width=4, depth=2)
    x = torch.rand(3, 3, 21, 26)
    with torch.no_grad():
        out = net(x)
    assert out["albedo"].shape == (3, 3, 21, 26) and out["shadow"].shape == (3, 1, 21, 26)
    assert float(out["albedo"].min()) >= 0 and float(out["albedo"].max()) <= 1
    assert torch.allclose(out["normals"].norm(dim=1), torch.ones(3, 21, 26), atol=1e-5)
    assert float(out["normals"][:, 2].min()) > 0  # facing the camera
    # GroupNorm, no batch statistics: the same image gives the same output alone, in a batch, train or eval.
    alone = net.eval()(x[1:2])["albedo"]
    assert torch.allclose(net.train()(x)["albedo"][1:2], alone, atol=1e-5)
    sn = ShadowNet(width=4, depth=2)
    light = torch.randn(3, 9, 3)
    with torch.no_grad():
        s = sn(out["normals"], light)
    assert s.shape == (3, 1, 21, 26) and float(s.min()) >= 0 and float(s.max()) <= 1
    assert torch.allclose(sn.eval()(out["normals"][:1].detach(), light[:1] * 7.0), s[:1], atol=1e-5)  # scale-free
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        net(torch.rand(3, 21, 26))


def test_04_gradients_flow_through_the_lighting_solve_into_the_network(tiny_dataset: Path, tiny_prior: Path) -> None:
    torch.manual_seed(0)
    net = InverseNet(width=4, depth=2)
    batch = PairSampler(tiny_dataset, split="all", res=24).batch(2, 0)
    prior = LightingPrior.load(tiny_prior)
    captured = {}

    def hook(grad: torch.Tensor) -> None:
        captured["lighting"] = grad

    from learned import objectives

    original = objectives.solve_projected

    def spy(*args, **kw):
        solved, projected = original(*args, **kw)
        assert solved.requires_grad and projected.requires_grad
        projected.register_hook(hook)
        return solved, projected

    objectives.solve_projected = spy
    try:
        total, terms, out = inverse_losses(net, batch, prior)
    finally:
        objectives.solve_projected = original
    total.backward()
    assert captured["lighting"].abs().sum() > 0  # the loss depends on the solved lighting...
    # ...and the solve's gradient reaches the albedo head: d(lighting)/d(albedo) != 0.
    image = batch.image
    albedo = net(image)["albedo"].detach().requires_grad_(True)
    normals = net(image)["normals"].detach()
    solved = objectives.solve_projected(image, albedo, normals, torch.ones_like(image[:, :1]),
                                        (~batch.sky).float(), prior)[1]
    solved.sum().backward()
    assert albedo.grad is not None and float(albedo.grad.abs().sum()) > 0
    assert all(p.grad is not None for p in net.parameters())
    assert set(terms) == {"appearance", "albedo", "normal", "normal_smooth", "cross", "prior", "shadow"}


def test_05_a_tiny_self_supervised_run_lowers_the_loss(tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    cfg = config(tiny_dataset, tmp_path / "run", tiny_prior, steps=40, ckpt_every=40, val_every=40, log_every=1,
                 batch=2)
    result = train(cfg)
    log = rows(tmp_path / "run" / "train.csv")
    total = np.array([float(r["total"]) for r in log])
    assert len(total) == 40 and np.all(np.isfinite(total))
    assert total[-10:].mean() < 0.7 * total[:10].mean()
    for key in ("albedo_si_mse", "normal_mae_deg", "normal_median_deg", "shadow_ap", "lighting_rel_err",
                "lighting_shading_err", "oracle_lighting_shading_err", "oracle_map_lighting_shading_err",
                "oracle_albedo_si_mse", "oracle_shadow_ap", "baseline_albedo_si_mse", "implied_albedo_si_mse",
                "implied_albedo_si_mse_true_lighting", "implied_albedo_si_mse_true_normals_lighting"):
        assert np.isfinite(result["val"][key]), key
    assert (tmp_path / "run" / "panels" / "step_0000040.png").is_file()
    assert list((tmp_path / "run" / "tb").iterdir())  # TensorBoard events
    assert (tmp_path / "run" / "checkpoints" / "step_0000040.safetensors").is_file()


def test_06_resume_after_a_kill_gives_identical_state_and_losses(tiny_dataset: Path, tiny_prior: Path,
                                                                  tmp_path: Path) -> None:
    straight = config(tiny_dataset, tmp_path / "straight", tiny_prior, steps=6, ckpt_every=3)
    train(straight)
    killed = config(tiny_dataset, tmp_path / "killed", tiny_prior, steps=6, ckpt_every=3)
    train(config(tiny_dataset, tmp_path / "killed", tiny_prior, steps=4, ckpt_every=3))  # dies after step 4...
    (tmp_path / "killed" / "checkpoints" / "step_0000004.safetensors").unlink()
    (tmp_path / "killed" / "checkpoints" / "step_0000004.json").unlink()  # ...before its step-4 checkpoint
    torch.manual_seed(1234)  # a different global RNG state must not matter
    train(killed)
    a = ckpt.load_checkpoint(tmp_path / "straight" / "checkpoints" / "step_0000006.json")
    b = ckpt.load_checkpoint(tmp_path / "killed" / "checkpoints" / "step_0000006.json")
    assert a["step"] == b["step"] == 6
    from safetensors.torch import load_file

    ta = load_file(str(tmp_path / "straight" / "checkpoints" / "step_0000006.safetensors"))
    tb = load_file(str(tmp_path / "killed" / "checkpoints" / "step_0000006.safetensors"))
    assert ta.keys() == tb.keys() and any(k.startswith("optim.") for k in ta)
    for k in ta:
        assert torch.equal(ta[k], tb[k]), k  # model, Adam moments, RNG: bit-identical
    la, lb = rows(tmp_path / "straight" / "train.csv"), rows(tmp_path / "killed" / "train.csv")
    assert [r["step"] for r in lb] == [str(i) for i in range(1, 7)]  # rows after the checkpoint replaced
    assert [r["total"] for r in la] == [r["total"] for r in lb]  # the same numbers after the resume


def test_07_ddp_with_two_gloo_processes_trains_and_agrees(tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    torchrun = Path(sys.executable).with_name("torchrun")
    physrelight = Path(sys.executable).with_name("physrelight")
    out = tmp_path / "ddp"
    cmd = [str(torchrun), "--standalone", "--nproc_per_node", "2", str(physrelight), "train", "inverse",
           "--data", str(tiny_dataset), "--out", str(out), "--prior", str(tiny_prior), "--train-split", "all",
           "--val-split", "all", "--width", "4", "--depth", "2", "--res", "24", "--batch", "1", "--steps", "3",
           "--ckpt-every", "3", "--val-every", "3", "--val-images", "2", "--threads", "1", "--log-every", "1", "--quiet"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=240, env=env)
    assert proc.returncode == 0, proc.stderr[-3000:]
    meta = ckpt.load_checkpoint(out / "checkpoints" / "step_0000003.json", restore_rng=False)
    assert meta["world_size"] == 2
    assert len(rows(out / "train.csv")) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert summary["world_size"] == 2 and summary["rank_param_max_diff"] < 1e-6  # DDP kept the ranks in sync


def test_08_exported_weights_load_offline_and_relight(tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    from learned import Relighter

    inv = config(tiny_dataset, tmp_path / "inv", tiny_prior, steps=2, ckpt_every=2, val_every=2)
    train(inv)
    train(config(tiny_dataset, tmp_path / "sh", tiny_prior, stage="shadow", inverse=str(tmp_path / "inv"),
                 steps=2, ckpt_every=2, val_every=2))
    dest = tmp_path / "weights"
    ckpt.export_weights(ckpt.latest_checkpoint(tmp_path / "inv"), dest / "inverse.safetensors", "inverse")
    ckpt.export_weights(ckpt.latest_checkpoint(tmp_path / "sh"), dest / "shadow.safetensors", "shadow")
    shutil.copy(tiny_prior, dest / "lighting_prior.npz")
    r = Relighter.load(dest)
    photo = (np.random.default_rng(0).uniform(0, 1, (24, 32, 3))).astype(np.float32)
    out = r.decompose(photo)
    assert out["albedo"].shape == (24, 32, 3) and out["normals"].shape == (24, 32, 3)
    assert out["shadow"].shape == (24, 32, 1) and out["lighting"].shape == (9, 3)
    # Round trip: the same weights, re-saved and re-loaded, give the same decomposition.
    again = Relighter.load(dest).decompose(photo)
    np.testing.assert_array_equal(out["albedo"], again["albedo"])
    target = np.zeros((9, 3))
    target[0] = 1.0
    relit = r.relight(photo, target)
    assert relit.shape == (24, 32, 3) and 0 <= relit.min() and relit.max() <= 1
    env = np.ones((8, 16, 3), np.float32)
    relit_t = r.relight(torch.from_numpy(photo).permute(2, 0, 1), env, world_to_camera=np.eye(4))
    assert relit_t.shape == (3, 24, 32)
    from physrelight import sh
    from physrelight.target_lighting import target_lighting

    sun = target_lighting(np.array([0.0, 2.0, 0.0]))  # sun overhead, level camera

    e_up = sh.irradiance(sun.numpy(), np.array([[0.0, 1.0, 0.0]]))[0]
    # the order-2 sun at its own direction (1/4 + 1/2 + 5/16 = 1.0625 in every channel, the clamped
    # cosine's truncation) + the clear fill sky (Hosek-Wilkie's with the sun overhead: 0.21 of the sun's
    # irradiance in green, bluer than it is red; checked against Mitsuba in tests/synth/test_sunsky_table.py)
    from physrelight.target_lighting import sun_sky_map

    sky_up = sh.irradiance(sh.project_envmap(sun_sky_map("clear", [0.0, 1.0, 0.0]), order=2),
                           np.array([[0.0, 1.0, 0.0]]))[0]
    np.testing.assert_allclose(e_up - sky_up, 1.0625, rtol=1e-6)
    assert 0.18 < sky_up[1] < 0.25 and sky_up[2] > sky_up[1] > sky_up[0]
    with pytest.raises(ValueError, match="target"):
        r.relight(photo, np.zeros((4, 3)))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        r.decompose(photo * 3)
    with pytest.raises(ValueError, match="rotation"):
        r.relight(photo, target, world_to_camera=np.diag([1.0, 1.0, -1.0]))
    # A checkpoint by step (what `train export --inverse-step` and `export-renderer --step` read).
    assert ckpt.checkpoint_at(tmp_path / "inv", 2) == ckpt.checkpoint_at(tmp_path / "inv") == \
        ckpt.latest_checkpoint(tmp_path / "inv")
    with pytest.raises(ValueError, match="no checkpoint of step 99"):
        ckpt.checkpoint_at(tmp_path / "inv", 99)
    with pytest.raises(ValueError, match="no checkpoint in"):
        ckpt.checkpoint_at(tmp_path / "empty")
    from physrelight.cli import main

    args = ["train", "export", "--inverse", str(tmp_path / "inv"), "--shadow", str(tmp_path / "sh")]
    assert main(args + ["--inverse-step", "2", "--dest", str(tmp_path / "by_step")]) == 0
    for f in ("inverse.safetensors", "shadow.safetensors"):
        assert ckpt.load_weights(tmp_path / "by_step" / f)[0].keys() == ckpt.load_weights(dest / f)[0].keys()
    assert main(args + ["--shadow-step", "5", "--dest", str(tmp_path / "none")]) == 2
    # --lighting-solve picks the lighting step the exported network runs (default: as trained).
    from learned.networks import load_inverse

    assert main(args + ["--lighting-solve", "map_relative", "--dest", str(tmp_path / "rel")]) == 0
    assert load_inverse(tmp_path / "rel" / "inverse.safetensors").lighting_solve == "map_relative"
    assert load_inverse(dest / "inverse.safetensors").lighting_solve == "project"
    # --mirror-average: the exported network averages each photo with its mirror image (test_20).
    assert main(args + ["--mirror-average", "--dest", str(tmp_path / "mir")]) == 0
    assert load_inverse(tmp_path / "mir" / "inverse.safetensors").mirror_average
    assert not load_inverse(dest / "inverse.safetensors").mirror_average
    # A candidate folder from an inverse run alone: --fill-from copies the rest of a complete folder.
    cand = tmp_path / "candidate"
    inv_only = ["train", "export", "--inverse", str(tmp_path / "inv"), "--dest", str(cand)]
    assert main(inv_only + ["--fill-from", str(dest)]) == 0
    assert (cand / "shadow.safetensors").read_bytes() == (dest / "shadow.safetensors").read_bytes()
    assert (cand / "lighting_prior.npz").read_bytes() == (dest / "lighting_prior.npz").read_bytes()
    np.testing.assert_array_equal(Relighter.load(cand).decompose(photo)["albedo"], out["albedo"])
    assert main(inv_only + ["--fill-from", str(tmp_path / "nowhere")]) == 2
    assert main(inv_only + ["--shadow-step", "2"]) == 2


def test_09_the_shipped_weights_load_without_arguments() -> None:
    from learned import Relighter
    from learned.lighting import WEIGHTS_DIR

    if not (WEIGHTS_DIR / "inverse.safetensors").is_file():
        pytest.fail("no shipped weights in learned/weights (see docs/learned.md to train them)")
    r = Relighter.load()
    total = sum(p.stat().st_size for p in WEIGHTS_DIR.iterdir())
    assert total < 8e6  # a few MB
    out = r.decompose(np.full((32, 32, 3), 128, np.uint8))
    assert np.isfinite(out["lighting"]).all()


def test_10_init_warm_starts_from_another_run_and_refuses_a_mismatched_network(tiny_dataset: Path,
                                                                               tiny_prior: Path, tmp_path: Path) -> None:
    train(config(tiny_dataset, tmp_path / "base", tiny_prior, steps=3, ckpt_every=3))
    train(config(tiny_dataset, tmp_path / "tuned", tiny_prior, steps=1, ckpt_every=1, init=str(tmp_path / "base")))
    from safetensors.torch import load_file

    base = load_file(str(tmp_path / "base" / "checkpoints" / "step_0000003.safetensors"))
    tuned = load_file(str(tmp_path / "tuned" / "checkpoints" / "step_0000001.safetensors"))
    params = [k for k in base if k.startswith("model.") and base[k].is_floating_point()]
    assert params
    # One Adam step moves a parameter by at most ~lr (3e-3); a fresh initialisation differs by far more.
    worst = max(float((tuned[k] - base[k]).abs().max()) for k in params)
    assert worst < 3.1e-3, worst
    with pytest.raises(ValueError, match="does not match"):
        train(config(tiny_dataset, tmp_path / "wide", tiny_prior, steps=1, width=8, init=str(tmp_path / "base")))
    with pytest.raises(ValueError, match="does not exist"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, init=str(tmp_path / "missing"))


def test_11_a_log_whose_metrics_gain_a_column_keeps_every_value_under_its_heading(tmp_path: Path) -> None:
    from learned.runs import RunLogs

    logs = RunLogs(tmp_path, 0, True)
    logs.write("val.csv", 1, {"a": 1.0, "b": 2.0})
    logs.write("val.csv", 2, {"a": 3.0, "c": 4.0, "b": 5.0})  # a new metric, in another order
    logs.write("val.csv", 3, {"a": 6.0, "b": 7.0, "c": 8.0})
    logs.close()
    got = rows(tmp_path / "val.csv")
    assert list(got[0]) == ["step", "a", "b", "c"]
    assert got == [{"step": "1", "a": "1", "b": "2", "c": ""}, {"step": "2", "a": "3", "b": "5", "c": "4"},
                   {"step": "3", "a": "6", "b": "7", "c": "8"}]


def test_12_the_lighting_shading_error_sees_only_what_the_photo_faces() -> None:
    from learned.evaluate import shading_error

    rng = np.random.default_rng(0)
    L = torch.from_numpy(rng.normal(size=(9, 3))) + torch.tensor([3.0, 3.0, 3.0])  # a positive DC term
    up = torch.zeros(3, 8, 8, dtype=torch.float64)
    up[2] = 1.0  # every pixel faces the camera (+z)
    mask = torch.ones(1, 8, 8, dtype=torch.bool)
    assert shading_error(L, L, up, mask) == pytest.approx(0.0, abs=1e-12)
    assert shading_error(2.5 * L, L, up, mask) == pytest.approx(0.0, abs=1e-12)  # scale-free
    # Index l(l+1)+m: 1 is Y_1,-1 (~ y), 4 is Y_2,-2 (~ xy); both vanish at n = +z, so changing
    # them changes nothing this photo shows, however far the coefficients move.
    unseen = L.clone()
    unseen[1] += 5.0
    unseen[4] -= 5.0
    assert shading_error(unseen, L, up, mask) == pytest.approx(0.0, abs=1e-9)
    # Y_1,0 (~ z) changes the shading these pixels see; with a single normal that is only a
    # scale, so half the pixels get another normal and the change must show.
    seen = L.clone()
    seen[2] += 1.0
    tilted = up.clone()
    tilted[0, :, :4] = 0.6
    tilted[2, :, :4] = 0.8
    assert shading_error(seen, L, tilted, mask) > 1e-3
    with pytest.raises(ValueError, match="empty mask"):
        shading_error(L, L, up, torch.zeros(1, 8, 8, dtype=torch.bool))


def test_13_the_map_lighting_solve_travels_with_the_network(tiny_dataset: Path, tiny_prior: Path,
                                                            tmp_path: Path) -> None:
    from learned.objectives import decompose_and_solve
    from learned.networks import load_inverse
    from physrelight import image_model

    train(config(tiny_dataset, tmp_path / "map", tiny_prior, steps=2, ckpt_every=2, val_every=2,
                 lighting_solve="map"))
    ckpt.export_weights(ckpt.latest_checkpoint(tmp_path / "map"), tmp_path / "inverse.safetensors", "inverse")
    prior = LightingPrior.load(tiny_prior)
    image = PairSampler(tiny_dataset, split="all", res=24).batch(1, 0).image
    sky = torch.zeros(image.shape[0], 1, 24, 24, dtype=torch.bool)
    for source in (tmp_path / "map", tmp_path / "inverse.safetensors"):  # run folder and exported file
        net = load_inverse(source)
        assert net.lighting_solve == "map"
        with torch.no_grad():
            out = decompose_and_solve(net, image, sky, prior)
            expected = image_model.solve_lighting_map(image, out["albedo"], out["normals"], torch.ones_like(sky).float(),
                                                      prior, shadow=out["shadow"])
        torch.testing.assert_close(out["lighting"], expected.float())
        torch.testing.assert_close(prior.project(out["lighting"]), out["lighting"], atol=1e-4, rtol=1e-4)
        assert not torch.allclose(out["lighting"], prior.project(out["lighting_solved"]))  # not the paper's step
    with pytest.raises(ValueError, match="lighting_solve"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, lighting_solve="ridge")
    with pytest.raises(ValueError, match="lighting_solve"):
        InverseNet(4, 2, "ridge")


def test_14_the_shadow_head_starts_where_asked(tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    image = PairSampler(tiny_dataset, split="all", res=24).batch(1, 0).image
    for logit in (3.0, 1.0):
        torch.manual_seed(0)
        with torch.no_grad():
            s = InverseNet(4, 2, initial_shadow_logit=logit)(image)["shadow"]
        # The head's other weights are small at initialisation: s sits near sigmoid(logit).
        assert abs(float(s.mean()) - 1 / (1 + np.exp(-logit))) < 0.1, (logit, float(s.mean()))
    with pytest.raises(ValueError, match="initial_shadow_logit"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, initial_shadow_logit=float("nan"))


def test_15_the_one_sided_mvs_stencil_supervises_more_pixels_with_the_same_normals(tiny_dataset: Path,
                                                                                   tiny_prior: Path,
                                                                                   tmp_path: Path) -> None:
    from learned.data import mvs_normals

    batch = PairSampler(tiny_dataset, split="all", res=24).batch(2, 0)
    n_c, v_c = mvs_normals(batch)
    n_o, v_o = mvs_normals(batch, "one_sided")
    # Every centrally supervised pixel stays supervised (so here and on data/train: a pixel could
    # only drop if both sides of an axis failed the nearer-depth jump test) and more join it.
    assert not bool((v_c & ~v_o).any())
    assert int(v_o.sum()) > int(v_c.sum())
    both = v_c.expand_as(n_c)
    # Central where both sides are usable; the jump test differs (centre vs nearer depth), so
    # a few central pixels fall back to one side (0.5 % on data/train): the rest are equal.
    same = (n_o - n_c).abs().amax(1, keepdim=True) < 1e-6
    assert float(same[v_c].float().mean()) > 0.9 and bool(torch.isfinite(n_o[both]).all())
    assert not bool(v_o[batch.sky].any())
    torch.manual_seed(0)
    net = InverseNet(4, 2)
    prior = LightingPrior.load(tiny_prior)
    _, t_c, _ = inverse_losses(net, batch, prior)
    _, t_o, _ = inverse_losses(net, batch, prior, mvs_stencil="one_sided")
    assert t_o["normal"] != t_c["normal"] and t_o["appearance"] == t_c["appearance"]
    with pytest.raises(ValueError, match="mvs_stencil"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, mvs_stencil="sobel")


def test_16_exports_are_byte_reproducible_and_carry_a_chosen_lighting_step(tiny_dataset: Path, tiny_prior: Path,
                                                                          tmp_path: Path) -> None:
    from learned.objectives import decompose_and_solve
    from learned.networks import load_inverse
    from physrelight import image_model

    run = tmp_path / "map"
    train(config(tiny_dataset, run, tiny_prior, steps=2, ckpt_every=2, val_every=2, lighting_solve="map"))
    side = ckpt.latest_checkpoint(run)
    # safetensors writes its metadata from a hash map: the header's key order used to change
    # from one export to the next. Same checkpoint, same bytes now; mode as open() gives.
    a = ckpt.export_weights(side, tmp_path / "a.safetensors", "inverse")
    b = ckpt.export_weights(side, tmp_path / "b.safetensors", "inverse")
    assert a.read_bytes() == b.read_bytes()
    umask = os.umask(0)
    os.umask(umask)
    assert (a.stat().st_mode & 0o777) == (0o666 & ~umask)
    # The lighting step chosen at export travels with the weights and is the one used.
    w = tmp_path / "w"
    ckpt.export_weights(side, w / "inverse.safetensors", "inverse", extra={"lighting_solve": "map_relative"})
    net = load_inverse(w / "inverse.safetensors")
    assert net.lighting_solve == "map_relative" and load_inverse(a).lighting_solve == "map"
    prior = LightingPrior.load(tiny_prior)
    image = PairSampler(tiny_dataset, split="all", res=24).batch(1, 0).image
    sky = torch.zeros(image.shape[0], 1, 24, 24, dtype=torch.bool)
    with torch.no_grad():
        out = decompose_and_solve(net, image, sky, prior)
        expected = image_model.solve_lighting_map(image, out["albedo"], out["normals"], torch.ones_like(sky).float(),
                                                  prior, shadow=out["shadow"], relative=True)
    torch.testing.assert_close(out["lighting"], expected.float())


def test_17_edge_aware_smoothness_charges_normal_breaks_where_the_photo_is_smooth() -> None:
    from learned.objectives import SMOOTHNESS_EDGE_GAIN, edge_aware_smoothness

    h, w, k = 6, 8, 4
    up = torch.tensor([0.0, 1.0, 0.0]).reshape(1, 3, 1, 1).expand(1, 3, h, w).clone()
    fg = torch.ones(1, 1, h, w)
    flat = torch.full((1, 3, h, w), 0.2**2.2)  # linear; display value 0.2
    assert float(edge_aware_smoothness(up, flat, fg)) == 0.0  # constant normals cost nothing
    broken = up.clone()
    broken[:, :, :, k:] = torch.tensor([0.0, 0.0, 1.0]).reshape(1, 3, 1, 1)  # a crease between columns k-1, k
    pairs = h * (w - 1) + (h - 1) * w
    jump = 2.0  # |(0, 1, 0) - (0, 0, 1)|_1
    torch.testing.assert_close(edge_aware_smoothness(broken, flat, fg), torch.tensor(h * jump / pairs))
    # The same crease on an image edge (display values 0.2 -> 0.8) costs exp(-g 0.6) as much.
    edge = flat.clone()
    edge[:, :, :, k:] = 0.8**2.2
    expected = h * jump * math.exp(-SMOOTHNESS_EDGE_GAIN * 0.6) / pairs
    torch.testing.assert_close(edge_aware_smoothness(broken, edge, fg), torch.tensor(expected), rtol=1e-5, atol=1e-7)
    # Only pairs with both pixels in the foreground count: a crease against the sky is free.
    sky_right = fg.clone()
    sky_right[:, :, :, k:] = 0.0
    assert float(edge_aware_smoothness(broken, flat, sky_right)) == 0.0
    n = broken.clone().requires_grad_(True)
    edge_aware_smoothness(n, flat, fg).backward()
    assert torch.isfinite(n.grad).all() and float(n.grad.abs().sum()) > 0


def test_18_a_run_recorded_before_a_loss_term_existed_keeps_its_identity(tiny_dataset: Path, tiny_prior: Path,
                                                                         tmp_path: Path) -> None:
    new = config(tiny_dataset, tmp_path / "r", tiny_prior)
    old_weights = {k: v for k, v in new.weights.items() if k != "normal_smooth"}
    old = config(tiny_dataset, tmp_path / "r", tiny_prior, weights=old_weights)
    assert old.weights["normal_smooth"] == 0.0 and old.identity() == new.identity()  # resumable


def test_19_a_mirrored_pair_is_the_mirror_image_of_the_pair_in_every_multi_view_term(tiny_dataset: Path,
                                                                                     tiny_prior: Path,
                                                                                     tmp_path: Path) -> None:
    from learned.data import Batch, mirror_view, mvs_normals
    from physrelight import camera, sh

    plain = PairSampler(tiny_dataset, split="all", res=24)
    batch = plain.batch(2, 0)
    names = ("image", "depth", "sky", "K", "world_to_camera")
    views = [mirror_view(*(getattr(batch, n)[i] for n in names)) for i in range(4)]
    mirrored = Batch(*(torch.stack([v[k] for v in views]) for k in range(5)), keys=batch.keys)
    flip_x = torch.tensor([-1.0, 1.0, 1.0])[None, :, None, None]

    def partner_warp(b: Batch) -> tuple[torch.Tensor, torch.Tensor]:
        rel = camera.relative_pose(b.world_to_camera, b.partner(b.world_to_camera))
        return camera.warp(b.partner(b.image), b.depth, b.K, b.partner(b.K), rel, depth_src=b.partner(b.depth))

    # Warping the mirrored partner gives the mirrored warp (same pixels valid, same values).
    w0, v0 = partner_warp(batch)
    w1, v1 = partner_warp(mirrored)
    assert bool(v0.any()) and torch.equal(v0.flip(-1), v1)
    torch.testing.assert_close(w1[v1.expand_as(w1)], w0.flip(-1)[v1.expand_as(w1)], atol=1e-4, rtol=0)
    # MVS normals: the mirrored ones, x negated.
    n0, ok0 = mvs_normals(batch)
    n1, ok1 = mvs_normals(mirrored)
    assert torch.equal(ok0.flip(-1), ok1)
    torch.testing.assert_close(n1[ok1.expand_as(n1)], (n0.flip(-1) * flip_x)[ok1.expand_as(n1)], atol=1e-5, rtol=0)
    # The lighting rotation between the views commutes with mirroring the SH (x-odd terms negated).
    x_odd = torch.tensor([1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, -1.0, 1.0], dtype=torch.float64)[:, None]
    light = torch.randn(9, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    R0 = camera.relative_pose(batch.partner(batch.world_to_camera), batch.world_to_camera)[:, :3, :3].double()
    R1 = camera.relative_pose(mirrored.partner(mirrored.world_to_camera), mirrored.world_to_camera)[:, :3, :3].double()
    for r0, r1 in zip(R0, R1):
        assert abs(float(torch.linalg.det(r1)) - 1.0) < 1e-5  # still a proper rotation
        torch.testing.assert_close(sh.rotation(r1, 2) @ (light * x_odd), (sh.rotation(r0, 2) @ light) * x_odd,
                                   atol=1e-5, rtol=0)
    # The sampler mirrors whole pairs, half of them, by its own seeded stream; the pairs do not change.
    aug = PairSampler(tiny_dataset, split="all", res=24, mirror=True)
    flips = [f for step in range(20) for f in aug.mirrored_pairs(2, step)]
    assert 0 < sum(flips) < len(flips) and plain.mirrored_pairs(2, 0) == [False, False]
    step = next(s for s in range(20) if aug.mirrored_pairs(2, s)[0])
    a, p = aug.batch(2, step), plain.batch(2, step)
    assert a.keys == p.keys and torch.equal(a.image[0], p.image[0].flip(-1)) and torch.equal(a.image[2], p.image[2].flip(-1))
    assert torch.equal(aug.batch(2, step).image, a.image)
    # Mirrored training runs and resumes like any other (the option is part of the run's identity).
    cfg = config(tiny_dataset, tmp_path / "m", tiny_prior, mirror=True)
    assert cfg.identity() != config(tiny_dataset, tmp_path / "m", tiny_prior).identity()
    assert math.isfinite(train(cfg)["train_seconds"])
    with pytest.raises(ValueError, match="mirror"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, mirror="yes")


def test_20_mirror_averaging_is_exactly_mirror_symmetric_and_travels_with_the_export(tiny_dataset: Path,
                                                                                     tiny_prior: Path,
                                                                                     tmp_path: Path) -> None:
    from learned.networks import mirror_averaged
    from learned.objectives import decompose_and_solve
    from learned.networks import load_inverse

    torch.manual_seed(0)
    net = InverseNet(4, 2).eval()
    image = PairSampler(tiny_dataset, split="all", res=24).batch(2, 0).image
    flip_x = torch.tensor([-1.0, 1.0, 1.0])[None, :, None, None]
    with torch.no_grad():
        plain, mean, of_mirror = net(image), mirror_averaged(net, image), mirror_averaged(net, image.flip(-1))
    # The averaged decomposition of the mirror image is the mirror image of the averaged one
    # (the plain network's is not: it has no reason to be symmetric).
    torch.testing.assert_close(of_mirror["albedo"], mean["albedo"].flip(-1), atol=1e-6, rtol=0)
    torch.testing.assert_close(of_mirror["shadow"], mean["shadow"].flip(-1), atol=1e-6, rtol=0)
    torch.testing.assert_close(of_mirror["normals"], mean["normals"].flip(-1) * flip_x, atol=1e-6, rtol=0)
    assert float((plain["albedo"] - mean["albedo"]).abs().max()) > 1e-4
    n = mean["normals"]
    assert torch.allclose(n.norm(dim=1), torch.ones(()), atol=1e-5) and bool((n[:, 2] > 0).all())
    # Chosen at export; the default export keeps single-pass inference; training never averages.
    run = tmp_path / "r"
    train(config(tiny_dataset, run, tiny_prior, steps=2, ckpt_every=2, val_every=2))
    side = ckpt.latest_checkpoint(run)
    ckpt.export_weights(side, tmp_path / "a.safetensors", "inverse")
    ckpt.export_weights(side, tmp_path / "m.safetensors", "inverse", extra={"mirror_average": "1"})
    single, averaged = load_inverse(tmp_path / "a.safetensors"), load_inverse(tmp_path / "m.safetensors")
    assert not single.mirror_average and averaged.mirror_average
    prior = LightingPrior.load(tiny_prior)
    sky = torch.zeros(image.shape[0], 1, 24, 24, dtype=torch.bool)
    with torch.no_grad():
        a = decompose_and_solve(averaged, image, sky, prior)
        b = decompose_and_solve(single, image, sky, prior, mirror_average=True)
        c = decompose_and_solve(averaged, image, sky, prior, mirror_average=False)
        d = decompose_and_solve(single, image, sky, prior)
    torch.testing.assert_close(a["lighting"], b["lighting"])
    torch.testing.assert_close(c["normals"], d["normals"])
    assert not torch.allclose(a["normals"], d["normals"])
    with pytest.raises(ValueError, match="mirror_average"):
        InverseNet(4, 2, mirror_average="yes")


def _truth_decomposer(root: Path):
    """A "network" that returns the ground truth of the photos of ``evaluate``'s order."""
    from learned.evaluate import load_ground_truth
    from synth.dataset import SynthDataset

    ds = SynthDataset(root, split="all", mode="full")
    queue = list(ds.items)

    def truth(image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        gts = [load_ground_truth(ds, it.scene, it.view, it.light, 24) for it in queue[:image.shape[0]]]
        del queue[:image.shape[0]]
        normals = torch.stack([g["normal"] for g in gts])
        facing = torch.tensor([0.0, 0.0, 1.0])[:, None, None]  # sky pixels: any unit normal
        normals = torch.where(normals.norm(dim=1, keepdim=True) > 0.5, normals, facing)
        return {"albedo": torch.stack([g["albedo"] for g in gts]), "normals": normals / normals.norm(dim=1, keepdim=True),
                "shadow": torch.stack([g["direct_shadow"] for g in gts]),
                "lighting": torch.stack([g["lighting"] for g in gts]).float()}

    return truth, queue


def test_21_a_perfect_decomposition_scores_zero_and_its_albedo_ladder_meets_the_reference(tiny_dataset: Path,
                                                                                         tiny_prior: Path) -> None:
    from learned.evaluate import evaluate

    truth, queue = _truth_decomposer(tiny_dataset)
    m = evaluate(truth, tiny_dataset, "all", 24, LightingPrior.load(tiny_prior), batch_size=3)
    assert not queue and m["albedo_si_mse"] < 1e-12 and m["normal_mae_deg"] < 0.05
    assert m["lighting_rel_err"] < 1e-6 and m["lighting_shading_err"] < 1e-6
    # Each rung of the ladder swaps in one more true layer; with all of them true (the network's
    # shadow is the true direct-light ratio here) every rung is the reference.
    for key in ("implied_albedo_si_mse", "implied_albedo_si_mse_true_lighting",
                "implied_albedo_si_mse_true_normals_lighting"):
        assert m[key] == pytest.approx(m["oracle_albedo_si_mse"], rel=1e-4), key
    assert m["oracle_albedo_si_mse"] < m["baseline_albedo_si_mse"]
    # The lighting steps fed the truth: each is an error in [0, 1), and both MAP steps (the shipped
    # one is the exposure-equivariant form) see more of the lighting than solve-then-project
    # (tiny set: 0.21 / 0.21 against 0.82).
    for key in ("oracle_lighting_shading_err", "oracle_map_lighting_shading_err",
                "oracle_map_relative_lighting_shading_err"):
        assert 0.0 <= m[key] < 1.0, key
    assert m["oracle_map_relative_lighting_shading_err"] < m["oracle_lighting_shading_err"]
    assert m["oracle_map_lighting_shading_err"] < m["oracle_lighting_shading_err"]


def test_22_per_photo_metrics_give_the_reported_means_scene_intervals_and_paired_differences(
        tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    from learned.evaluate import PER_IMAGE_METRICS, compare_decompositions, evaluate, scene_intervals

    prior = LightingPrior.load(tiny_prior)
    truth, _ = _truth_decomposer(tiny_dataset)
    m, per = evaluate(truth, tiny_dataset, "all", 24, prior, batch_size=3, return_per_image=True)
    assert per["scene"].size == m["images"] and len(set(per["scene"])) == 3  # 3 scenes x 2 views x 2 lightings
    for key in PER_IMAGE_METRICS:
        assert per[key].mean() == pytest.approx(m[key], rel=1e-12), key
        assert per[f"baseline_{key}"].mean() == pytest.approx(m[f"baseline_{key}"], rel=1e-12), key
    ci = scene_intervals(per)
    for key, c in ci.items():
        assert c["lo"] <= c["mean"] <= c["hi"] and c["scenes"] == 3, key
    # The camera-facing baseline's per-photo spread gives a proper interval around its mean.
    b = ci["baseline_normal_mae_deg"]
    assert b["lo"] < b["mean"] < b["hi"] and b["mean"] == pytest.approx(m["baseline_normal_mae_deg"])

    # The truth against itself: no difference, and an interval of zero width.
    truth2, _ = _truth_decomposer(tiny_dataset)
    _, again = evaluate(truth2, tiny_dataset, "all", 24, prior, batch_size=5, return_per_image=True)
    for key, d in compare_decompositions(per, again).items():
        assert d["diff"] == d["lo"] == d["hi"] == 0.0, key
    # The truth against a decomposition that is the truth with camera-facing normals: better
    # normals on every photo, so every scene resample is negative.
    truth3, _ = _truth_decomposer(tiny_dataset)

    def flat_normals(image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        out = truth3(image, sky)
        out["normals"] = torch.zeros_like(out["normals"])
        out["normals"][:, 2] = 1.0
        return out

    _, flat = evaluate(flat_normals, tiny_dataset, "all", 24, prior, batch_size=3, return_per_image=True)
    d = compare_decompositions(per, flat)["normal_mae_deg"]
    assert d["hi"] < 0 and d["diff"] == pytest.approx(-m["baseline_normal_mae_deg"], rel=1e-6)
    with pytest.raises(ValueError, match="different photos"):
        compare_decompositions(per, {k: v[:-1] for k, v in flat.items()})
    with pytest.raises(ValueError, match="scene"):
        scene_intervals({"normal_mae_deg": per["normal_mae_deg"]})

    # The command line: intervals always, a reference's metrics and the paired differences on request.
    from physrelight.cli import main

    weights = tmp_path / "w"
    torch.manual_seed(5)
    for net, kind in ((InverseNet(4, 2), "inverse"), (ShadowNet(4, 2), "shadow")):
        save_weights(net, weights / f"{kind}.safetensors", kind)
    shutil.copy(tiny_prior, weights / "lighting_prior.npz")
    out = tmp_path / "e.json"
    assert main(["train", "evaluate", "--data", str(tiny_dataset), "--weights", str(weights), "--threads", "1",
                 "--reference-weights", str(weights), "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    assert got["intervals"]["normal_mae_deg"]["mean"] == pytest.approx(got["normal_mae_deg"])
    assert got["reference"]["normal_mae_deg"] == got["normal_mae_deg"]
    assert all(v["diff"] == 0.0 for v in got["paired"].values())
    assert main(["train", "evaluate", "--data", str(tiny_dataset), "--weights", str(weights),
                 "--reference-weights", str(tmp_path / "missing")]) != 0


def test_23_a_metered_network_decomposes_a_photo_the_same_at_any_exposure(tiny_dataset: Path, tiny_prior: Path,
                                                                          tmp_path: Path) -> None:
    from learned.checkpoint import read_metadata
    from learned.networks import EXPOSURE_KEY, log_average_luminance, metered
    from learned.objectives import decompose_and_solve
    from learned.networks import load_inverse

    image = PairSampler(tiny_dataset, split="all", res=24).batch(2, 0).image
    # Scaling the linear tensor is a pure exposure change (the network takes any positive values).
    # Metering maps every photo to the key, and a scaled photo to the same photo.
    torch.testing.assert_close(log_average_luminance(metered(image)), torch.full((len(image),), EXPOSURE_KEY),
                               rtol=1e-5, atol=0)
    torch.testing.assert_close(metered(image / 8), metered(image), rtol=1e-5, atol=1e-7)
    assert bool(torch.isfinite(metered(torch.zeros(1, 3, 4, 4))).all())
    prior = LightingPrior.load(tiny_prior)
    sky = torch.zeros(len(image), 1, 24, 24, dtype=torch.bool)
    torch.manual_seed(0)
    net = InverseNet(4, 2, lighting_solve="map_relative", meter_exposure=True).eval()
    with torch.no_grad():
        a = decompose_and_solve(net, image, sky, prior)
        dark = decompose_and_solve(net, image / 8, sky, prior)
        bright = decompose_and_solve(net, image * 4, sky, prior)
        plain = decompose_and_solve(net, image / 8, sky, prior, meter_exposure=False)
    for other in (dark, bright):
        for k in ("albedo", "normals", "shadow"):
            torch.testing.assert_close(other[k], a[k], rtol=1e-4, atol=1e-5)
    # The lighting is solved against the photo as given, so it carries the exposure (map_relative
    # is exposure-equivariant).
    torch.testing.assert_close(dark["lighting"] * 8, a["lighting"], rtol=1e-3, atol=1e-5)
    torch.testing.assert_close(bright["lighting"] / 4, a["lighting"], rtol=1e-3, atol=1e-5)
    # Without metering the network sees the darker photo and answers differently.
    assert float((plain["normals"] - a["normals"]).abs().max()) > 1e-3
    # Chosen at export and read back; training never meters.
    path = save_weights(net, tmp_path / "inverse.safetensors", "inverse", lighting_solve="map_relative",
                        meter_exposure="1")
    assert read_metadata(path)["meter_exposure"] == "1" and load_inverse(path).meter_exposure
    with pytest.raises(ValueError, match="meter_exposure"):
        InverseNet(4, 2, meter_exposure=1)
    with pytest.raises(ValueError, match="key"):
        metered(image, key=0.0)


def test_24_a_capped_evaluation_spreads_its_picks_from_first_to_last() -> None:
    """Evaluations cap photos / cases with :func:`learned.data.evenly_spread`: the first and last item
    always, evenly between, no repeats; all items (a copy) when the cap is absent or not below the count."""
    from learned.data import evenly_spread

    items = list(range(10))
    assert evenly_spread(items, 4) == [0, 3, 6, 9]
    assert evenly_spread(items, 2) == [0, 9]
    assert evenly_spread(items, 10) == items and evenly_spread(items, None) == items
    assert evenly_spread(items, 50) is not items
    picks = evenly_spread(list(range(1000)), 96)
    assert len(set(picks)) == 96 and picks[0] == 0 and picks[-1] == 999
    assert np.ptp(np.diff(picks)) <= 1  # even: gaps differ by at most one
    with pytest.raises(ValueError, match="n must be"):
        evenly_spread(items, 0)


def test_25_mvs_normals_taken_at_the_dataset_resolution_pool_to_the_training_one(tiny_dataset: Path) -> None:
    """``PairSampler(mvs_pooled=True)``: the normal term's MVS normals come from the dataset's own
    resolution, area-pooled (:func:`learned.data.pooled_mvs_normals`); on a plane the pooled normal is the
    plane's, a sub-pixel hole costs a pixel only when half of it is missing, and mirroring carries them."""
    from learned.data import _mirrored, mvs_normals, pooled_mvs_normals
    from physrelight import camera

    # A tilted plane n . X = c seen by a pinhole camera: every finite-difference normal is the same.
    size, f = 24, 30.0
    K = torch.tensor([[f, 0.0, size / 2], [0.0, f, size / 2], [0.0, 0.0, 1.0]])
    v, u = torch.meshgrid(torch.arange(size) + 0.5, torch.arange(size) + 0.5, indexing="ij")
    rays = torch.stack([(u - size / 2) / f, (v - size / 2) / f, torch.ones_like(u)])
    plane = torch.nn.functional.normalize(torch.tensor([0.3, -0.2, -1.0]), dim=0)
    depth = (-2.0 / (plane[:, None, None] * rays).sum(0))[None]
    full, ok_full = camera.normals_from_depth(depth[None], K[None], max_rel_jump=0.1)
    reference = full[0][:, ok_full[0, 0]].mean(1)
    pooled, ok = pooled_mvs_normals(depth, K, 12)
    assert pooled.shape == (3, 12, 12) and ok.shape == (1, 12, 12)
    assert int(ok.sum()) >= 100  # interior: all of it; the border loses what the stencil loses
    torch.testing.assert_close(pooled[:, ok[0]], reference[:, None].expand(3, int(ok.sum())), atol=1e-4, rtol=0)
    # At the dataset's resolution it is the depth's own normals, bit for bit.
    same, same_ok = pooled_mvs_normals(depth, K, size)
    assert torch.equal(same_ok, ok_full[0]) and torch.equal(same[:, same_ok[0]], full[0][:, ok_full[0, 0]])
    # A one-pixel hole column (dilated by the stencil) loses only the pooled pixels half-missing.
    holed = depth.clone()
    holed[..., 11] = 0.0
    _, ok_full_h = camera.normals_from_depth(holed[None], K[None], max_rel_jump=0.1)
    _, ok_h = pooled_mvs_normals(holed, K, 12)
    share = torch.nn.functional.avg_pool2d(ok_full_h[0].float()[None], 2)[0]
    assert torch.equal(ok_h, share >= 0.5) and int(ok_h.sum()) > int((share == 1).sum())
    with pytest.raises(ValueError, match="multiple of res"):
        pooled_mvs_normals(depth, K, 10)

    sampler = PairSampler(tiny_dataset, split="all", res=12, mvs_pooled=True, mirror=True)
    batch = sampler.batch(2, step=0)
    assert batch.mvs_normal.shape == (4, 3, 12, 12) and batch.mvs_valid.dtype == torch.bool
    norms = batch.mvs_normal.norm(dim=1, keepdim=True)
    assert bool(batch.mvs_valid.any()) and torch.allclose(norms[batch.mvs_valid], torch.ones(1), atol=1e-5)
    n, valid = mvs_normals(batch)
    assert n is batch.mvs_normal and torch.equal(valid, batch.mvs_valid & ~batch.sky)
    photo = sampler.photo(batch.keys[0])
    mirrored = _mirrored(photo)
    torch.testing.assert_close(mirrored["mvs_normal"][0], -photo["mvs_normal"][0].flip(-1))
    torch.testing.assert_close(mirrored["mvs_normal"][1:], photo["mvs_normal"][1:].flip(-1))
    assert torch.equal(mirrored["mvs_valid"], photo["mvs_valid"].flip(-1))
    with pytest.raises(ValueError, match="multiple of res"):
        PairSampler(tiny_dataset, split="all", res=10, mvs_pooled=True)
    with pytest.raises(ValueError, match="mvs_pooled"):
        TrainConfig(stage="inverse", data=str(tiny_dataset), out="x", mvs_pooled=1)


def test_26_a_set_with_twice_the_mvs_resolution_gives_native_photos_and_more_normal_targets(
        tiny_dataset: Path, tmp_path: Path) -> None:
    """``synth --mvs-scale 2``: the loader hands out the native photos, bit for bit, with depth at their
    size and intrinsics, and pooled MVS normals from the 2x depth that cover far more of the foreground
    than normals of native-resolution MVS depth, and point where the true normals do."""
    from learned.data import load_photo, pooled_mvs_normals
    from synth import writer
    from synth.dataset import SynthDataset, to_chw

    writer.write_dataset(tmp_path, writer.SynthConfig(**TINY, mvs_scale=2), progress=False)
    native = SynthDataset(tiny_dataset, split="all")
    fine = SynthDataset(tmp_path, split="all")
    truth = SynthDataset(tiny_dataset, split="all", mode="full")
    foreground = covered_native = covered_fine = 0
    errors = []
    for it in native.items:
        a = load_photo(native, it.scene, it.view, it.light, 24)
        b = load_photo(fine, it.scene, it.view, it.light, 24, mvs_pooled=True)
        assert torch.equal(a["image"], b["image"]) and torch.equal(a["K"], b["K"]) and torch.equal(a["sky"], b["sky"])
        assert b["depth"].shape == a["depth"].shape == (1, 24, 24)
        _, ok = pooled_mvs_normals(a["depth"], a["K"], 24)  # at the depth's own size: its own normals
        fg = ~a["sky"]
        foreground += int(fg.sum())
        covered_native += int((ok & fg).sum())
        valid = b["mvs_valid"] & fg
        covered_fine += int(valid.sum())
        n = to_chw(truth.load(it.scene, it.view, it.light, keys=("normal",))["normal"])
        cos = (b["mvs_normal"] * n).sum(0, keepdim=True).clamp(-1, 1)
        errors.append(torch.rad2deg(torch.acos(cos))[valid])
    # Measured: 4 % of the foreground against 38 %, median error 3.4 deg (24-px scenes are mostly edges).
    assert covered_fine > 3 * covered_native and covered_fine > 0.2 * foreground
    assert float(torch.cat(errors).median()) < 6.0
    PairSampler(tmp_path, split="all", res=16, mvs_pooled=True).batch(1, 0)  # 48 is a multiple of 16
    with pytest.raises(ValueError, match="multiple of res"):
        PairSampler(tmp_path, split="all", res=20, mvs_pooled=True)


def test_27_a_degraded_batch_shows_the_network_native_nuisances_and_the_losses_the_clean_photo(
        tiny_dataset: Path, tiny_prior: Path, tmp_path: Path) -> None:
    """``PairSampler(degrade=True)``: ``image`` stays the clean photo bit for bit and ``network_image`` is
    a pure function of ``(seed, step, rank)``; on a flat grey photo the residual of :func:`degrade_photo`
    without JPEG has no bias and the spread of the drawn noise plus 8-bit quantisation; the network sees
    the degraded copy while the lighting is solved against the clean photo."""
    from learned.data import degrade_photo
    from learned.objectives import decompose_and_solve, solve_projected
    from physrelight import colour

    clean = PairSampler(tiny_dataset, split="all", res=24, seed=3).batch(2, 5)
    aug = PairSampler(tiny_dataset, split="all", res=24, seed=3, degrade=True).batch(2, 5)
    again = PairSampler(tiny_dataset, split="all", res=24, seed=3, degrade=True, cache=False).batch(2, 5)
    assert clean.network_image is None and torch.equal(clean.image, aug.image)
    assert torch.equal(aug.network_image, again.network_image)
    assert aug.network_image.shape == aug.image.shape and not torch.equal(aug.network_image, aug.image)

    level = 0.2
    code = round(float(colour.to_ldr(np.float64(level))) * 255)
    lsb = float(colour.from_ldr(np.float64((code + 1) / 255)) - colour.from_ldr(np.float64(code / 255)))
    flat = torch.full((3, 64, 64), level)
    rng = np.random.default_rng(0)
    draws = [degrade_photo(flat, rng) for _ in range(40)]
    assert 10 <= sum(p.jpeg_quality is not None for _, p in draws) <= 30  # half the time, as synth draws it
    checked = 0
    for out, p in draws:
        assert out.dtype == torch.float32 and out.shape == flat.shape
        assert p.ev == 0.0 and p.wb_gains == (1.0, 1.0, 1.0) and p.curve == "srgb" and 0 <= p.noise_sigma <= 0.01
        r = (out - level).double()
        if p.jpeg_quality is None and p.noise_sigma > 0.004:  # noise above the code step: quantisation is additive
            expected = math.sqrt(p.noise_sigma ** 2 + lsb ** 2 / 12)
            assert abs(float(r.std()) / expected - 1) < 0.05, (p, float(r.std()), expected)
            assert abs(float(r.mean())) < 4 * expected / math.sqrt(r.numel()) + 0.02 * lsb
            checked += 1
    assert checked >= 5
    with pytest.raises(ValueError, match=r"\(3, H, W\)"):
        degrade_photo(torch.zeros(1, 8, 8), rng)

    torch.manual_seed(0)
    net = InverseNet(width=4, depth=2).eval()
    prior = LightingPrior.load(tiny_prior)
    fg = (~aug.sky).float()
    with torch.no_grad():
        dec = decompose_and_solve(net, aug.image, aug.sky, prior, mirror_average=False, meter_exposure=False,
                                  network_input=aug.network_image)
        seen = net(aug.network_image)
        on_clean = solve_projected(aug.image, seen["albedo"], seen["normals"], seen["shadow"], fg, prior)[1]
        on_degraded = solve_projected(aug.network_image, seen["albedo"], seen["normals"], seen["shadow"], fg, prior)[1]
    assert torch.equal(dec["albedo"], seen["albedo"]) and torch.equal(dec["normals"], seen["normals"])
    torch.testing.assert_close(dec["lighting"], on_clean)
    assert float((on_clean - on_degraded).abs().max()) > 1e-4  # the two solves do differ
    with pytest.raises(ValueError, match="network_input"):
        decompose_and_solve(net, aug.image, aug.sky, prior, network_input=aug.network_image[:1])

    # The run's flag reaches the sampler: the same step-0 network and pairs, another loss; and it is part of the
    # run's identity (a resume cannot switch it).
    for flag in (False, True):
        train(config(tiny_dataset, tmp_path / f"d{flag}", tiny_prior, steps=1, ckpt_every=1, degrade=flag))
    first = [float(rows(tmp_path / f"d{flag}" / "train.csv")[0]["total"]) for flag in (False, True)]
    assert first[0] != first[1]
    with pytest.raises(ValueError, match="another configuration"):
        train(config(tiny_dataset, tmp_path / "dTrue", tiny_prior, steps=2, ckpt_every=1, degrade=False))


def test_28_an_averaged_export_is_the_mean_of_the_checkpoints_weights(tiny_dataset: Path, tiny_prior: Path,
                                                                      tmp_path: Path) -> None:
    from safetensors.torch import load_file

    from learned.networks import load_inverse
    from physrelight.cli import main

    run = tmp_path / "inv"
    train(config(tiny_dataset, run, tiny_prior, steps=4, ckpt_every=1, val_every=4))
    sides = ckpt.checkpoints_between(run, 2, 4)
    assert [s.name for s in sides] == ["step_0000002.json", "step_0000003.json", "step_0000004.json"]
    a = ckpt.export_weights(sides[-1], tmp_path / "a.safetensors", "inverse", average=sides)
    b = ckpt.export_weights(sides[-1], tmp_path / "b.safetensors", "inverse", average=sides)
    assert a.read_bytes() == b.read_bytes()  # the same checkpoints, the same bytes
    averaged, meta = ckpt.load_weights(a)
    assert meta["average_steps"] == "2,3,4" and meta["step"] == "4"
    raw = [load_file(str(s.with_suffix(".safetensors"))) for s in sides]
    assert averaged.keys() == {k[len("model."):] for k in raw[0] if k.startswith("model.")}
    moved = 0
    for name, value in averaged.items():
        per = [r["model." + name].double() for r in raw]
        torch.testing.assert_close(value.double(), sum(per) / 3, rtol=0, atol=1e-7)
        moved += int(not torch.equal(per[0], per[-1]))
    assert moved > 0  # training changed the weights, so the mean is not any one checkpoint
    # The mean of one checkpoint taken twice is that checkpoint.
    single = ckpt.load_weights(ckpt.export_weights(sides[-1], tmp_path / "s.safetensors", "inverse"))[0]
    twice = ckpt.load_weights(ckpt.export_weights(sides[-1], tmp_path / "t.safetensors", "inverse",
                                                  average=[sides[-1], sides[-1]]))[0]
    assert all(torch.equal(single[k], twice[k]) for k in single)
    assert load_inverse(a).width == TINY_NET["width"]
    with pytest.raises(ValueError, match="averaging needs two or more"):
        ckpt.checkpoints_between(run, 4, 9)
    with pytest.raises(ValueError, match="must be the last"):
        ckpt.export_weights(sides[0], tmp_path / "c.safetensors", "inverse", average=sides)
    # The command line: --inverse-average FIRST:LAST gives the same file; bad ranges are refused in one line.
    args = ["train", "export", "--inverse", str(run), "--dest", str(tmp_path / "cli")]
    assert main(args + ["--inverse-average", "2:4"]) == 0
    assert (tmp_path / "cli" / "inverse.safetensors").read_bytes() == a.read_bytes()
    assert main(args + ["--inverse-average", "4:9"]) == 2
    assert main(args + ["--inverse-average", "2:4", "--inverse-step", "4"]) == 2
    with pytest.raises(SystemExit):
        main(args + ["--inverse-average", "4:2"])


def test_29_an_under_exposed_degradation_is_the_dark_photo_metered_back(tiny_dataset: Path, tiny_prior: Path,
                                                                        tmp_path: Path) -> None:
    """``degrade_photo(under_ev=E)``: half the time the photo is taken ``d ~ U(0, E)`` stops under and
    multiplied back by ``2**d``; the residual on a flat grey then has no bias and the spread
    ``2**d sqrt(sigma^2 + lsb(level 2**-d)^2 / 12)`` (noise and quantisation acting on the dark signal);
    ``under_ev=0`` is the call without it, byte for byte."""
    from learned.data import degrade_photo
    from physrelight import colour

    level = 0.2
    flat = torch.full((3, 64, 64), level)
    a, b = np.random.default_rng(4), np.random.default_rng(4)
    for _ in range(6):
        x, px = degrade_photo(flat, a)
        y, py = degrade_photo(flat, b, under_ev=0.0)
        assert torch.equal(x, y) and px == py

    def lsb_at(v: float) -> float:
        code = round(float(colour.to_ldr(np.float64(v))) * 255)
        return float(colour.from_ldr(np.float64((code + 1) / 255)) - colour.from_ldr(np.float64(code / 255)))

    rng = np.random.default_rng(1)
    draws = [degrade_photo(flat, rng, under_ev=3.0) for _ in range(80)]
    stops = [-p.ev for _, p in draws]
    assert all(0.0 <= d <= 3.0 for d in stops) and 25 <= sum(d == 0.0 for d in stops) <= 55  # half the time
    checked = 0
    for out, p in draws:
        d = -p.ev
        r = (out - level).double()
        if p.jpeg_quality is None and d > 1.0 and p.noise_sigma > 0.004:
            dark = level * 2.0**-d
            expected = 2.0**d * math.sqrt(p.noise_sigma ** 2 + lsb_at(dark) ** 2 / 12)
            assert abs(float(r.std()) / expected - 1) < 0.06, (p, float(r.std()), expected)
            assert abs(float(r.mean())) < 4 * expected / math.sqrt(r.numel()) + 0.02 * 2.0**d * lsb_at(dark)
            checked += 1
    assert checked >= 3
    bright = [float((o - level).std()) for o, p in draws if p.jpeg_quality is None and -p.ev == 0.0]
    darkest = [float((o - level).std()) for o, p in draws if p.jpeg_quality is None and -p.ev > 2.0]
    assert bright and darkest and min(darkest) > float(np.median(bright))  # the dark photos lose more
    for bad in (-1.0, 9.0, True):
        with pytest.raises(ValueError, match="under_ev"):
            degrade_photo(flat, rng, under_ev=bad)
    with pytest.raises(ValueError, match="needs degrade"):
        PairSampler(tiny_dataset, split="all", res=24, degrade_under_ev=2.0)
    with pytest.raises(ValueError, match="needs degrade"):
        config(tiny_dataset, tmp_path / "x", tiny_prior, degrade_under_ev=2.0)
    # Part of the run's identity.
    train(config(tiny_dataset, tmp_path / "u", tiny_prior, steps=1, ckpt_every=1, degrade=True, degrade_under_ev=3.0))
    with pytest.raises(ValueError, match="another configuration"):
        train(config(tiny_dataset, tmp_path / "u", tiny_prior, steps=2, ckpt_every=1, degrade=True))


def test_30_the_level_error_sees_the_scale_of_albedo_times_lighting_and_only_that(tiny_dataset: Path,
                                                                                  tiny_prior: Path) -> None:
    """``level_log2_ratio``: 0 for the truth and for the truth rescaled along the albedo/lighting
    ambiguity ``(k a, L / k)``, ``log2 k`` for ``(k a, L)``, blind to the SH beyond the DC; ``evaluate``
    reports it per photo (0 for a perfect decomposition, 1 stop for its albedo doubled)."""
    from learned.evaluate import compare_decompositions, evaluate, level_log2_ratio

    g = torch.Generator().manual_seed(0)
    albedo = torch.rand(3, 8, 8, generator=g, dtype=torch.float64) * 0.8 + 0.1
    light = torch.randn(9, 3, generator=g, dtype=torch.float64) * 0.1
    light[0] = torch.tensor([1.0, 0.9, 0.8])
    mask = torch.zeros(1, 8, 8, dtype=torch.bool)
    mask[:, 2:7, 1:6] = True
    assert level_log2_ratio(albedo, light, albedo, light, mask) == 0.0
    assert level_log2_ratio(3 * albedo, light / 3, albedo, light, mask) == pytest.approx(0.0, abs=1e-12)
    assert level_log2_ratio(3 * albedo, light, albedo, light, mask) == pytest.approx(math.log2(3), rel=1e-12)
    other = light.clone()
    other[1:] = torch.randn(8, 3, generator=g, dtype=torch.float64)  # only the DC sets the level
    assert level_log2_ratio(albedo, other, albedo, light, mask) == pytest.approx(0.0, abs=1e-12)
    outside = albedo.clone()
    outside[:, ~mask[0]] = 5.0  # pixels off the mask do not count
    assert level_log2_ratio(outside, light, albedo, light, mask) == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="empty mask"):
        level_log2_ratio(albedo, light, albedo, light, torch.zeros_like(mask))
    with pytest.raises(ValueError, match="positive"):
        level_log2_ratio(albedo, light, albedo, -light, mask)
    assert level_log2_ratio(albedo, -light, albedo, light, mask) == -10.0  # no level: clipped, not a crash
    assert level_log2_ratio(albedo * 2.0**12, light, albedo, light, mask) == 10.0

    prior = LightingPrior.load(tiny_prior)
    truth, _ = _truth_decomposer(tiny_dataset)
    m, per = evaluate(truth, tiny_dataset, "all", 24, prior, batch_size=3, return_per_image=True)
    assert m["level_err_stops"] < 1e-6 and m["baseline_level_err_stops"] > 0.1  # the truth in float32
    truth2, _ = _truth_decomposer(tiny_dataset)

    def doubled(image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        out = truth2(image, sky)
        return {**out, "albedo": 2 * out["albedo"]}  # the si metrics cannot see this; the level can

    m2, per2 = evaluate(doubled, tiny_dataset, "all", 24, prior, batch_size=3, return_per_image=True)
    assert m2["level_log2_ratio"] == pytest.approx(1.0, abs=1e-6) and m2["albedo_si_mse"] < 1e-12
    d = compare_decompositions(per2, per)["level_err_stops"]
    assert d["diff"] == pytest.approx(1.0, abs=1e-6) and d["lo"] == pytest.approx(1.0, abs=1e-6)
