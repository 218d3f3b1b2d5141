"""Input checks and the numpy <-> torch round trip shared by every public function.

Public functions accept numpy arrays or torch tensors and give back the type they were
given. They convert at the door with :func:`to_tensor`, compute in torch, and convert
back with the returned ``restore`` function. Checks raise ``ValueError`` with a message
that names the argument and the problem, so a bad input never turns into a wrong number.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np
import torch

Array = Any  # numpy.ndarray | torch.Tensor; kept loose so both pass type checkers
Restore = Callable[[torch.Tensor], Array]


def to_tensor(x: Array, name: str, dtype: torch.dtype | None = None) -> tuple[torch.Tensor, Restore]:
    """Convert ``x`` to a floating torch tensor and return a function that converts back.

    numpy inputs are computed in float64 (they come from analysis code where accuracy
    matters more than speed) and are returned as numpy arrays of the input's float
    dtype (float64 for integer input). torch inputs keep their dtype, device and
    autograd graph; integer tensors are promoted to float32.

    Raises:
        ValueError: ``x`` is neither a numpy array nor a torch tensor (lists are accepted
            and treated as numpy), or it is complex.
    """
    if isinstance(x, torch.Tensor):
        if x.is_complex():
            raise ValueError(f"{name} must be real, got a complex tensor")
        t = x if x.is_floating_point() else x.to(torch.float32)
        if dtype is not None:
            t = t.to(dtype)
        return t, _identity
    if isinstance(x, (list, tuple, float, int, np.number)):
        x = np.asarray(x)
    if not isinstance(x, np.ndarray):
        raise ValueError(f"{name} must be a numpy array or a torch tensor, got {type(x).__name__}")
    if np.iscomplexobj(x):
        raise ValueError(f"{name} must be real, got a complex array")
    if x.dtype == object:
        raise ValueError(f"{name} must be a numeric array, got dtype object")
    out_dtype = x.dtype if np.issubdtype(x.dtype, np.floating) else np.dtype(np.float64)
    # np.array (not ascontiguousarray) keeps 0-dim arrays 0-dim.
    t = torch.from_numpy(np.array(x, dtype=np.float64, order="C"))
    if dtype is not None:
        t = t.to(dtype)

    def restore(y: torch.Tensor) -> np.ndarray:
        return y.detach().cpu().numpy().astype(out_dtype, copy=False)

    return t, restore


def _identity(y: torch.Tensor) -> torch.Tensor:
    return y


def check_finite(t: torch.Tensor, name: str) -> None:
    """Raise if ``t`` holds NaN or inf, naming how many and where the first one is."""
    bad = ~torch.isfinite(t.detach())
    if bool(bad.any()):
        n = int(bad.sum())
        first = tuple(int(i) for i in torch.nonzero(bad)[0])
        raise ValueError(f"{name} holds {n} non-finite value(s) (NaN or inf), first at index {first}")


def check_nonnegative(t: torch.Tensor, name: str, what: str = "radiance") -> None:
    """Raise if ``t`` holds negative values (e.g. radiance, irradiance, albedo)."""
    neg = t.detach() < 0
    if bool(neg.any()):
        first = tuple(int(i) for i in torch.nonzero(neg)[0])
        raise ValueError(
            f"{name} must be non-negative {what}: found {int(neg.sum())} negative value(s), "
            f"min {float(t.detach().min()):.4g} (first at index {first})"
        )


def check_last_dim(t: torch.Tensor, size: int, name: str, layout: str) -> None:
    """Raise unless ``t`` has at least one dimension and its last one has ``size`` entries."""
    if t.ndim == 0 or t.shape[-1] != size:
        raise ValueError(f"{name} must have shape {layout}, got {tuple(t.shape)}")


def check_image(t: torch.Tensor, name: str, channels: int | Sequence[int] | None = None) -> None:
    """Raise unless ``t`` is a batched image ``(B, C, H, W)`` with an allowed channel count."""
    if t.ndim != 4:
        raise ValueError(f"{name} must be a (B, C, H, W) image, got shape {tuple(t.shape)}")
    if channels is not None:
        allowed = (channels,) if isinstance(channels, int) else tuple(channels)
        if t.shape[1] not in allowed:
            want = " or ".join(str(c) for c in allowed)
            raise ValueError(f"{name} must have {want} channel(s), got shape {tuple(t.shape)}")


def check_same_spatial(a: torch.Tensor, b: torch.Tensor, name_a: str, name_b: str) -> None:
    """Raise unless two ``(B, C, H, W)`` images share batch and spatial size."""
    if a.shape[0] != b.shape[0] or a.shape[-2:] != b.shape[-2:]:
        raise ValueError(
            f"{name_a} {tuple(a.shape)} and {name_b} {tuple(b.shape)} must share batch size and (H, W)"
        )


def check_rotation(R: torch.Tensor, name: str = "R", atol: float = 1e-4) -> None:
    """Raise unless ``R`` is a ``(..., 3, 3)`` proper rotation (orthonormal, det +1)."""
    if R.ndim < 2 or R.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3), got {tuple(R.shape)}")
    check_finite(R, name)
    Rd = R.detach().to(torch.float64)
    eye = torch.eye(3, dtype=torch.float64, device=Rd.device)
    err = (Rd @ Rd.transpose(-1, -2) - eye).abs().amax()
    if float(err) > atol:
        raise ValueError(f"{name} must be orthonormal: max |R R^T - I| = {float(err):.3g}")
    det = torch.linalg.det(Rd)
    if bool((det < 0).any()):
        raise ValueError(f"{name} must be a proper rotation (det +1), got a reflection (det -1)")


def batched_intrinsics(K: Array, batch: int, like: torch.Tensor) -> torch.Tensor:
    """``K`` ``(3, 3)`` or ``(batch, 3, 3)`` -> ``(batch, 3, 3)`` in ``like``'s dtype and device,
    finite with positive ``fx``, ``fy``; ``ValueError`` naming the bad shape or value otherwise."""
    K = torch.as_tensor(K, dtype=like.dtype, device=like.device)
    if K.shape == (3, 3):
        K = K[None].expand(batch, 3, 3)
    if K.shape != (batch, 3, 3):
        raise ValueError(f"K must have shape (3, 3) or ({batch}, 3, 3), got {tuple(K.shape)}")
    if not torch.isfinite(K).all() or bool((K[:, 0, 0] <= 0).any()) or bool((K[:, 1, 1] <= 0).any()):
        raise ValueError("K must be finite with positive fx, fy")
    return K
