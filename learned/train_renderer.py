"""Training of the neural renderer: ``physrelight train renderer --data DIR --out RUN``.

The inverse network and ShadowNet are frozen (default: the shipped weights); the renderer
and a 2-scale PatchGAN discriminator train on photo pairs from the self-supervised loader
(:class:`learned.data.PairSampler`; no ground truth). Two phases as in the paper:
steps ``[0, phase1_steps)`` minimise self-reconstruction + cross-projection, later steps
add cycle consistency, the LSGAN and discriminator feature matching
(:mod:`learned.renderer_objectives`).

Like :mod:`learned.train` the loop is

* **seeded**: networks from ``torch.manual_seed(seed)``, batch ``t`` a pure function of
  ``(seed, t)``; the frozen decomposition of each photo is computed alone (batch of one)
  and cached, so it does not depend on which batch first needed it;
* **resumable to the same numbers**: generator + discriminator in one ``nn.ModuleDict``
  and both Adam states (``{"g", "d"}``) in safetensors checkpoints; re-running the same
  command continues bit-identically after a kill;
* **logged**: ``train.csv``, ``val.csv`` (relighting of held-out scenes against path
  tracing, :mod:`learned.relight_eval`: l1 / SSIM / PSNR / CIEDE2000 of the renderer and
  of the Lambertian SH baselines), TensorBoard in ``RUN/tb``, PNG panels, a progress bar;
* **on any device and precision** as :mod:`learned.train` (``device``, ``precision``: the
  networks under autocast, fp16 with one loss scaler per optimizer; ``workers``); validation
  runs on CPU copies of the networks.

``physrelight train export-renderer --run RUN`` writes the generator alone as
``learned/weights/renderer.safetensors`` (kind ``renderer``).
"""

from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from physrelight import io
from physrelight.lighting_prior import LightingPrior

from . import checkpoint as ckpt
from .data import Batch, PairSampler
from .discriminators import MultiscaleDiscriminator
from .lighting import WEIGHTS_DIR, load_prior

from .networks import count_parameters, load_inverse, load_shadow
from .neural_renderer import BASES, NeuralRenderer
from .objectives import decompose_and_solve
from .relight_eval import evaluate_relight, load_case, relight_cases
from .relighter import Relighter
from .renderer_objectives import RendererWeights, discriminator_loss, renderer_losses
from . import runs
from .runs import RunConfig, RunLogs, display

__all__ = ["DecompositionCache", "RendererConfig", "export_renderer", "train_renderer"]


@dataclass
class RendererConfig(RunConfig):
    """Everything that determines a renderer run (recorded in every checkpoint)."""

    data: str
    out: str
    inverse: str | None = None
    shadow: str | None = None
    prior: str | None = None
    val_data: str | None = None
    val_split: str = "val"
    train_split: str = "train"
    width: int = 12
    depth: int = 3
    d_width: int = 16
    res: int = 64
    batch: int = 4
    steps: int = 3000
    phase1_steps: int = 2000
    cross_scale: int = 4
    cross_match_scale: bool = True
    additive: bool = True
    base: str = "lambertian"
    lr: float = 5e-4
    lr_d: float = 2e-4
    seed: int = 0
    val_every: int = 500
    val_images: int = 96
    ckpt_every: int = 250
    log_every: int = 10
    threads: int = 1
    weights: dict[str, float] = field(default_factory=lambda: RendererWeights().as_dict())
    progress: bool = True
    device: str = "auto"  # auto | cpu | cuda | mps (learned.runs.resolve_device)
    precision: str = "fp32"  # fp32 | bf16 | fp16 (learned.runs.autocast)
    workers: int = 0  # DataLoader processes making the batches (0: in this process)

    def __post_init__(self) -> None:
        self.check_common(("width", "depth", "d_width", "res", "batch", "steps", "cross_scale", "val_every",
                           "val_images", "ckpt_every", "log_every", "threads"), ("lr", "lr_d"),
                          RendererWeights().as_dict())
        self.check_compute_fields()
        if self.base not in BASES:
            raise ValueError(f"base must be one of {BASES}, got {self.base!r}")
        if isinstance(self.phase1_steps, bool) or not isinstance(self.phase1_steps, int) or self.phase1_steps < 0:
            raise ValueError(f"phase1_steps must be a non-negative integer, got {self.phase1_steps!r}")


class DecompositionCache:
    """The frozen networks' view of each training photo, computed once, alone (batch of one).

    Per photo: ``albedo``, ``normals``, ``shadow`` ``(C, H, W)``, ``lighting`` ``(9, 3)`` and
    ``self_shadow`` (ShadowNet on the photo's own lighting). About 130 kB a photo at 64 px.
    """

    def __init__(self, inverse: nn.Module, shadow_net: nn.Module, prior, relighter: Relighter | None = None) -> None:
        # With ``relighter``, each photo is decomposed as the Relighter does at inference
        # (:meth:`Relighter.decompose_linear`: its source-lighting estimate, the top rows repaired),
        # so a quotient-based renderer trains on the quotient images it will be given.
        self.inverse, self.shadow_net, self.prior, self.relighter = inverse, shadow_net, prior, relighter
        self._cache: dict[tuple[str, int, int], dict[str, torch.Tensor]] = {}

    @torch.no_grad()
    def get(self, batch: Batch) -> dict[str, torch.Tensor]:
        """Stacked decomposition of ``batch.image``: ``(2B, C, H, W)`` and lighting ``(2B, 9, 3)``."""
        items = []
        for j, key in enumerate(batch.keys):
            if key not in self._cache:
                if self.relighter is not None:
                    d = self.relighter.decompose_linear(batch.image[j:j + 1], batch.sky[j:j + 1])
                else:
                    d = decompose_and_solve(self.inverse, batch.image[j:j + 1], batch.sky[j:j + 1], self.prior)
                d["self_shadow"] = self.shadow_net(d["normals"], d["lighting"])
                self._cache[key] = {k: d[k][0] for k in ("albedo", "normals", "shadow", "lighting", "self_shadow")}
            items.append(self._cache[key])
        return {k: torch.stack([it[k] for it in items]) for k in items[0]}


def _frozen(net: nn.Module) -> nn.Module:
    for p in net.parameters():
        p.requires_grad_(False)
    return net.eval()


def build_models(config: RendererConfig) -> nn.ModuleDict:
    """Generator ``g`` (:class:`NeuralRenderer`) and discriminator ``d``, initialised from the seed."""
    torch.manual_seed(config.seed)
    return nn.ModuleDict({"g": NeuralRenderer(config.width, config.depth, config.additive, config.base),
                          "d": MultiscaleDiscriminator(3, config.d_width, layers=3, scales=2)})


def _on(net: nn.Module, device: torch.device) -> nn.Module:
    """``net`` on ``device``: itself on the CPU, else a moved copy (the CPU original stays for validation)."""
    return net if device.type == "cpu" else copy.deepcopy(net).to(device)


def train_renderer(config: RendererConfig) -> dict[str, Any]:
    """Run (or resume) a renderer training run; return the last validation metrics and timings.

    An unavailable device or precision is a ``ValueError`` before anything is written."""
    torch.set_num_threads(config.threads)
    device = runs.resolve_device(config.device)
    runs.check_compute(device, config.precision)
    run = Path(config.out)
    (run / "panels").mkdir(parents=True, exist_ok=True)
    prior = load_prior(config.prior)
    inverse = _frozen(load_inverse(config.inverse or WEIGHTS_DIR / "inverse.safetensors"))
    shadow_net = _frozen(load_shadow(config.shadow or WEIGHTS_DIR / "shadow.safetensors"))
    inverse_dev, shadow_dev = _on(inverse, device), _on(shadow_net, device)
    inverse_fwd = runs.autocast(inverse_dev, device, config.precision)
    shadow_fwd = runs.autocast(shadow_dev, device, config.precision)
    sampler = PairSampler(config.data, split=config.train_split, res=config.res, seed=config.seed)
    cache = DecompositionCache(inverse_fwd, shadow_fwd, prior,
                               Relighter(inverse_dev, shadow_dev, prior, config.res) if config.base == "quotient"
                               else None)
    weights = RendererWeights(**config.weights)

    models = build_models(config).to(device)  # initialised on the CPU from the seed, then moved
    g, d = models["g"], models["d"]
    g_fwd, d_fwd = runs.autocast(g, device, config.precision), runs.autocast(d, device, config.precision)
    opts = {"g": torch.optim.Adam(g.parameters(), lr=config.lr, betas=(0.5, 0.999)),
            "d": torch.optim.Adam(d.parameters(), lr=config.lr_d, betas=(0.5, 0.999))}
    scalers = ({k: runs.grad_scaler(device, config.precision) for k in opts} if config.precision == "fp16"
               else None)

    start, seconds = ckpt.resume(run, models, opts, config, scalers=scalers, map_location=device)
    if start >= config.steps:
        print(f"{run}: already at step {start} >= {config.steps}")
        return {"step": start, "train_seconds": seconds}

    logs = RunLogs(run, start, True)
    if start == 0:
        io.write_json(run / "config.json", {**asdict(config), "device_used": str(device),
                                            "parameters_g": count_parameters(g), "parameters_d": count_parameters(d)})
    from tqdm import tqdm

    bar = tqdm(total=config.steps, initial=start, disable=not config.progress, dynamic_ncols=True,
               desc="train renderer")
    val: dict[str, float] = {}
    models.train()
    batches = runs.batch_stream(sampler, config.batch, start, config.steps, 0, config.workers, device)
    for step in range(start, config.steps):
        t0 = time.perf_counter()
        phase = 1 if step < config.phase1_steps else 2
        batch = next(batches)
        dec = cache.get(batch)
        loss, terms, outputs = renderer_losses(g_fwd, d_fwd if phase == 2 else None, inverse_fwd, shadow_fwd, prior,
                                               batch, dec, weights, phase, config.cross_scale, config.cross_match_scale)
        opts["g"].zero_grad(set_to_none=True)
        gnorm = _backward_step(loss, g, opts["g"], scalers["g"] if scalers else None)
        extra = {}
        if phase == 2:
            opts["d"].zero_grad(set_to_none=True)  # drop what the generator's loss left on D
            d_loss = discriminator_loss(d_fwd, batch, outputs)
            _backward_step(d_loss, None, opts["d"], scalers["d"] if scalers else None)
            extra["d_loss"] = float(d_loss.detach())
        seconds += time.perf_counter() - t0
        done = step + 1
        bar.update(1)
        bar.set_postfix(loss=f"{float(loss.detach()):.4g}", phase=phase)
        if done % config.log_every == 0 or done == config.steps:
            logs.write("train.csv", done, {**{k: terms.get(k, math.nan) for k in RendererWeights().as_dict()},
                                           "total": float(loss.detach()), "d_loss": extra.get("d_loss", math.nan),
                                           "phase": float(phase), "grad_norm": float(gnorm), "seconds": seconds})
        if done % config.ckpt_every == 0 or done == config.steps:
            ckpt.save_checkpoint(run, done, models, opts, {"config": asdict(config), "train_seconds": seconds,
                                                           "device_used": str(device)},
                                 scalers=scalers, device=device)
        if done % config.val_every == 0 or done == config.steps:
            g_cpu = g if device.type == "cpu" else copy.deepcopy(g).cpu()  # validation runs on the CPU
            val = validate(g_cpu, inverse, shadow_net, prior, config, panel=run / "panels" / f"step_{done:07d}.png")
            logs.write("val.csv", done, val)
            models.train()
    batches.close()
    bar.close()
    logs.close()
    io.write_json(run / "summary.json", {"step": config.steps, "train_seconds": seconds,
                                         "parameters_g": count_parameters(g), "val": val})
    return {"step": config.steps, "train_seconds": seconds, "val": val}


def _backward_step(loss: torch.Tensor, clipped: nn.Module | None, opt: torch.optim.Optimizer,
                   scaler: "torch.amp.GradScaler | None") -> torch.Tensor | None:
    """Backward and one optimizer step, the gradients of ``clipped`` (if given) clipped to norm 1; with an
    fp16 ``scaler``, scaled and unscaled around the clip, the step skipped on overflow. Returns the norm."""
    gnorm = None
    if scaler is None:
        loss.backward()
        if clipped is not None:
            gnorm = torch.nn.utils.clip_grad_norm_(clipped.parameters(), 1.0)
        opt.step()
        return gnorm
    scaler.scale(loss).backward()
    if clipped is not None:
        scaler.unscale_(opt)
        gnorm = torch.nn.utils.clip_grad_norm_(clipped.parameters(), 1.0)
    scaler.step(opt)
    scaler.update()
    return gnorm


def validate(renderer: NeuralRenderer, inverse: nn.Module, shadow_net: nn.Module, prior: LightingPrior, config: RendererConfig,
             panel: Path | None = None) -> dict[str, float]:
    """Held-out relighting metrics (flat: ``<method>_<metric>``) and a panel
    (source | lambertian_sh | shadownet_lambertian | proposed | path-traced target)."""
    renderer.eval()
    pipe = Relighter(inverse, shadow_net, prior, config.res, renderer)
    root = config.val_data or config.data
    methods = ("proposed", "lambertian_sh", "shadownet_lambertian")
    if renderer.base == "quotient":
        methods += ("quotient",)
    result = evaluate_relight(pipe.relight_linear, root, config.val_split, config.res, config.val_images, methods)
    flat = {f"{m}_{k}": v for m in methods for k, v in result[m].items()}
    flat["cases"] = result["cases"]
    flat["saturated_cases"] = result["saturated_cases"]  # left out (target clipped on the whole foreground)
    if panel is not None:
        write_relight_panel(panel, pipe, root, config.val_split, config.res)
    return flat


def write_relight_panel(path: Path, pipe: Relighter, root: str, split: str, res: int, rows: int = 4) -> None:
    """PNG grid, one row per held-out case: source | lambertian_sh | shadownet_lambertian | proposed | target."""
    from synth.dataset import SynthDataset

    ds = SynthDataset(root, split=split, mode="full")
    cases = relight_cases(ds)
    picks = [cases[i] for i in np.linspace(0, len(cases) - 1, rows).round().astype(int)]
    tiles = []
    for c in picks:
        case = load_case(ds, *c, res=res)
        image, sky = case["image"][None], case["sky"][None]
        row = [display(image[0])]
        for m in ("lambertian_sh", "shadownet_lambertian", "proposed"):
            out = pipe.relight_linear(image, sky, case["target_sh"][None], case["source_sh"][None], m)
            row.append(display(out["relit"][0]))
        row.append(case["target_ldr"].permute(1, 2, 0).numpy())
        tiles.append(np.concatenate(row, 1))
    io.write_png(path, np.clip(np.concatenate(tiles, 0), 0, 1))


def export_renderer(sidecar: str | Path, dest: str | Path) -> Path:
    """Write the generator of a renderer checkpoint to ``dest`` (safetensors, weights only,
    ``kind = "renderer"``, ``width``, ``depth``, ``res``, ``step``, training seconds in the metadata)."""
    sidecar = Path(sidecar)
    meta = json.loads(sidecar.read_text())
    cfg = meta["config"]
    if "phase1_steps" not in cfg:
        raise ValueError(f"{str(sidecar)!r} is not a renderer checkpoint")
    return ckpt.export_weights(sidecar, dest, "renderer", submodule="g",
                               extra={"additive": "1" if cfg.get("additive", True) else "0",
                                      **({"base": cfg["base"]} if cfg.get("base", "lambertian") != "lambertian" else {})})
