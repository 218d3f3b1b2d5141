"""Statistical model of outdoor lighting: a whitened PCA subspace of SH lighting vectors.

The paper does not predict lighting: it solves for it (:func:`physrelight.image_model.solve_lighting`)
and projects the solution onto a low-dimensional subspace learnt from real outdoor
environment maps (18 of 27 dimensions for order 2 in the original). The prior loss is the
negative log-likelihood of the whitened coordinates under a unit Gaussian.

Lighting vectors are ``(..., K, 3)`` radiance SH, flattened coefficient-major (27-D for
order 2). The model holds state (mean, basis, scales), so it is a small class; all its
methods are differentiable in torch.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from physrelight import sh
from physrelight._checks import Array, check_finite, to_tensor


@dataclass(frozen=True)
class LightingPrior:
    """Whitened PCA subspace of SH lighting.

    Attributes:
        mean: ``(D,)`` mean lighting vector, ``D = 3 K``.
        components: ``(k, D)`` orthonormal principal directions, by decreasing variance.
        scale: ``(k,)`` standard deviation along each direction (> 0).
        explained: fraction of the training variance the ``k`` components explain.
    """

    mean: torch.Tensor
    components: torch.Tensor
    scale: torch.Tensor
    explained: float

    @property
    def dim(self) -> int:
        """Number of components k."""
        return int(self.components.shape[0])

    @property
    def order(self) -> int:
        """SH order of the lighting this prior models."""
        return sh.order_of(self.mean.shape[0] // 3)

    def _flat(self, lighting: torch.Tensor) -> torch.Tensor:
        d = self.mean.shape[0]
        if lighting.ndim < 2 or lighting.shape[-2] * lighting.shape[-1] != d or lighting.shape[-1] != 3:
            raise ValueError(f"lighting must have shape (..., {d // 3}, 3), got {tuple(lighting.shape)}")
        check_finite(lighting, "lighting")
        return lighting.reshape(*lighting.shape[:-2], d)

    def encode(self, lighting: Array) -> Array:
        """``(..., K, 3)`` lighting -> ``(..., k)`` whitened coordinates ``z``."""
        t, restore = to_tensor(lighting, "lighting")
        x = self._flat(t)
        p = self._cast(t)
        return restore(((x - p.mean) @ p.components.T) / p.scale)

    def decode(self, z: Array) -> Array:
        """``(..., k)`` whitened coordinates -> ``(..., K, 3)`` lighting in the subspace."""
        t, restore = to_tensor(z, "z")
        if t.ndim < 1 or t.shape[-1] != self.dim:
            raise ValueError(f"z must have shape (..., {self.dim}), got {tuple(t.shape)}")
        p = self._cast(t)
        x = p.mean + (t * p.scale) @ p.components
        return restore(x.reshape(*t.shape[:-1], -1, 3))

    def project(self, lighting: Array) -> Array:
        """Closest lighting in the subspace (orthogonal projection), ``(..., K, 3)``."""
        t, restore = to_tensor(lighting, "lighting")
        return restore(to_tensor(self.decode(self.encode(t)), "z")[0])

    def loss(self, lighting: Array) -> Array:
        """Prior loss ``mean_j z_j^2`` (per-dimension Gaussian NLL up to constants), averaged over the batch.

        About 1 for lighting drawn from the training distribution; grows quadratically
        for implausible lighting.
        """
        t, restore = to_tensor(lighting, "lighting")
        z = to_tensor(self.encode(t), "z")[0]
        return restore((z**2).mean())

    def _cast(self, like: torch.Tensor) -> "LightingPrior":
        if self.mean.dtype == like.dtype and self.mean.device == like.device:
            return self
        return LightingPrior(self.mean.to(like), self.components.to(like), self.scale.to(like), self.explained)

    def save(self, path: str | os.PathLike) -> None:
        """Write the model as ``.npz`` (no pickle), atomically."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp = p.with_name(f".{p.name}.tmp.npz")
        np.savez(tmp, mean=self.mean.double().numpy(), components=self.components.double().numpy(),
                 scale=self.scale.double().numpy(), explained=np.float64(self.explained))
        os.replace(tmp, p)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "LightingPrior":
        """Read a model written by :meth:`save`."""
        try:
            with np.load(path, allow_pickle=False) as f:
                return cls(torch.from_numpy(f["mean"]), torch.from_numpy(f["components"]),
                           torch.from_numpy(f["scale"]), float(f["explained"]))
        except (OSError, KeyError, ValueError) as err:
            raise ValueError(f"cannot read a lighting prior from {str(path)!r}: {err}") from None


def fit_lighting_prior(lightings: Array, k: int) -> LightingPrior:
    """Fit a whitened PCA subspace of ``k`` components.

    Args:
        lightings: ``(N, K, 3)`` SH lighting vectors (e.g. outdoor maps under many
            rotations, in camera frames), ``N > k``.
        k: number of components, ``1 <= k <= min(N - 1, 3 K)``.

    Returns:
        The fitted :class:`LightingPrior` (float64).
    """
    t, _ = to_tensor(lightings, "lightings")
    if t.ndim != 3 or t.shape[-1] != 3:
        raise ValueError(f"lightings must have shape (N, K, 3), got {tuple(t.shape)}")
    sh.order_of(t.shape[1])
    check_finite(t, "lightings")
    n, d = t.shape[0], t.shape[1] * 3
    if not 1 <= k <= min(n - 1, d):
        raise ValueError(f"k must be in [1, min(N-1, D)] = [1, {min(n - 1, d)}], got {k}")
    x = t.reshape(n, d).to(torch.float64)
    mean = x.mean(dim=0)
    _, svals, vh = torch.linalg.svd(x - mean, full_matrices=False)
    var = svals**2 / (n - 1)
    if float(var[k - 1]) <= 1e-12 * float(var[0]):
        raise ValueError(f"the lightings span fewer than k={k} dimensions; choose a smaller k")
    return LightingPrior(mean=mean, components=vh[:k].contiguous(), scale=var[:k].sqrt(),
                         explained=float(var[:k].sum() / var.sum()))
