"""Specification of where training computes: devices, precision, DataLoader workers, checkpoints that
move between devices, and the paper preset.

Runs on the CPU with the tiny dataset of the learned tests (3 scenes x 2 views x 2 lightings, 24 px)
and tiny networks. What needs a GPU (CUDA, NCCL, fp16) is checked by scripts/device_check.sh on the
device machine; here the same code paths run where the CPU can run them.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file, save_file

from learned import checkpoint as ckpt
from learned import runs
from learned.data import PairSampler
from learned.networks import InverseNet
from learned.train import TrainConfig, train

from .conftest import tiny_train_config

ROOT = Path(__file__).resolve().parents[2]
HAS_CUDA = torch.cuda.is_available()
HAS_MPS = bool(getattr(torch.backends, "mps", None) and torch.backends.mps.is_available())


def config(data: Path, out: Path, prior: Path, **kw) -> TrainConfig:
    return tiny_train_config(data, out, prior, **{"steps": 4, "val_images": 2, "ckpt_every": 2, **kw})


def totals(run: Path) -> list[str]:
    with (run / "train.csv").open() as f:
        return [r["total"] for r in csv.DictReader(f)]


def tensors(run: Path, step: int) -> dict[str, torch.Tensor]:
    return load_file(str(run / "checkpoints" / f"step_{step:07d}.safetensors"))


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from physrelight.cli import main; raise SystemExit(main())", *args],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)


def test_01_auto_is_the_best_device_present_and_a_missing_one_is_refused_by_name() -> None:
    want = "cuda" if HAS_CUDA else "mps" if HAS_MPS else "cpu"
    assert runs.resolve_device("auto").type == want
    assert runs.resolve_device("cpu") == torch.device("cpu")
    if not HAS_CUDA:
        with pytest.raises(ValueError, match="CUDA is not available"):
            runs.resolve_device("cuda")
    if not HAS_MPS:
        with pytest.raises(ValueError, match="MPS"):
            runs.resolve_device("mps")
    with pytest.raises(ValueError, match="device must be one of"):
        runs.resolve_device("tpu")
    with pytest.raises(ValueError, match="precision must be one of"):
        runs.check_compute(torch.device("cpu"), "fp8")
    runs.check_compute(torch.device("cpu"), "fp32")


def test_02_the_command_line_refuses_an_impossible_combination_in_one_line_before_writing(
        tiny_dataset: Path, tmp_path: Path) -> None:
    bad = [("--device", "cuda")] if not HAS_CUDA else []
    bad += [("--device", "mps", "--precision", "fp16")] if not HAS_MPS else []
    for flags in bad:
        out = tmp_path / "run"
        proc = cli("train", "inverse", "--data", str(tiny_dataset), "--out", str(out), *flags, "--quiet")
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("physrelight: error:"), proc.stderr
        assert "Traceback" not in proc.stderr and not out.exists()  # nothing half-written
    proc = cli("train", "renderer", "--data", str(tiny_dataset), "--out", str(tmp_path / "rn"), "--workers", "-1")
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "workers" in proc.stderr
    with pytest.raises(ValueError, match="workers"):
        config(tiny_dataset, tmp_path / "w", tmp_path / "p.npz", workers=-2)
    with pytest.raises(ValueError, match="precision"):
        config(tiny_dataset, tmp_path / "w", tmp_path / "p.npz", precision="half")


def test_03_worker_processes_hand_out_the_batches_of_the_in_process_path(tiny_dataset: Path) -> None:
    sampler = PairSampler(tiny_dataset, split="all", res=24, seed=3, mirror=True, degrade=True)
    here = list(runs.batch_stream(sampler, 2, 5, 9, rank=1, workers=0))
    there = list(runs.batch_stream(sampler, 2, 5, 9, rank=1, workers=2))
    assert len(here) == len(there) == 4
    for a, b in zip(here, there):
        assert a.keys == b.keys and all(isinstance(k, tuple) for k in b.keys)  # hashable, as the caches need
        for name in ("image", "depth", "sky", "K", "world_to_camera", "network_image"):
            assert torch.equal(getattr(a, name), getattr(b, name)), name
    again = sampler.batch(2, 7, 1)  # step 7 of rank 1 = the third item
    assert torch.equal(again.network_image, there[2].network_image)


def test_04_a_run_with_workers_is_the_run_without_them_bit_for_bit(tiny_dataset: Path, tiny_prior: Path,
                                                                  tmp_path: Path) -> None:
    train(config(tiny_dataset, tmp_path / "w0", tiny_prior, mirror=True))
    train(config(tiny_dataset, tmp_path / "w2", tiny_prior, mirror=True, workers=2))
    assert totals(tmp_path / "w0") == totals(tmp_path / "w2")
    a, b = tensors(tmp_path / "w0", 4), tensors(tmp_path / "w2", 4)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)  # model, Adam, RNG
    # Workers are where a run computes, not what it is: a resume may change them.
    train(config(tiny_dataset, tmp_path / "w2", tiny_prior, mirror=True, workers=0, steps=6))
    assert len(totals(tmp_path / "w2")) == 6


def test_05_the_explicit_cpu_fp32_run_is_the_default_run_bit_for_bit(tiny_dataset: Path, tiny_prior: Path,
                                                                     tmp_path: Path) -> None:
    if HAS_CUDA or HAS_MPS:
        pytest.skip("auto picks an accelerator here")
    train(config(tiny_dataset, tmp_path / "auto", tiny_prior))
    train(config(tiny_dataset, tmp_path / "cpu", tiny_prior, device="cpu", precision="fp32"))
    assert totals(tmp_path / "auto") == totals(tmp_path / "cpu")
    a, b = tensors(tmp_path / "auto", 4), tensors(tmp_path / "cpu", 4)
    assert all(torch.equal(a[k], b[k]) for k in a)
    cfg = json.loads((tmp_path / "cpu" / "config.json").read_text())
    assert (cfg["device"], cfg["precision"], cfg["device_used"]) == ("cpu", "fp32", "cpu")


def test_06_bf16_autocast_runs_the_network_in_bf16_and_hands_float32_to_the_losses(tiny_dataset: Path,
                                                                                  tiny_prior: Path,
                                                                                  tmp_path: Path) -> None:
    cpu = torch.device("cpu")
    try:
        runs.check_compute(cpu, "bf16")
    except ValueError:
        pytest.skip("this torch has no bf16 autocast on the CPU")
    net = InverseNet(4, 2, "map")
    seen: list[torch.dtype] = []
    hook = net.unet.head.register_forward_hook(lambda m, i, o: seen.append(o.dtype))
    wrapped = runs.autocast(net, cpu, "bf16")
    out = wrapped(torch.rand(2, 3, 16, 16))
    hook.remove()
    assert seen == [torch.bfloat16]  # the convolutions ran in bf16...
    assert all(v.dtype == torch.float32 for v in out.values())  # ...the losses read float32
    assert wrapped.module is net and wrapped.lighting_solve == "map"  # read as through DDP
    assert runs.autocast(net, cpu, "fp32") is net  # fp32: the plain network, the plain code path

    # A bf16 run trains with finite losses that differ from fp32 (it did run in bf16) and resumes bit-identically.
    train(config(tiny_dataset, tmp_path / "bf", tiny_prior, precision="bf16", steps=4))
    train(config(tiny_dataset, tmp_path / "fp", tiny_prior, steps=4))
    bf = [float(v) for v in totals(tmp_path / "bf")]
    assert all(math.isfinite(v) for v in bf) and bf != [float(v) for v in totals(tmp_path / "fp")]
    assert abs(bf[0] - float(totals(tmp_path / "fp")[0])) < 0.05 * abs(bf[0])  # same first batch, same weights
    train(config(tiny_dataset, tmp_path / "bf2", tiny_prior, precision="bf16", steps=2))
    train(config(tiny_dataset, tmp_path / "bf2", tiny_prior, precision="bf16", steps=4))
    assert totals(tmp_path / "bf2") == totals(tmp_path / "bf")
    a, b = tensors(tmp_path / "bf", 4), tensors(tmp_path / "bf2", 4)
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_07_a_checkpoint_saved_under_another_device_and_precision_resumes_here(tiny_dataset: Path,
                                                                                tiny_prior: Path,
                                                                                tmp_path: Path) -> None:
    """A run saved on a GPU (device, precision and a CUDA RNG state in its checkpoint) continues on the CPU
    with the numbers of an uninterrupted CPU run: the GPU's tags are no part of the run's identity and its
    RNG state is ignored where there is no GPU."""
    straight = tmp_path / "straight"
    train(config(tiny_dataset, straight, tiny_prior, steps=4))
    moved = tmp_path / "moved"
    train(config(tiny_dataset, moved, tiny_prior, steps=2))
    side = moved / "checkpoints" / "step_0000002.json"
    meta = json.loads(side.read_text())
    meta["config"].update(device="cuda", precision="bf16", workers=4)
    meta["device_used"] = "cuda:0"
    side.write_text(json.dumps(meta))
    t = load_file(str(side.with_suffix(".safetensors")))
    t["rng.cuda"] = torch.zeros(16, dtype=torch.uint8)  # a CUDA generator's state, as a GPU run saves it
    save_file(t, str(side.with_suffix(".safetensors")))
    train(config(tiny_dataset, moved, tiny_prior, steps=4))
    assert totals(moved) == totals(straight)
    a, b = tensors(straight, 4), tensors(moved, 4)
    assert all(torch.equal(a[k], b[k]) for k in a)
    # Another run's identity (here: the learning rate) is still refused.
    with pytest.raises(ValueError, match="another configuration"):
        train(config(tiny_dataset, moved, tiny_prior, steps=6, lr=1e-3))


def test_08_optimizer_state_lands_on_the_device_of_the_model_it_is_loaded_into(tiny_dataset: Path,
                                                                              tiny_prior: Path,
                                                                              tmp_path: Path) -> None:
    train(config(tiny_dataset, tmp_path / "run", tiny_prior, steps=2))
    side = tmp_path / "run" / "checkpoints" / "step_0000002.json"
    stored = load_file(str(side.with_suffix(".safetensors")))
    assert all(v.device.type == "cpu" for v in stored.values())  # stored device-free
    # 'meta' stands in for an accelerator this machine lacks: a device other than the CPU.
    with torch.device("meta"):
        model = InverseNet(4, 2)
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    ckpt.load_checkpoint(side, None, opt, map_location="meta", restore_rng=False)  # (weights into meta: a no-op)
    state = opt.state_dict()["state"]
    assert len(state) == len(list(model.parameters()))
    for s in state.values():
        assert s["exp_avg"].device.type == "meta" and s["exp_avg_sq"].device.type == "meta"
        assert s["step"].device.type == "cpu"  # torch keeps a non-capturable Adam's step counter on the CPU
    # And back: the same checkpoint into a CPU model gives the stored moments exactly.
    cpu_model = InverseNet(4, 2)
    cpu_opt = torch.optim.Adam(cpu_model.parameters(), lr=3e-3)
    ckpt.load_checkpoint(side, cpu_model, cpu_opt, map_location="cpu", restore_rng=False)
    assert torch.equal(cpu_opt.state_dict()["state"][0]["exp_avg"], stored["optim.0.exp_avg"])


def test_09_an_fp16_loss_scaler_travels_in_the_checkpoint(tmp_path: Path) -> None:
    model = torch.nn.Linear(3, 2)
    opt = torch.optim.Adam(model.parameters())
    model(torch.ones(1, 3)).sum().backward()
    opt.step()
    saved = torch.amp.GradScaler("cpu", init_scale=1024.0, growth_interval=7)
    side = ckpt.save_checkpoint(tmp_path, 1, model, opt, {}, scalers={"": saved})
    assert json.loads(side.read_text())["grad_scaler"][""]["scale"] == 1024.0
    fresh = torch.amp.GradScaler("cpu")
    ckpt.load_checkpoint(side, model, opt, scalers={"": fresh}, restore_rng=False)
    assert fresh.state_dict() == saved.state_dict()
    # A checkpoint without a scaler (a fp32 or bf16 run) leaves a scaler as it was.
    side2 = ckpt.save_checkpoint(tmp_path, 2, model, opt, {})
    other = torch.amp.GradScaler("cpu", init_scale=8.0)
    ckpt.load_checkpoint(side2, model, opt, scalers={"": other}, restore_rng=False)
    assert other.state_dict()["scale"] == 8.0


def _parse(*argv: str) -> argparse.Namespace:
    from learned import cli as lcli

    parser = argparse.ArgumentParser()
    lcli.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["train", *argv])


def test_10_the_paper_preset_trains_at_200_px_and_explicit_flags_override_it(tiny_dataset: Path) -> None:
    from learned.cli import PRESETS, _compute_fields

    assert PRESETS["paper"] == {"res": 200}
    for stage in ("inverse", "renderer"):
        base = ["--data", str(tiny_dataset), "--out", "x"]
        cases = {(): 64, ("--preset", "paper"): 200, ("--preset", "paper", "--res", "64"): 64,
                 ("--res", "96"): 96, ("--res", "128", "--preset", "paper"): 128}
        for flags, res in cases.items():
            args = _parse(stage, *base, *flags)
            fields = _compute_fields(args)
            assert args.res == res, (stage, flags)
            assert fields == {"device": "auto", "precision": "fp32", "workers": 0}
    args = _parse("inverse", "--data", "d", "--out", "x", "--device", "cpu", "--precision", "bf16", "--workers", "3")
    assert _compute_fields(args) == {"device": "cpu", "precision": "bf16", "workers": 3}


@pytest.mark.parametrize("precision", ["bf16", "fp16"])
def test_11_the_renderer_trains_in_reduced_precision_with_workers_and_resumes(precision: str, tiny_dataset: Path,
                                                                              tiny_prior: Path, tmp_path: Path) -> None:
    try:
        runs.check_compute(torch.device("cpu"), precision)
    except ValueError:
        pytest.skip(f"this torch has no {precision} autocast on the CPU")
    from learned.train_renderer import RendererConfig, train_renderer

    def cfg(out: Path, steps: int, **kw) -> RendererConfig:
        base = dict(data=str(tiny_dataset), out=str(out), prior=str(tiny_prior), train_split="all", val_split="all",
                    width=4, depth=2, d_width=4, res=24, batch=1, steps=steps, phase1_steps=1, val_every=1000,
                    val_images=2, ckpt_every=1, log_every=1, threads=1, progress=False, precision=precision)
        base.update(kw)
        return RendererConfig(**base)

    train_renderer(cfg(tmp_path / "a", 3, workers=2))  # phase 1, then phase 2 (GAN, cycle) under autocast
    train_renderer(cfg(tmp_path / "b", 2))
    train_renderer(cfg(tmp_path / "b", 3))
    ta, tb = totals(tmp_path / "a"), totals(tmp_path / "b")
    assert ta == tb and all(math.isfinite(float(v)) for v in ta)
    a, b = tensors(tmp_path / "a", 3), tensors(tmp_path / "b", 3)
    assert all(torch.equal(a[k], b[k]) for k in a)
    side = json.loads((tmp_path / "b" / "checkpoints" / "step_0000003.json").read_text())
    assert set(side.get("grad_scaler", {})) == ({"g", "d"} if precision == "fp16" else set())  # one per optimizer


def test_12_fp16_scales_the_loss_and_its_scaler_resumes_with_the_run(tiny_dataset: Path, tiny_prior: Path,
                                                                     tmp_path: Path) -> None:
    """Where this torch runs fp16 autocast and a loss scaler on the CPU, the CUDA fp16 code path runs here:
    scaled backward, unscaled clip, scaler step and update, the scaler's state in each checkpoint."""
    try:
        runs.check_compute(torch.device("cpu"), "fp16")
    except ValueError:
        pytest.skip("this torch has no fp16 autocast or loss scaler on the CPU")
    train(config(tiny_dataset, tmp_path / "a", tiny_prior, precision="fp16", steps=4))
    side = json.loads((tmp_path / "a" / "checkpoints" / "step_0000004.json").read_text())
    # The scaler is in the loop: fp16 gradients of a loss ~50 scaled by 2**16 overflow, those steps are skipped
    # and the scale backs off by halves (a power of two below the initial 65536).
    scale = side["grad_scaler"][""]["scale"]
    assert scale < 65536.0 and math.log2(scale).is_integer()
    assert all(math.isfinite(float(v)) for v in totals(tmp_path / "a"))
    train(config(tiny_dataset, tmp_path / "b", tiny_prior, precision="fp16", steps=2))
    train(config(tiny_dataset, tmp_path / "b", tiny_prior, precision="fp16", steps=4))
    assert totals(tmp_path / "a") == totals(tmp_path / "b")
    assert json.loads((tmp_path / "b" / "checkpoints" / "step_0000004.json").read_text())["grad_scaler"] == \
        side["grad_scaler"]
    a, b = tensors(tmp_path / "a", 4), tensors(tmp_path / "b", 4)
    assert all(torch.equal(a[k], b[k]) for k in a)
