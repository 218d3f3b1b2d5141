"""Checkpoints in ``safetensors`` (no pickle) with a JSON sidecar.

``RUN/checkpoints/step_XXXXXXX.safetensors`` holds the model (``model.*``), the Adam
state (``optim.<param index>.<exp_avg|exp_avg_sq|step>``; with several optimizers, as for a
GAN's generator and discriminator, ``optim.<name>.<param index>.<...>``) and the torch RNG state
(``rng.torch``; a run on a GPU adds that GPU's ``rng.cuda``); ``step_XXXXXXX.json`` holds the step,
the configuration, the optimizer's param groups, an fp16 run's loss-scaler state (``grad_scaler``)
and anything else JSON-able. The sidecar is written last and its presence
marks a checkpoint complete, so a run killed while saving resumes from the previous one.

Tensors are stored device-free (moved to the CPU on save) and land on the device of the model and
optimizer they are loaded into, so a run saved on CUDA resumes on the CPU and the reverse. The CUDA
RNG state is per device: restored when the checkpoint has one and the run resumes on a GPU, left
as seeded otherwise (the loops draw no random numbers on the GPU).

Shipped weights (:func:`export_weights`) are the model tensors only, with the network's
hyperparameters in the safetensors metadata.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from typing import Any

import torch
from safetensors import safe_open
from safetensors.torch import load_file
from safetensors.torch import save as serialize_tensors

from physrelight import io

__all__ = ["checkpoint_at", "checkpoints_between", "export_weights", "latest_checkpoint", "load_checkpoint", "load_weights",
           "read_metadata", "resume", "save_checkpoint"]

_NAME = re.compile(r"^step_(\d{7})\.json$")


def _atomic_save_tensors(tensors: dict[str, torch.Tensor], path: Path, metadata: dict[str, str] | None = None) -> None:
    """Write ``tensors`` (and string ``metadata``) as safetensors, atomically, byte-reproducibly, with the
    mode an ordinary ``open()`` gives (safetensors' own writer leaves 0600)."""
    data = serialize_tensors({k: v.detach().contiguous().cpu() for k, v in tensors.items()}, metadata=metadata)
    with io.atomic_path(path, ".safetensors") as tmp:
        tmp.write_bytes(io.canonical_safetensors(data))


def _atomic_write_json(data: Any, path: Path) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
    os.replace(tmp, path)


Optimizers = torch.optim.Optimizer | dict[str, torch.optim.Optimizer]
Scalers = dict[str, "torch.amp.GradScaler"]


def _named(optimizer: Optimizers) -> dict[str, torch.optim.Optimizer]:
    """One optimizer keeps the historical unprefixed layout (name ""); a dict is stored by name."""
    if isinstance(optimizer, torch.optim.Optimizer):
        return {"": optimizer}
    if not optimizer or any(not k or "." in k for k in optimizer):
        raise ValueError(f"optimizer names must be non-empty and free of dots, got {sorted(optimizer)}")
    return dict(optimizer)


def save_checkpoint(run: str | Path, step: int, model: torch.nn.Module, optimizer: Optimizers,
                    extra: dict[str, Any], scalers: Scalers | None = None,
                    device: torch.device | str | None = None) -> Path:
    """Write the checkpoint of ``step`` (optimizer steps done) into ``run/checkpoints``; return the sidecar path.

    ``optimizer`` is one optimizer or a dict ``{name: optimizer}`` (e.g. ``{"g": ..., "d": ...}``);
    ``scalers`` the fp16 loss scalers by the same names (None: no loss scaling); ``device`` where the
    run computes (a CUDA device adds its RNG state).
    """
    d = Path(run) / "checkpoints"
    d.mkdir(parents=True, exist_ok=True)
    tensors = {f"model.{k}": v for k, v in model.state_dict().items()}
    groups: dict[str, Any] = {}
    for name, o in _named(optimizer).items():
        opt = o.state_dict()
        prefix = f"optim.{name}." if name else "optim."
        for pid, state in opt["state"].items():
            for key, value in state.items():
                tensors[f"{prefix}{pid}.{key}"] = value if isinstance(value, torch.Tensor) else torch.tensor(value)
        groups[name] = opt["param_groups"]
    tensors["rng.torch"] = torch.get_rng_state()
    if device is not None and torch.device(device).type == "cuda":
        tensors["rng.cuda"] = torch.cuda.get_rng_state(torch.device(device))
    _atomic_save_tensors(tensors, d / f"step_{step:07d}.safetensors")
    sidecar = {"step": step, "param_groups": groups[""] if "" in groups else groups, **extra}
    if scalers:
        sidecar["grad_scaler"] = {name: sc.state_dict() for name, sc in scalers.items()}
    path = d / f"step_{step:07d}.json"
    _atomic_write_json(sidecar, path)
    return path


def checkpoint_at(run: str | Path, step: int | None = None) -> Path:
    """Sidecar of ``run``'s checkpoint at ``step`` (None: the latest); ``ValueError`` naming the run
    when there is none."""
    if step is None:
        side = latest_checkpoint(run)
        if side is None:
            raise ValueError(f"no checkpoint in {str(run)!r}")
        return side
    side = Path(run) / "checkpoints" / f"step_{step:07d}.json"
    if not (side.is_file() and side.with_suffix(".safetensors").is_file()):
        raise ValueError(f"no checkpoint of step {step} in {str(run)!r}")
    return side


def _complete_checkpoints(run: str | Path) -> list[tuple[int, Path]]:
    """``(step, sidecar)`` of every complete checkpoint in ``run`` (sidecar and tensors both there), in
    step order; empty when there is none."""
    d = Path(run) / "checkpoints"
    if not d.is_dir():
        return []
    found = ((_NAME.match(p.name), p) for p in d.iterdir())
    return sorted((int(m.group(1)), p) for m, p in found if m and p.with_suffix(".safetensors").is_file())


def latest_checkpoint(run: str | Path) -> Path | None:
    """Sidecar of the latest complete checkpoint in ``run``, or None."""
    found = _complete_checkpoints(run)
    return found[-1][1] if found else None


def checkpoints_between(run: str | Path, first: int, last: int) -> list[Path]:
    """Sidecars of ``run``'s complete checkpoints with ``first <= step <= last``, in step order;
    ``ValueError`` naming the run and the range when fewer than two are there (nothing to average)."""
    if first > last:
        raise ValueError(f"checkpoint range {first}:{last} is empty (first step after last)")
    found = [p for step, p in _complete_checkpoints(run) if first <= step <= last]
    if len(found) < 2:
        raise ValueError(f"{len(found)} checkpoint(s) of {str(run)!r} in steps {first}:{last}; averaging needs two or more")
    return found


def _averaged_tensors(sidecars: list[Path], head: str) -> dict[str, torch.Tensor]:
    """The uniform mean of the ``head``-prefixed tensors of several checkpoints of one network.

    Summed in float64 in the order given and cast back, so the same checkpoints give the same bytes.
    Integer tensors (e.g. BatchNorm's batch counter) have no meaningful mean and are refused, as are
    checkpoints whose tensor names or shapes differ."""
    total: dict[str, torch.Tensor] = {}
    dtypes: dict[str, torch.dtype] = {}
    for side in sidecars:
        tensors = {k: v for k, v in load_file(str(side.with_suffix(".safetensors"))).items() if k.startswith(head)}
        if not total:
            for k, v in tensors.items():
                if not v.is_floating_point():
                    raise ValueError(f"cannot average checkpoints: tensor {k!r} is {v.dtype}, not floating point")
                total[k], dtypes[k] = v.to(torch.float64), v.dtype
            continue
        if tensors.keys() != total.keys():
            raise ValueError(f"cannot average {side}: its tensors differ from {sidecars[0]}'s")
        for k, v in tensors.items():
            if v.shape != total[k].shape:
                raise ValueError(f"cannot average {side}: {k!r} has shape {tuple(v.shape)}, "
                                 f"{sidecars[0]} has {tuple(total[k].shape)}")
            total[k] += v.to(torch.float64)
    return {k: (v / len(sidecars)).to(dtypes[k]) for k, v in total.items()}


def load_checkpoint(sidecar: str | Path, model: torch.nn.Module | None = None,
                    optimizer: Optimizers | None = None, restore_rng: bool = True,
                    scalers: Scalers | None = None, map_location: torch.device | str | None = None) -> dict[str, Any]:
    """Load a checkpoint into ``model``/``optimizer`` (either may be None; ``optimizer`` as given
    to :func:`save_checkpoint`); return the sidecar dict.

    ``map_location``: the device the run resumes on (None: the CPU), where ``model`` and the
    optimizer's parameters already are; the tensors land there, and a CUDA RNG state is restored
    only on a CUDA device. ``scalers``: fp16 loss scalers by optimizer
    name, given the checkpoint's state when it has one (a run saved without fp16 leaves them fresh).
    """
    sidecar = Path(sidecar)
    if not sidecar.is_file():
        raise FileNotFoundError(f"no checkpoint sidecar at {str(sidecar)!r}")
    meta = json.loads(sidecar.read_text())
    tensors = load_file(str(sidecar.with_suffix(".safetensors")))
    rng = {k: tensors.pop(k) for k in [k for k in tensors if k.startswith("rng.")]}
    target = torch.device(map_location) if map_location is not None else torch.device("cpu")
    # Read on the CPU: load_state_dict copies into the parameters wherever they live, and the optimizer
    # moves its state to its parameters' device (its step counters stay on the CPU, as torch keeps them).
    if model is not None:
        model.load_state_dict({k[6:]: v for k, v in tensors.items() if k.startswith("model.")})
    if optimizer is not None:
        for name, o in _named(optimizer).items():
            prefix = f"optim.{name}." if name else "optim."
            state: dict[int, dict[str, torch.Tensor]] = {}
            for k, v in tensors.items():
                if k.startswith(prefix):
                    pid, key = k[len(prefix):].split(".", 1)
                    if not pid.isdigit():
                        continue  # another optimizer's entry
                    state.setdefault(int(pid), {})[key] = v
            groups = meta["param_groups"] if not name else meta["param_groups"].get(name)
            if groups is None:
                raise ValueError(f"checkpoint {str(sidecar)!r} has no optimizer named {name!r}")
            o.load_state_dict({"state": state, "param_groups": groups})
    if restore_rng and "rng.torch" in rng:
        torch.set_rng_state(rng["rng.torch"])
    if restore_rng and "rng.cuda" in rng and target.type == "cuda":
        torch.cuda.set_rng_state(rng["rng.cuda"], target)
    for name, sc in (scalers or {}).items():
        state = meta.get("grad_scaler", {}).get(name)
        if state:
            sc.load_state_dict(state)
    return meta


def export_weights(sidecar: str | Path, dest: str | Path, kind: str, submodule: str | None = None,
                   strip_submodule: bool = True, extra: dict[str, str] | None = None,
                   average: list[str | Path] | None = None) -> Path:
    """Write the model tensors of a checkpoint to ``dest`` (safetensors, weights only).

    The metadata records ``kind`` (e.g. "inverse", "shadow", "renderer"), ``width``,
    ``depth``, ``res``, ``step``, the training seconds, the configuration and ``extra``, so
    the matching loader rebuilds the network.

    Args:
        submodule: export only this child of the checkpointed ``ModuleDict`` (e.g. ``"g"``,
            a GAN's generator: the discriminator is for training only); None = the whole model.
        strip_submodule: drop the ``"<submodule>."`` prefix from the tensor names.
        average: export the uniform mean of these checkpoints' weights instead (stochastic weight
            averaging; ``sidecar`` must be the last of them and gives the metadata, which adds
            ``average_steps``). Only for networks without running statistics (ours use GroupNorm).
    """
    sidecar = Path(sidecar)
    meta = json.loads(sidecar.read_text())
    head = "model." if submodule is None else f"model.{submodule}."
    cut = len(head) if strip_submodule else len("model.")
    if average is None:
        tensors = {k[cut:]: v for k, v in load_file(str(sidecar.with_suffix(".safetensors"))).items()
                   if k.startswith(head)}
    else:
        sides = [Path(a) for a in average]
        if not sides or sides[-1] != sidecar:
            raise ValueError(f"average: {sidecar} must be the last of the averaged checkpoints")
        metas = [json.loads(a.read_text()) for a in sides]
        if len({json.dumps(m["config"], sort_keys=True) for m in metas}) > 1:
            raise ValueError("cannot average checkpoints of different configurations (another run or size)")
        tensors = {k[cut:]: v for k, v in _averaged_tensors(sides, head).items()}
        extra = {**(extra or {}), "average_steps": ",".join(str(m["step"]) for m in metas)}
    cfg = meta["config"]
    info = {"kind": kind, "width": str(cfg["width"]), "depth": str(cfg["depth"]), "res": str(cfg["res"]),
            "step": str(meta["step"]), "train_seconds": f"{meta.get('train_seconds', 0.0):.1f}",
            "config": json.dumps(cfg, sort_keys=True), **(extra or {})}
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    _atomic_save_tensors(tensors, dest, metadata=info)
    return dest


def read_metadata(path: str | Path) -> dict[str, str]:
    """The metadata of a file written by :func:`export_weights` (its header only, no tensors)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no weights at {str(path)!r}")
    with safe_open(str(path), framework="pt") as f:
        return dict(f.metadata() or {})


def load_weights(path: str | Path) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """Tensors and metadata of a file written by :func:`export_weights`."""
    meta = read_metadata(path)
    return load_file(str(path)), meta


def resume(run: str | Path, model: torch.nn.Module, optimizer: Optimizers, config: Any,
           scalers: Scalers | None = None, map_location: torch.device | str | None = None) -> tuple[int, float]:
    """Load the latest checkpoint of ``run`` (if any) into ``model``/``optimizer`` (and fp16 ``scalers``)
    on ``map_location`` and return ``(step, train_seconds)`` to continue from (``(0, 0.0)`` for a fresh run).

    ``config`` is the run's configuration dataclass: a checkpoint written under another
    configuration (compared with ``config.identity()``, the fields a resume must keep) is refused.
    The device, precision and workers are not part of it: a run moves between machines.
    """
    side = latest_checkpoint(run)
    if side is None:
        return 0, 0.0
    meta = load_checkpoint(side, model, optimizer, scalers=scalers, map_location=map_location)
    saved = meta.get("config")
    if saved and type(config)(**{**saved, "out": config.out}).identity() != config.identity():
        raise ValueError(f"{str(run)!r} holds a run with another configuration; use another --out")
    return int(meta["step"]), float(meta.get("train_seconds", 0.0))
