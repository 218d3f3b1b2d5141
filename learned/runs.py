"""What every training loop shares (inverse network and ShadowNet, renderer, SkyGAN and sky
segmenter): the configuration mixin a resume is checked against, the CSV/TensorBoard logs,
display conversion for the PNG panels, and the compute plumbing (device, mixed precision,
DataLoader workers) of :mod:`learned.train` and :mod:`learned.train_renderer`.

Each loop (:mod:`learned.train`, :mod:`learned.train_renderer`, :mod:`learned.train_sky`)
imports this module, none imports another loop.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physrelight import colour, io

__all__ = ["DEVICES", "PRECISIONS", "RESUME_FREE_FIELDS", "Autocast", "RunConfig", "RunLogs", "StepBatches",
           "autocast", "batch_stream", "batch_to", "check_compute", "display", "grad_scaler", "resolve_device"]

# Fields a resumed run may change: where it writes, how long it runs, how it reports, and where it
# computes (a run saved on a GPU resumes on the CPU and the reverse; the precision may change with it).
RESUME_FREE_FIELDS = frozenset({"out", "progress", "steps", "val_every", "val_images", "threads", "val_data",
                                "val_split", "device", "precision", "workers"})

DEVICES = ("auto", "cpu", "cuda", "mps")
PRECISIONS = ("fp32", "bf16", "fp16")
_AMP_DTYPES = {"bf16": torch.bfloat16, "fp16": torch.float16}


class RunConfig:
    """What every training-run configuration dataclass shares (a mixin): the input checks
    and the identity a resume must keep (:func:`learned.checkpoint.resume`)."""

    def check_common(self, positive_ints: tuple[str, ...], positive_numbers: tuple[str, ...],
                     known_weights: set[str] | dict[str, float]) -> None:
        """Raise a ``ValueError`` naming the field unless every ``positive_ints`` field is a
        positive int, every ``positive_numbers`` field a finite positive number, ``data`` a
        dataset folder and every loss weight one of ``known_weights``."""
        for name in positive_ints:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        for name in positive_numbers:
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if not Path(self.data, "manifest.json").is_file():
            from physrelight.collections import find_layout

            find_layout(self.data)  # a photo collection (COLMAP, MegaDepth) is data too; else a ValueError
        unknown = set(self.weights) - set(known_weights)
        if unknown:
            raise ValueError(f"unknown loss weights {sorted(unknown)}; known: {sorted(known_weights)}")

    def check_compute_fields(self) -> None:
        """``ValueError`` naming the field unless ``device``, ``precision`` and ``workers`` are valid
        values (whether the device is there is checked when the run starts: :func:`resolve_device`)."""
        if self.device not in DEVICES:
            raise ValueError(f"device must be one of {DEVICES}, got {self.device!r}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision must be one of {PRECISIONS}, got {self.precision!r}")
        w = self.workers
        if isinstance(w, bool) or not isinstance(w, int) or w < 0:
            raise ValueError(f"workers must be a non-negative integer, got {w!r}")

    def identity(self) -> dict[str, Any]:
        """The fields that must agree for a resume (all but :data:`RESUME_FREE_FIELDS`)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name not in RESUME_FREE_FIELDS}


def _settle_header(path: Path, wanted: list[str]) -> list[str]:
    """The columns ``path`` is written under from now on: its own, plus any of ``wanted`` it lacks
    (e.g. a run resumed under newer code whose metrics gained a column). When columns are added,
    the file is rewritten under them, so that no row lands under the wrong heading."""
    if not path.is_file():
        return wanted
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        rows, old = list(reader), list(reader.fieldnames or [])
    header = old + [k for k in wanted if k not in old]
    if header != old:
        with io.atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=header, restval="")
            w.writeheader()
            w.writerows(rows)
    return header


class RunLogs:
    """CSV and TensorBoard writers of rank 0; on resume the CSV keeps rows up to ``step``."""

    def __init__(self, run: Path, start: int, enabled: bool) -> None:
        self.run, self.enabled = run, enabled
        self._headers: dict[str, list[str]] = {}  # each CSV's columns, read from disk once
        self.tb = None
        if not enabled:
            return
        for name in ("train.csv", "val.csv"):
            path = run / name
            if path.is_file():  # drop rows written after the checkpoint we resume from
                rows = list(csv.reader(path.open()))
                kept = [rows[0]] + [r for r in rows[1:] if int(r[0]) <= start]
                with path.open("w", newline="") as f:
                    csv.writer(f).writerows(kept)
        try:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(run / "tb"), purge_step=start + 1)
        except ImportError:  # tensorboard is the optional [learned] extra: CSV always
            self.tb = None
            print(f"no TensorBoard events in {run / 'tb'} (pip install 'physrelight[learned]' for them); "
                  "CSV logs only", flush=True)

    def write(self, name: str, step: int, values: dict[str, float]) -> None:
        if not self.enabled:
            return
        path = self.run / name
        header = self._headers.get(name)
        if header is None or any(k not in header for k in values):  # first write here, or a new metric
            header = self._headers[name] = _settle_header(path, ["step", *values])
        new = not path.is_file()
        row = {"step": step, **{k: f"{v:.8g}" for k, v in values.items()}}
        with path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=header, restval="")
            if new:
                w.writeheader()
            w.writerow(row)
        if self.tb is not None:
            group = name.split(".")[0]
            for k, v in values.items():
                self.tb.add_scalar(f"{group}/{k}", v, step)
            self.tb.flush()

    def close(self) -> None:
        if self.tb is not None:
            self.tb.close()


def display(x: torch.Tensor) -> np.ndarray:
    """``(3, H, W)`` linear -> ``(H, W, 3)`` display values (for PNG panels)."""
    return colour.to_ldr(x.detach().clamp_min(0)).permute(1, 2, 0).numpy()


# ------------------------------------------------------------------------- compute: device, precision, workers


def resolve_device(device: str, local_rank: int | None = None) -> torch.device:
    """The ``torch.device`` a run computes on.

    ``"auto"`` = CUDA if available, else MPS, else the CPU. Under ``torchrun`` (``local_rank`` given)
    each rank takes its own GPU, ``cuda:LOCAL_RANK``. A device that is not there is a ``ValueError``
    naming it (never a silent fall back to the CPU).
    """
    if device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
    mps = getattr(torch.backends, "mps", None)
    has_mps = bool(mps is not None and mps.is_available())
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "mps" if has_mps else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise ValueError(f"--device cuda: CUDA is not available (torch {torch.__version__}, "
                             f"built for CUDA {torch.version.cuda or 'none'}; no GPU visible)")
        index = local_rank or 0
        if index >= torch.cuda.device_count():
            raise ValueError(f"--device cuda: local rank {index} has no GPU of its own "
                             f"({torch.cuda.device_count()} visible); start at most that many processes per node")
        return torch.device("cuda", index)
    if device == "mps" and not has_mps:
        raise ValueError("--device mps: MPS (Apple GPU) is not available on this machine")
    return torch.device(device)


def _amp_works(device: torch.device, dtype: torch.dtype) -> bool:
    """Whether autocast to ``dtype`` on ``device`` runs a convolution in that dtype and, for fp16, a
    loss scaler exists for the device (a probe, not a guess from version numbers)."""
    try:
        conv = torch.nn.Conv2d(3, 4, 3).to(device)
        with torch.autocast(device.type, dtype=dtype):
            y = conv(torch.ones(1, 3, 8, 8, device=device))
        if dtype == torch.float16:
            torch.amp.GradScaler(device.type)
        return y.dtype == dtype
    except (RuntimeError, TypeError, ValueError, AssertionError):
        return False


def check_compute(device: torch.device, precision: str) -> None:
    """``ValueError`` naming the combination unless ``precision`` runs on ``device`` with this torch
    (e.g. fp16 on a CPU whose torch has no fp16 autocast or CPU loss scaler)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    if precision == "fp32":
        return
    if not _amp_works(device, _AMP_DTYPES[precision]):
        what = "autocast and loss scaling" if precision == "fp16" else "autocast"
        raise ValueError(f"--precision {precision}: {what} in {_AMP_DTYPES[precision]} does not run on "
                         f"{device} with torch {torch.__version__}; use fp32")


def _float32(out: Any) -> Any:
    """Floating tensors of reduced precision (in dicts, lists, tuples) back to float32."""
    if isinstance(out, torch.Tensor):
        return out.float() if out.dtype in (torch.float16, torch.bfloat16) else out
    if isinstance(out, dict):
        return {k: _float32(v) for k, v in out.items()}
    if isinstance(out, (list, tuple)):
        return type(out)(_float32(v) for v in out)
    return out


class Autocast:
    """A network called under ``torch.autocast``, its outputs handed back in float32.

    Only the network runs in reduced precision: the lighting solve (float64 least squares), the
    losses and the optimizer step read float32, as in an fp32 run. Attribute reads go to the bare
    network, and ``module`` is the bare network, as the loss code reads it through DDP.

    Args:
        net: the network (or its DDP wrapper) to call.
        device: where it runs; precision: ``"bf16"`` or ``"fp16"``.
    """

    def __init__(self, net: torch.nn.Module, device: torch.device, precision: str) -> None:
        self.net, self.module = net, getattr(net, "module", net)
        self.device_type, self.dtype = device.type, _AMP_DTYPES[precision]

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        with torch.autocast(self.device_type, dtype=self.dtype):
            out = self.net(*args, **kwargs)
        return _float32(out)

    def __getattr__(self, name: str) -> Any:
        if name in ("net", "module", "device_type", "dtype"):  # not set yet: no recursion through module
            raise AttributeError(name)
        return getattr(self.module, name)


def autocast(net: torch.nn.Module, device: torch.device, precision: str) -> Any:
    """``net`` itself for fp32 (the exact code path of a plain run), else :class:`Autocast` of it."""
    return net if precision == "fp32" else Autocast(net, device, precision)


def grad_scaler(device: torch.device, precision: str) -> "torch.amp.GradScaler | None":
    """A ``torch.amp.GradScaler`` for fp16 (its state travels in the checkpoints); None otherwise."""
    return torch.amp.GradScaler(device.type) if precision == "fp16" else None


def batch_to(batch: Any, device: torch.device, non_blocking: bool = False) -> Any:
    """A :class:`learned.data.Batch` with every tensor moved to ``device`` (the batch itself on the CPU
    when it is there already)."""
    if device.type == "cpu":
        return batch
    moved = {f.name: getattr(batch, f.name) for f in dataclasses.fields(batch)}
    moved = {k: v.to(device, non_blocking=non_blocking) if isinstance(v, torch.Tensor) else v
             for k, v in moved.items()}
    return dataclasses.replace(batch, **moved)


class StepBatches(torch.utils.data.Dataset):
    """Item ``i`` = the batch of step ``start + i`` (``sampler.batch(batch_size, start + i, rank)``).

    Indexed by step, so a DataLoader's workers hand out exactly the batches of the in-process loop:
    batches stay a pure function of ``(seed, step, rank)``. Items are plain dicts (a worker pickles
    them; ``pin_memory`` walks dicts), made a :class:`learned.data.Batch` again by :func:`batch_stream`.
    """

    def __init__(self, sampler: Any, batch_size: int, start: int, steps: int, rank: int = 0) -> None:
        self.sampler, self.batch_size, self.start, self.steps, self.rank = sampler, batch_size, start, steps, rank

    def __len__(self) -> int:
        return max(0, self.steps - self.start)

    def __getitem__(self, i: int) -> dict[str, Any]:
        b = self.sampler.batch(self.batch_size, self.start + i, self.rank)
        return {f.name: getattr(b, f.name) for f in dataclasses.fields(b)}


def _one_thread(_: int) -> None:
    torch.set_num_threads(1)  # workers load and resize photos; the main process keeps the threads


def batch_stream(sampler: Any, batch_size: int, start: int, steps: int, rank: int = 0, workers: int = 0,
                 device: torch.device = torch.device("cpu")) -> Iterator[Any]:
    """The batches of steps ``start .. steps - 1`` on ``device``, in order.

    ``workers == 0``: made in this process, step by step (the historical path). ``workers > 0``: a
    ``torch.utils.data.DataLoader`` over :class:`StepBatches` with that many processes, pinned memory
    when the device is CUDA; the same batches either way.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 0:
        raise ValueError(f"workers must be a non-negative integer, got {workers!r}")
    if workers == 0:
        for step in range(start, steps):
            yield batch_to(sampler.batch(batch_size, step, rank), device)
        return
    from .data import Batch

    pin = device.type == "cuda"
    loader = torch.utils.data.DataLoader(StepBatches(sampler, batch_size, start, steps, rank), batch_size=None,
                                         shuffle=False, num_workers=workers, pin_memory=pin,
                                         worker_init_fn=_one_thread, prefetch_factor=2,
                                         # its own generator: the workers' base seed is not drawn from the
                                         # global RNG, whose state the checkpoints carry
                                         generator=torch.Generator().manual_seed(0))
    for item in loader:
        item["keys"] = [tuple(k) for k in item["keys"]]  # the loader's collation makes tuples lists
        yield batch_to(Batch(**item), device, non_blocking=pin)
