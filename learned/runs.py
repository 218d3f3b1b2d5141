"""What every training loop shares (inverse network and ShadowNet, renderer, SkyGAN and sky
segmenter): the configuration mixin a resume is checked against, the CSV/TensorBoard logs,
and display conversion for the PNG panels.

Each loop (:mod:`learned.train`, :mod:`learned.train_renderer`, :mod:`learned.train_sky`)
imports this module, none imports another loop.
"""

from __future__ import annotations

import csv
import math
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physrelight import colour, io

__all__ = ["RESUME_FREE_FIELDS", "RunConfig", "RunLogs", "display"]

# Fields a resumed run may change: where it writes, how long it runs, how it reports.
RESUME_FREE_FIELDS = frozenset({"out", "progress", "steps", "val_every", "val_images", "threads", "val_data",
                                "val_split"})


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
