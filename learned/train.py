"""Training loops of the first stage: the inverse network and ShadowNet.

``physrelight train inverse --data DIR --out RUN`` and ``physrelight train shadow --data DIR
--out RUN --inverse RUN_OR_WEIGHTS`` (see :mod:`learned.cli`). Both loops are

* **seeded**: the model is initialised from ``torch.manual_seed(seed)``; batch ``t`` of
  rank ``r`` is a pure function of ``(seed, t, r)`` (:class:`learned.data.PairSampler`);
* **resumable to the same numbers**: a checkpoint (model, Adam state, RNG state in
  safetensors + a JSON sidecar) every ``ckpt_every`` steps; restarting the same command
  loads the latest one, truncates ``train.csv`` to it and continues: the parameters,
  optimizer state and every later loss are bit-identical to an uninterrupted run
  (``tests/learned``);
* **logged**: ``train.csv`` (every ``log_every`` steps), ``val.csv`` (every ``val_every``
  steps, held-out scenes against ground truth: :mod:`learned.evaluate`), TensorBoard
  events in ``RUN/tb``, PNG panels of the layers in ``RUN/panels``, a progress bar;
* **distributed** when ``WORLD_SIZE`` is set (``torchrun --nproc_per_node 2 ...``):
  ``torch.distributed`` with NCCL on CUDA (each rank its own GPU, ``cuda:LOCAL_RANK``) and gloo
  on the CPU, DDP gradient averaging, each rank its own batches, rank 0 writes logs and checkpoints;
* **on any device** (``device``: auto, cpu, cuda, mps) and **precision** (``precision``: fp32;
  bf16 or fp16 autocast of the networks, fp16 with a loss scaler saved in the checkpoints), batches
  made in the process or by ``workers`` DataLoader processes (the same batches either way;
  :func:`learned.runs.batch_stream`). A checkpoint resumes on another device.

The self-supervised loader never hands out ground truth; ground truth is read only by
the validation (``mode="full"``) on the validation split (or ``--val-data``).
"""

from __future__ import annotations

import copy
import math
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from physrelight import image_model, io
from physrelight.collections import find_layout
from physrelight.lighting_prior import LightingPrior
from synth.dataset import SynthDataset

from . import checkpoint as ckpt
from .collection_sky import segmenter_sky_fn
from .data import PairSampler, check_under_ev, data_notes, open_training_data
from .evaluate import evaluate
from .lighting import load_prior

from .networks import LIGHTING_SOLVES, InverseNet, ShadowNet, count_parameters, load_inverse, load_network
from .objectives import LossWeights, decompose_and_solve, inverse_losses
from . import runs
from .runs import RunConfig, RunLogs, display

__all__ = ["MVS_STENCILS", "TrainConfig", "train", "write_panel"]

MVS_STENCILS = ("central", "one_sided")  # how the normal term reads the MVS-like depth

STAGES = ("inverse", "shadow")


@dataclass
class TrainConfig(RunConfig):
    """Everything that determines a run (recorded in every checkpoint)."""

    stage: str
    data: str
    out: str
    val_data: str | None = None
    val_split: str = "val"
    train_split: str = "train"
    width: int = 16
    depth: int = 3
    res: int = 64
    batch: int = 4
    steps: int = 2000
    lr: float = 1e-3
    seed: int = 0
    val_every: int = 250
    val_images: int = 96
    ckpt_every: int = 250
    log_every: int = 10
    threads: int = 2
    prior: str | None = None
    inverse: str | None = None
    init: str | None = None
    lighting_solve: str = "project"
    initial_shadow_logit: float = 3.0
    mvs_stencil: str = "central"
    mirror: bool = False  # left-right mirrored pairs (learned.data.mirror_view); off in runs before it existed
    mvs_pooled: bool = False  # MVS normals at the dataset's resolution, pooled (learned.data.pooled_mvs_normals)
    degrade: bool = False  # the network sees photos with camera nuisances put back (learned.data.degrade_photo)
    degrade_under_ev: float = 0.0  # and, half the time, up to this many stops under-exposed, metered back
    scenes: str | None = None  # "a,b": only these scenes of data (its split ignored); learned.data.open_training_data
    sky: str = "auto"  # a photo collection's photos without a mask: the shipped segmenter's sky ("auto") or none
    weights: dict[str, float] = field(default_factory=lambda: LossWeights().as_dict())
    progress: bool = True
    device: str = "auto"  # auto | cpu | cuda | mps (learned.runs.resolve_device)
    precision: str = "fp32"  # fp32 | bf16 | fp16 (autocast of the networks; learned.runs.autocast)
    workers: int = 0  # DataLoader processes making the batches (0: in this process)

    def __post_init__(self) -> None:
        # Runs recorded before a term existed ran without it (weight 0 = the default of any new term).
        self.weights = {**LossWeights().as_dict(), **self.weights}
        if self.stage not in STAGES:
            raise ValueError(f"stage must be one of {STAGES}, got {self.stage!r}")
        self.check_compute_fields()
        self.check_common(("width", "depth", "res", "batch", "steps", "val_every", "val_images", "ckpt_every",
                           "log_every", "threads"), ("lr",), LossWeights().as_dict())
        if self.stage == "shadow" and self.inverse is None:
            raise ValueError("the shadow stage needs --inverse (an inverse run folder or weights file)")
        v = self.initial_shadow_logit
        if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise ValueError(f"initial_shadow_logit must be a finite number, got {v!r}")
        if self.lighting_solve not in LIGHTING_SOLVES:
            raise ValueError(f"lighting_solve must be one of {LIGHTING_SOLVES}, got {self.lighting_solve!r}")
        if self.mvs_stencil not in MVS_STENCILS:
            raise ValueError(f"mvs_stencil must be one of {MVS_STENCILS}, got {self.mvs_stencil!r}")
        if self.init is not None and not Path(self.init).exists():
            raise ValueError(f"init {self.init!r} does not exist (a {self.stage} run folder or weights file)")
        if self.sky not in ("auto", "none"):
            raise ValueError(f"sky must be 'auto' or 'none', got {self.sky!r}")
        if not isinstance(self.mirror, bool):
            raise ValueError(f"mirror must be True or False, got {self.mirror!r}")
        if not isinstance(self.mvs_pooled, bool):
            raise ValueError(f"mvs_pooled must be True or False, got {self.mvs_pooled!r}")
        if not isinstance(self.degrade, bool):
            raise ValueError(f"degrade must be True or False, got {self.degrade!r}")
        check_under_ev(self.degrade_under_ev, "degrade_under_ev")
        if self.degrade_under_ev and not self.degrade:
            raise ValueError("degrade_under_ev needs degrade (--degrade-under-ev is one of --degrade's nuisances)")


# ------------------------------------------------------------------------- distributed


def _local_rank() -> int | None:
    """``LOCAL_RANK`` under torchrun (each rank's GPU), None in a plain process."""
    return int(os.environ["LOCAL_RANK"]) if "LOCAL_RANK" in os.environ else None


def _dist_setup(device: torch.device) -> tuple[int, int]:
    """Join torchrun's process group (NCCL for CUDA ranks, gloo on the CPU); ``(rank, world size)``."""
    ws = int(os.environ.get("WORLD_SIZE", "1"))
    if ws > 1 and not dist.is_initialized():
        if device.type == "cuda":
            torch.cuda.set_device(device)
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
    return (dist.get_rank(), dist.get_world_size()) if dist.is_initialized() else (0, 1)


def _barrier() -> None:
    if dist.is_initialized():
        dist.barrier()


def _mean_terms(terms: dict[str, float], world: int, device: torch.device = torch.device("cpu")) -> dict[str, float]:
    if world == 1:
        return terms
    keys = sorted(terms)
    t = torch.tensor([terms[k] for k in keys], dtype=torch.float64, device=device)  # NCCL reduces GPU tensors only
    dist.all_reduce(t)
    return {k: float(v) / world for k, v in zip(keys, t)}


def _rank_divergence(model: torch.nn.Module, world: int) -> float:
    """Largest difference of any parameter between a rank and the mean over ranks (0 = in sync)."""
    if world == 1:
        return 0.0
    flat = torch.cat([p.detach().reshape(-1).double() for p in model.parameters()])  # on the model's device
    mean = flat.clone()
    dist.all_reduce(mean)
    diff = (flat - mean / world).abs().max().reshape(1)
    dist.all_reduce(diff, op=dist.ReduceOp.MAX)
    return float(diff)


def write_panel(path: Path, image: torch.Tensor, out: dict[str, torch.Tensor], rows: int = 4) -> None:
    """PNG grid, one row per photo: photo | albedo | normals | shadow | shading | re-render."""
    tiles = []
    for j in range(min(rows, image.shape[0])):
        n = out["normals"][j]
        shading = image_model.shading(n[None], out["lighting"][j][None])[0]
        rerender = out["albedo"][j] * shading * out["shadow"][j]
        row = [display(image[j]), out["albedo"][j].permute(1, 2, 0).numpy() ** (1 / 2.2),
               (n.permute(1, 2, 0).numpy() * 0.5 + 0.5), np.repeat(out["shadow"][j].permute(1, 2, 0).numpy(), 3, -1),
               display(shading), display(rerender)]
        if "shadow_net" in out:
            row.append(np.repeat(out["shadow_net"][j].permute(1, 2, 0).numpy(), 3, -1))
        tiles.append(np.concatenate(row, 1))
    io.write_png(path, np.clip(np.concatenate(tiles, 0), 0, 1))


# ------------------------------------------------------------------------- the loop


def _warm_start(model: torch.nn.Module, config: TrainConfig) -> None:
    """Copy the weights of ``config.init`` (same stage, width and depth) into ``model``."""
    src = load_network(config.init, config.stage)
    theirs, ours = src.state_dict(), model.state_dict()
    bad = [k for k in ours if k not in theirs or theirs[k].shape != ours[k].shape]
    if bad or set(theirs) != set(ours):
        raise ValueError(f"init {config.init!r} does not match a {config.stage} network of width {config.width} "
                         f"and depth {config.depth} (mismatched: {sorted(bad or set(theirs) ^ set(ours))[:3]})")
    model.load_state_dict(theirs)


def train(config: TrainConfig) -> dict[str, Any]:
    """Run (or resume) a training run; return the last validation metrics and timings.

    Under ``torchrun`` the process group (NCCL on CUDA, gloo on the CPU) is created here and destroyed
    before returning: a group left to interpreter shutdown can abort a rank ("terminate called without
    an active exception") after all its work is done, which fails the whole launch. An unavailable
    device or precision is a ``ValueError`` before anything is written.
    """
    torch.set_num_threads(config.threads)
    device = runs.resolve_device(config.device, _local_rank())
    runs.check_compute(device, config.precision)
    owns_group = not dist.is_initialized()
    rank, world = _dist_setup(device)
    try:
        result = _train(config, rank, world, device)
        _barrier()  # no rank tears the group down while another still talks to it
        return result
    finally:
        if owns_group and dist.is_initialized():
            dist.destroy_process_group()


def _cpu_copy(model: torch.nn.Module) -> torch.nn.Module:
    """``model`` itself on the CPU, else a CPU copy of it (validation and panels run on the CPU)."""
    first = next(model.parameters(), None)
    if first is None or first.device.type == "cpu":
        return model
    return copy.deepcopy(model).cpu()


def _train(config: TrainConfig, rank: int, world: int, device: torch.device) -> dict[str, Any]:
    run = Path(config.out)
    # The data (synth set or photo collection) is opened and every file checked before the run folder exists.
    collection = find_layout(config.data) != "synth"  # its photos' sky: masks/, else the shipped segmenter's
    data = open_training_data(config.data, config.train_split, config.scenes,
                              segmenter_sky_fn() if collection and config.sky == "auto" else None)
    if rank == 0:
        (run / "panels").mkdir(parents=True, exist_ok=True)
        for line in data_notes(data):
            print(line, file=sys.stderr)
    _barrier()
    prior = load_prior(config.prior)
    sampler = PairSampler(config.data, split=config.train_split, res=config.res, seed=config.seed,
                          mirror=config.mirror, mvs_pooled=config.mvs_pooled, stencil=config.mvs_stencil,
                          degrade=config.degrade, degrade_under_ev=config.degrade_under_ev, data=data)
    # Validation reads ground truth: a photo collection has none, so without --val-data it is skipped.
    can_validate = config.val_data is not None or isinstance(data, SynthDataset)
    if rank == 0 and not can_validate:
        print(f"data: {config.data} has no ground truth and no --val-data was given: no validation", file=sys.stderr)
    weights = LossWeights(**config.weights)

    torch.manual_seed(config.seed)
    if config.stage == "inverse":
        model: torch.nn.Module = InverseNet(config.width, config.depth, config.lighting_solve,
                                            config.initial_shadow_logit)
        teacher = None
    else:
        model = ShadowNet(config.width, config.depth)
        teacher = load_inverse(config.inverse)
        for p in teacher.parameters():
            p.requires_grad_(False)
    if config.init is not None:
        _warm_start(model, config)
    # Initialised on the CPU from the seed, then moved: the same initial weights on every device.
    model.to(device)
    if teacher is not None:
        teacher.to(device)
    opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    scaler = runs.grad_scaler(device, config.precision)
    scalers = {"": scaler} if scaler is not None else None

    # A checkpoint of this run, if any, replaces the warm start (resume to the same numbers).
    start, seconds = ckpt.resume(run, model, opt, config, scalers=scalers, map_location=device)
    if start >= config.steps:
        if rank == 0:
            print(f"{run}: already at step {start} >= {config.steps}")
        return {"step": start, "train_seconds": seconds}

    if world > 1:
        net = torch.nn.parallel.DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda"
                                                        else None)
    else:
        net = model
    fwd = runs.autocast(net, device, config.precision)
    teacher_fwd = runs.autocast(teacher, device, config.precision) if teacher is not None else None
    logs = RunLogs(run, start, rank == 0)
    if rank == 0 and start == 0:
        io.write_json(run / "config.json", {**asdict(config), "world_size": world, "device_used": str(device),
                                            "parameters": count_parameters(model)})

    from tqdm import tqdm

    bar = tqdm(total=config.steps, initial=start, disable=not (config.progress and rank == 0), dynamic_ncols=True,
               desc=f"train {config.stage}")
    metrics: dict[str, float] = {}
    model.train()
    batches = runs.batch_stream(sampler, config.batch, start, config.steps, rank, config.workers, device)
    for step in range(start, config.steps):
        t0 = time.perf_counter()
        batch = next(batches)
        if config.stage == "inverse":
            loss, terms, _ = inverse_losses(fwd, batch, prior, weights, config.mvs_stencil)
        else:
            with torch.no_grad():
                dec = decompose_and_solve(teacher_fwd, batch.image, batch.sky, prior)
            pred = fwd(dec["normals"], dec["lighting"])
            fg = dec["foreground"]
            loss = ((pred - dec["shadow"]) ** 2 * fg).sum() / fg.sum().clamp_min(1.0)
            terms = {"shadow_mse": float(loss.detach())}
        opt.zero_grad(set_to_none=True)
        if scaler is None:
            loss.backward()
            gnorm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
        else:  # fp16: scaled backward, the clip on the true gradients, a step skipped on overflow
            scaler.scale(loss).backward()
            scaler.unscale_(opt)
            gnorm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            scaler.step(opt)
            scaler.update()
        seconds += time.perf_counter() - t0
        done = step + 1
        terms = _mean_terms({**terms, "total": float(loss.detach())}, world, device)
        bar.update(1)
        bar.set_postfix(loss=f"{terms['total']:.4g}")
        if done % config.log_every == 0 or done == config.steps:
            logs.write("train.csv", done, {**terms, "grad_norm": float(gnorm), "seconds": seconds})
        if done % config.ckpt_every == 0 or done == config.steps:
            if rank == 0:
                ckpt.save_checkpoint(run, done, model, opt, {"config": asdict(config), "train_seconds": seconds,
                                                             "world_size": world, "device_used": str(device)},
                                     scalers=scalers, device=device)
            _barrier()
        if can_validate and (done % config.val_every == 0 or done == config.steps):
            if rank == 0:  # on the CPU, in fp32: the same held-out figures whatever trained the weights
                metrics = validate(_cpu_copy(model) if config.stage == "inverse" else _cpu_copy(teacher), prior,
                                   config, shadow_net=_cpu_copy(model) if config.stage == "shadow" else None,
                                   panel=run / "panels" / f"step_{done:07d}.png")
                logs.write("val.csv", done, metrics)
                model.train()
            _barrier()
    batches.close()  # a DataLoader's workers stop here, not at garbage collection
    bar.close()
    logs.close()
    sync = _rank_divergence(model, world)
    if rank == 0:
        io.write_json(run / "summary.json", {"step": config.steps, "train_seconds": seconds, "world_size": world,
                                             "device_used": str(device), "precision": config.precision,
                                             "parameters": count_parameters(model), "val": metrics,
                                             "rank_param_max_diff": sync})
    return {"step": config.steps, "train_seconds": seconds, "val": metrics}


def validate(inverse: torch.nn.Module, prior: LightingPrior, config: TrainConfig, shadow_net: torch.nn.Module | None = None,
             panel: Path | None = None) -> dict[str, float]:
    """Metrics on held-out scenes (``val_data`` or the ``val`` split of ``data``) + a panel."""
    inverse.eval()
    if shadow_net is not None:
        shadow_net.eval()
    root = config.val_data or config.data

    def decompose(image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        return decompose_and_solve(inverse, image, sky, prior)

    shadow_fn = (lambda out: shadow_net(out["normals"], out["lighting"])) if shadow_net is not None else None
    metrics = evaluate(decompose, root, config.val_split, config.res, prior, config.val_images, shadow_fn)
    if panel is not None:
        from synth.dataset import SynthDataset

        from .data import load_photo

        ds = SynthDataset(root, split=config.val_split, mode="self_supervised")
        picks = ds.items[:: max(1, len(ds.items) // 4)][:4]
        photos = [load_photo(ds, it.scene, it.view, it.light, config.res) for it in picks]
        image = torch.stack([p["image"] for p in photos])
        with torch.no_grad():
            out = decompose(image, torch.stack([p["sky"] for p in photos]))
            if shadow_fn is not None:
                out["shadow_net"] = shadow_fn(out)
        write_panel(panel, image, out)
    return metrics
