"""Comparing two methods on the same cases: the mean paired difference and its confidence
interval by a cluster bootstrap.

Relighting cases are not independent: the (source, target) cases of one scene share its
geometry and materials, so a method that fails on a scene fails on all of its cases. The
bootstrap therefore resamples whole *groups* (scenes) with replacement, and each resample's
statistic is the case-weighted mean difference, ``sum(d over the drawn groups' cases) /
(their case count)``. With one group per case it is the ordinary bootstrap.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, NamedTuple, Sequence

import numpy as np

if TYPE_CHECKING:
    import torch

__all__ = ["MeanInterval", "PairedDifference", "hierarchical_bootstrap", "paired_bootstrap", "quantile"]


class PairedDifference(NamedTuple):
    """``mean(a - b)`` over the cases and the ``level`` percentile-bootstrap interval ``[lo, hi]``."""

    diff: float
    lo: float
    hi: float
    groups: int

    def excludes_zero(self) -> bool:
        """True when the interval lies entirely on one side of 0 (a difference at that level)."""
        return self.lo > 0.0 or self.hi < 0.0


def paired_bootstrap(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                     groups: Sequence | np.ndarray | None = None, samples: int = 2000, seed: int = 0,
                     level: float = 0.95) -> PairedDifference:
    """Mean of ``a - b`` (paired per case) with a cluster-bootstrap confidence interval.

    Args:
        a, b: per-case scores of the two methods, shape ``(N,)`` each, finite.
        groups: ``(N,)`` group label of each case (e.g. the scene); whole groups are
            resampled. None: every case is its own group.
        samples: bootstrap resamples. seed: the same seed gives the same interval.
        level: coverage of the interval, in (0, 1).

    Returns:
        :class:`PairedDifference` ``(diff, lo, hi, groups)``.
    """
    a = np.asarray(a, dtype=np.float64).ravel()
    b = np.asarray(b, dtype=np.float64).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired scores must have the same length, got {a.size} and {b.size}")
    if a.size == 0:
        raise ValueError("paired_bootstrap needs at least one case")
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError("paired scores must be finite")
    if not (isinstance(samples, int) and samples >= 1):
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    if not (0.0 < level < 1.0):
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    d = a - b
    labels = np.arange(d.size) if groups is None else np.asarray(groups).ravel()
    if labels.size != d.size:
        raise ValueError(f"groups has {labels.size} labels for {d.size} cases")
    _, inverse = np.unique(labels, return_inverse=True)
    sums = np.bincount(inverse, weights=d)
    counts = np.bincount(inverse).astype(np.float64)
    rng = np.random.default_rng(seed)
    draw = rng.integers(0, sums.size, size=(samples, sums.size))
    boot = sums[draw].sum(axis=1) / counts[draw].sum(axis=1)
    lo, hi = np.quantile(boot, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return PairedDifference(float(d.mean()), float(lo), float(hi), int(sums.size))


class MeanInterval(NamedTuple):
    """A mean and its ``level`` percentile-bootstrap interval ``[lo, hi]`` over ``groups`` groups of ``cases`` cases."""

    mean: float
    lo: float
    hi: float
    groups: int
    cases: int


def hierarchical_bootstrap(values: Sequence[float] | np.ndarray, groups: Sequence | np.ndarray,
                           samples: int = 2000, seed: int = 0, level: float = 0.95) -> MeanInterval:
    """Mean of ``values`` with a two-stage bootstrap interval: groups, then cases within each group.

    Each resample draws the groups (e.g. panoramas) with replacement, then, within each drawn
    group, its cases (e.g. crops of that panorama) with replacement, and takes the mean of all
    drawn cases. Both sources of spread enter: which places were photographed and which views
    of them. With a single group it is the ordinary bootstrap over its cases.

    Args:
        values: ``(N,)`` finite per-case scores. groups: ``(N,)`` group label of each case.
        samples, seed, level: as :func:`paired_bootstrap`.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    labels = np.asarray(groups).ravel()
    if v.size == 0:
        raise ValueError("hierarchical_bootstrap needs at least one case")
    if labels.size != v.size:
        raise ValueError(f"groups has {labels.size} labels for {v.size} cases")
    if not np.isfinite(v).all():
        raise ValueError("values must be finite")
    if not (isinstance(samples, int) and samples >= 1):
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    if not (0.0 < level < 1.0):
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    _, inverse = np.unique(labels, return_inverse=True)
    members = [v[inverse == g] for g in range(inverse.max() + 1)]
    rng = np.random.default_rng(seed)
    boot = np.empty(samples)
    for s in range(samples):
        drawn = [members[g] for g in rng.integers(0, len(members), size=len(members))]
        boot[s] = np.concatenate([m[rng.integers(0, m.size, size=m.size)] for m in drawn]).mean()
    lo, hi = np.quantile(boot, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return MeanInterval(float(v.mean()), float(lo), float(hi), len(members), int(v.size))


TORCH_QUANTILE_MAX = 2 ** 24
"""The most elements ``torch.quantile`` takes (torch 2.13 refuses more: "input tensor is too large"): the sky of a
24-megapixel photo can hold more."""


def quantile(x: "torch.Tensor", q: float) -> "torch.Tensor":
    """The ``q`` quantile of all of ``x``'s elements, as ``torch.quantile(x.flatten(), q)`` computes it (linear
    interpolation between the two order statistics around ``q (n - 1)``), for a tensor of any size. The two order
    statistics come from ``torch.kthvalue`` (a selection, not a sort); up to :data:`TORCH_QUANTILE_MAX` elements the
    result is ``torch.quantile``'s to the bit. A 0-d tensor of ``x``'s dtype.

    Raises:
        ValueError: ``x`` is empty or ``q`` is not in [0, 1].
    """
    import torch

    flat = x.flatten()
    n = flat.numel()
    if n == 0:
        raise ValueError("quantile of an empty tensor")
    if not (isinstance(q, (int, float)) and 0.0 <= float(q) <= 1.0):
        raise ValueError(f"q must be a number in [0, 1], got {q!r}")
    if n <= TORCH_QUANTILE_MAX:
        if bool(torch.isnan(flat).any()):
            return torch.quantile(flat, float(q))  # NaN, as torch gives it
        # torch.quantile's own arithmetic (q in x's dtype times n - 1), its two order statistics by selection
        # rather than a full sort: the same number, ten times faster on the 8 million pixels of a 12-MP sky
        ranks = torch.scalar_tensor(float(q), dtype=flat.dtype) * (n - 1)
        below, above = ranks.to(torch.long), ranks.ceil().to(torch.long)
        a = torch.kthvalue(flat, int(below) + 1).values
        b = a if int(above) == int(below) else torch.kthvalue(flat, int(above) + 1).values
        return torch.lerp(a, b, ranks - below)
    pos = float(q) * (n - 1)
    lo = math.floor(pos)
    a = torch.kthvalue(flat, lo + 1).values
    b = torch.kthvalue(flat, min(lo + 2, n)).values
    return torch.lerp(a, b, torch.tensor(pos - lo, dtype=flat.dtype))
