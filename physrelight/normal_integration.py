"""Depth from normals: perspective log-depth integration by weighted least squares.

For a pinhole camera the log of the z-depth ``zeta = log z`` has, at pixel ``(u, v)``, the gradient

    d zeta / du = -(m_x / fx) / D,   d zeta / dv = -(m_y / fy) / D,
    D = m . ((u - cx) / fx, (v - cy) / fy, 1),

where ``m = (n_x, -n_y, -n_z)`` is the normal in the vision frame (x right, y down, z forward)
and ``D`` its dot product with the pixel's viewing ray (negative on a visible surface). This follows
from ``n . dX = 0`` with ``X = z ((u - cx) / fx, (v - cy) / fy, 1)``; it holds for any normal field
of a perspective surface, so planes come back as planes (not the orthographic approximation).

The log depth is found by least squares over the foreground: every pair of 4-neighbours inside
``mask`` asks ``zeta_j - zeta_i`` to equal the mean of their two gradients along the edge, weighted
by how head-on the two normals see the camera (grazing normals make ``D`` small and the gradient
unreliable; back-facing estimated normals get no weight), plus a tiny ridge term that fixes the
free constant. The normal equations (a weighted graph Laplacian) are solved by Jacobi-preconditioned
conjugate gradients in torch, starting from the solution at half resolution (coarse to fine).

What comes back is depth up to one global scale (the foreground's geometric mean is 1). Parts of
the foreground that no chain of 4-neighbours connects each get their own scale, and a depth
discontinuity inside one connected part (an object in front of the ground) is integrated as if the
surfaces were joined: normals carry no information about it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from physrelight._checks import batched_intrinsics

__all__ = ["depth_from_normals", "log_depth_gradients"]


def _check(normals: torch.Tensor, K: torch.Tensor, mask: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
    if not isinstance(normals, torch.Tensor) or normals.ndim != 4 or normals.shape[1] != 3:
        raise ValueError(f"normals must have shape (B, 3, H, W), got {tuple(getattr(normals, 'shape', ()))}")
    b, _, h, w = normals.shape
    if h < 2 or w < 2:
        raise ValueError(f"normals must be at least 2 x 2 pixels, got shape {tuple(normals.shape)}")
    K = batched_intrinsics(K, b, normals)
    if bool((K[:, 0, 1] != 0).any()):
        raise ValueError("K must have zero skew")
    if mask is None:
        mask = torch.ones(b, 1, h, w, dtype=torch.bool, device=normals.device)
    if mask.shape != (b, 1, h, w) or mask.dtype != torch.bool:
        raise ValueError(f"mask must be a bool tensor of shape ({b}, 1, {h}, {w}), got {tuple(mask.shape)} {mask.dtype}")
    return K, mask


def log_depth_gradients(normals: torch.Tensor, K: torch.Tensor, min_cos: float = 0.05
                        ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-pixel ``(d zeta / du, d zeta / dv)`` and their confidence (see the module doc).

    Args:
        normals: ``(B, 3, H, W)`` camera-frame normals (normalised here; zero = none).
        K: ``(B, 3, 3)`` intrinsics without skew.
        min_cos: below this cosine between the normal and the direction to the camera the
            gradient gets no weight (and is clamped to what ``min_cos`` allows).

    Returns:
        ``p (B, 1, H, W)``, ``q (B, 1, H, W)``, ``conf (B, 1, H, W)`` in [0, 1] (the cosine, 0 below
        ``min_cos``).
    """
    b, _, h, w = normals.shape
    dt = normals.dtype
    n = F.normalize(normals, dim=1, eps=1e-12)
    mx, my, mz = n[:, 0:1], -n[:, 1:2], -n[:, 2:3]
    fx, fy = K[:, 0, 0].reshape(b, 1, 1, 1), K[:, 1, 1].reshape(b, 1, 1, 1)
    cx, cy = K[:, 0, 2].reshape(b, 1, 1, 1), K[:, 1, 2].reshape(b, 1, 1, 1)
    v, u = torch.meshgrid(torch.arange(h, dtype=dt, device=n.device) + 0.5,
                          torch.arange(w, dtype=dt, device=n.device) + 0.5, indexing="ij")
    rx, ry = (u - cx) / fx, (v - cy) / fy
    ray_norm = torch.sqrt(rx * rx + ry * ry + 1.0)
    D = mx * rx + my * ry + mz
    cos = (-D / ray_norm).clamp(0.0, 1.0)  # normal . direction to the camera
    conf = torch.where(cos >= min_cos, cos, torch.zeros_like(cos))
    D_safe = -torch.clamp_min(-D, min_cos * ray_norm)  # bounded slopes where the normal is grazing
    return -(mx / fx) / D_safe, -(my / fy) / D_safe, conf


def _edges(p: torch.Tensor, q: torch.Tensor, conf: torch.Tensor, mask: torch.Tensor
           ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Edge targets and weights: horizontal ``gx, wx (B, 1, H, W-1)``, vertical ``gy, wy (B, 1, H-1, W)``."""
    c = conf * mask.to(conf.dtype)
    gx, gy = 0.5 * (p[..., 1:] + p[..., :-1]), 0.5 * (q[..., 1:, :] + q[..., :-1, :])
    wx, wy = torch.minimum(c[..., 1:], c[..., :-1]), torch.minimum(c[..., 1:, :], c[..., :-1, :])
    return gx, wx, gy, wy


def _apply(x: torch.Tensor, wx: torch.Tensor, wy: torch.Tensor, ridge: torch.Tensor) -> torch.Tensor:
    """The weighted graph Laplacian plus ridge applied to ``x (B, 1, H, W)``."""
    out = ridge * x
    fx = wx * (x[..., 1:] - x[..., :-1])
    fy = wy * (x[..., 1:, :] - x[..., :-1, :])
    out = out + F.pad(fx, (1, 0)) - F.pad(fx, (0, 1))
    return out + F.pad(fy, (0, 0, 1, 0)) - F.pad(fy, (0, 0, 0, 1))


def _rhs(gx: torch.Tensor, wx: torch.Tensor, gy: torch.Tensor, wy: torch.Tensor) -> torch.Tensor:
    fx, fy = wx * gx, wy * gy
    return F.pad(fx, (1, 0)) - F.pad(fx, (0, 1)) + F.pad(fy, (0, 0, 1, 0)) - F.pad(fy, (0, 0, 0, 1))


def _cg(wx: torch.Tensor, wy: torch.Tensor, rhs: torch.Tensor, ridge: torch.Tensor, x0: torch.Tensor,
        iters: int, tol: float) -> torch.Tensor:
    """Jacobi-preconditioned conjugate gradients, per batch item, stopped at ``|r| <= tol |rhs|``."""
    diag = ridge + F.pad(wx, (1, 0)) + F.pad(wx, (0, 1)) + F.pad(wy, (0, 0, 1, 0)) + F.pad(wy, (0, 0, 0, 1))
    inv_diag = 1.0 / diag
    x = x0.clone()
    r = rhs - _apply(x, wx, wy, ridge)
    z = r * inv_diag
    d = z.clone()
    rz = (r * z).sum((1, 2, 3), keepdim=True)
    stop = tol * rhs.flatten(1).norm(dim=1).reshape(-1, 1, 1, 1).clamp_min(1e-30)
    for _ in range(iters):
        if bool((r.flatten(1).norm(dim=1).reshape(-1, 1, 1, 1) <= stop).all()):
            break
        Ad = _apply(d, wx, wy, ridge)
        alpha = rz / (d * Ad).sum((1, 2, 3), keepdim=True).clamp_min(1e-30)
        x = x + alpha * d
        r = r - alpha * Ad
        z = r * inv_diag
        rz_new = (r * z).sum((1, 2, 3), keepdim=True)
        d = z + (rz_new / rz.clamp_min(1e-30)) * d
        rz = rz_new
    return x


def _solve(p: torch.Tensor, q: torch.Tensor, conf: torch.Tensor, mask: torch.Tensor, iters: int, tol: float,
           ridge_share: float, levels: int) -> torch.Tensor:
    """Log depth ``(B, 1, H, W)`` (arbitrary constant per connected part), coarse to fine."""
    h, w = p.shape[-2:]
    x0 = torch.zeros_like(p)
    if levels > 1 and min(h, w) >= 16:
        # Half resolution: gradients per coarse pixel are twice the fine ones.
        m2 = F.avg_pool2d(mask.to(p.dtype), 2, ceil_mode=True)
        keep = m2 > 0.5
        def pool(x: torch.Tensor) -> torch.Tensor:
            return F.avg_pool2d(x * mask, 2, ceil_mode=True) / m2.clamp_min(1e-12)
        coarse = _solve(2.0 * pool(p), 2.0 * pool(q), pool(conf), keep, iters, tol, ridge_share, levels - 1)
        x0 = F.interpolate(coarse, scale_factor=2.0, mode="bilinear", align_corners=False)[..., :h, :w] * mask
    gx, wx, gy, wy = _edges(p, q, conf, mask)
    scale = torch.cat([wx.flatten(1), wy.flatten(1)], 1).mean(1).reshape(-1, 1, 1, 1).clamp_min(1e-12)
    ridge = ridge_share * scale * torch.ones_like(p)
    return _cg(wx, wy, _rhs(gx, wx, gy, wy), ridge, x0, iters, tol)


def depth_from_normals(normals: torch.Tensor, K: torch.Tensor, mask: torch.Tensor | None = None, *,
                       iters: int = 2000, tol: float = 1e-7, min_cos: float = 0.05, ridge: float = 1e-8,
                       levels: int = 4) -> torch.Tensor:
    """``(B, 1, H, W)`` z-depth up to scale from camera-frame ``normals`` (see the module doc).

    Args:
        normals: ``(B, 3, H, W)`` camera-frame normals (x right, y up, z towards the viewer).
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics of the normals' pixel grid (no skew).
        mask: ``(B, 1, H, W)`` bool foreground (sky False), or None = every pixel.
        iters, tol: conjugate-gradient iterations per level and relative residual to stop at.
        min_cos: normals within ``acos(min_cos)`` of grazing give no constraint.
        ridge: the ridge term's weight relative to the mean edge weight (fixes the free constant).
        levels: coarse-to-fine levels (1 = solve at full resolution only).

    Returns:
        ``(B, 1, H, W)`` positive depth on ``mask`` with geometric mean 1 over it, 0 elsewhere.

    Raises:
        ValueError: bad shapes (named) or values.
    """
    K, mask = _check(normals, K, mask)
    if not 0.0 < min_cos < 1.0:
        raise ValueError(f"min_cos must be in (0, 1), got {min_cos!r}")
    if int(iters) != iters or iters < 1 or int(levels) != levels or levels < 1:
        raise ValueError(f"iters and levels must be positive integers, got {iters!r}, {levels!r}")
    if not ridge > 0:
        raise ValueError(f"ridge must be positive, got {ridge!r}")
    work = normals.double()
    p, q, conf = log_depth_gradients(work, K.double(), min_cos)
    zeta = _solve(p, q, conf, mask, iters, tol, ridge, levels)
    m = mask.to(zeta.dtype)
    mean = (zeta * m).sum((1, 2, 3), keepdim=True) / m.sum((1, 2, 3), keepdim=True).clamp_min(1.0)
    depth = torch.where(mask, torch.exp(zeta - mean), torch.zeros_like(zeta))
    return depth.to(normals.dtype)
