"""What a method scored on the benchmark's pairs: the metrics, per pair, and their record.

:class:`MethodRun` is shared by :mod:`.run` (which makes them) and :mod:`.report` (which
reads them); it lives below both so neither imports the other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import torch

from physrelight import metrics

__all__ = ["GAIN_METRICS", "METRICS", "MethodRun", "score"]

METRICS = ("l1", "mse", "ssim", "dssim", "psnr", "ciede2000")
"""Reported per pair, on foreground pixels of display values (sRGB, [0, 1])."""
GAIN_METRICS = ("gain_l1", "gain_ssim", "gain_psnr")
"""Exposure-invariant: ``l1``, ``ssim``, ``psnr`` of the output after its best single gain per
image (:meth:`validation.bench.protocols.Pair.display_at_best_gain`): structure apart from level."""


@dataclass
class MethodRun:
    """One method over a list of pairs: per-pair metrics and seconds, and what went wrong."""

    name: str
    keys: list[str]
    values: dict[str, np.ndarray]
    seconds: list[float]
    nonfinite: int = 0
    failures: list[str] = field(default_factory=list)
    method: Any = field(default=None, repr=False)

    def mean(self, idx: Sequence[int] | None = None) -> dict[str, float]:
        sel = slice(None) if idx is None else list(idx)
        return {m: float(np.mean(v[sel])) if len(v[sel]) else math.nan for m, v in self.values.items()}


def score(preds: list[torch.Tensor], targets: list[torch.Tensor], masks: list[torch.Tensor],
          chunk: int = 64, which: Sequence[str] = METRICS) -> dict[str, np.ndarray]:
    """Per-pair metrics ``{name: (N,)}`` of display images ``(1, 3, H, W)`` on foreground masks ``(1, 1, H, W)``.

    ``which``: the metrics to compute (a subset of :data:`METRICS`).
    """
    bad = [m for m in which if m not in METRICS]
    if bad:
        raise ValueError(f"unknown metrics {bad}; expected a subset of {METRICS}")
    out: dict[str, list[np.ndarray]] = {m: [] for m in METRICS}
    for s in range(0, len(preds), chunk):
        p, t, m = (torch.cat(x[s:s + chunk]).double() for x in (preds, targets, masks))
        out["l1"].append(metrics.l1(p, t, m, reduction="none").numpy())
        out["mse"].append(metrics.mse(p, t, m, reduction="none").numpy())
        out["psnr"].append(metrics.psnr(p, t, m, reduction="none").numpy())
        try:
            ss = metrics.ssim(p.float(), t.float(), m, reduction="none").double().numpy()
        except ValueError:  # a foreground wholly within 5 px of the border: SSIM of the composite
            ss = metrics.ssim(p.float(), t.float(), reduction="none").double().numpy()
        out["ssim"].append(ss)
        out["dssim"].append((1.0 - ss) / 2.0)
        if "ciede2000" in which:  # the slow one
            out["ciede2000"].append(metrics.delta_e2000(p, t, m, reduction="none").numpy())
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items() if k in which}
